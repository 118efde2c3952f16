"""Bpy-free core of the Bolus add-on: numpy arrays in, numpy arrays out.

Conventions shared by every module here:
- vertices ``V`` are ``(n, 3) float64`` (millimetres when they come from Blender),
  triangles ``F`` are ``(m, 3) int64`` with counter-clockwise corners;
- bad input raises :class:`BolusError` (a ``ValueError``) with a message meant for
  the modeler;
- functions with randomness take ``rng`` (an ``int`` seed or ``numpy.random.Generator``);
- long functions take ``progress``: an optional callable ``progress(fraction, text)``.

Only numpy, scipy and scikit-learn may be imported here (``tests/test_core_imports.py``
scans this package).
"""
from .errors import BolusError

__all__ = ["BolusError"]
