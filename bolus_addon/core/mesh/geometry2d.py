"""Planar (2-D) vector helpers shared by the pattern code (overlap, outline, unfolding).

numpy 2 removed ``np.cross`` on 2-vectors (it raises ``ValueError: ... must be (arrays of)
3-dimensional vectors``; numpy 1.26 only warned).  Every 2-D cross product of the core,
the tests and the benchmarks goes through `cross2d`, so it behaves the same on numpy 1.26
(Blender 4.2-5.0, Python 3.11) and numpy 2.x (Blender 5.1+, Python 3.13).
"""
from __future__ import annotations

import numpy as np

__all__ = ["cross2d"]


def cross2d(a, b) -> np.ndarray:
    """z-component of the cross product of 2-vectors: ``a_x b_y - a_y b_x``.

    a, b: (..., 2) array-likes, broadcast against each other; returns (...,) float
    (a scalar array for single vectors).  Positive when b lies counter-clockwise of a;
    twice the signed area of the triangle (0, a, b) -- the orientation predicate of
    seed 4.5.3 (flipped triangles, edge crossings).
    """
    a = np.asarray(a)
    b = np.asarray(b)
    if a.shape[-1:] != (2,) or b.shape[-1:] != (2,):
        raise ValueError(f"cross2d needs (..., 2) arrays, got shapes {a.shape} and {b.shape}")
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
