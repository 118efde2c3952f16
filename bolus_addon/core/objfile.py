"""Minimal Wavefront OBJ reader for tests, benchmarks and scripts (no Blender needed).

`load_obj(path)` returns ``V`` (n,3) float64, ``F`` (m,3) int64 fan-triangulated and
``tri_face`` (m,) the OBJ polygon of each triangle.  Only ``v`` and ``f`` records are
read (texture/normal indices after ``/`` are ignored, negative indices resolved).
"""
from __future__ import annotations

import numpy as np

from .errors import BolusError
from .topology import triangulate_polygons

__all__ = ["load_obj"]


def load_obj(path, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read an OBJ file; ``scale`` multiplies the coordinates (e.g. 10 for cm -> mm)."""
    verts: list[list[float]] = []
    corners: list[int] = []
    sizes: list[int] = []
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if line.startswith("v "):
                verts.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                idx = []
                for tok in line.split()[1:]:
                    i = int(tok.split("/")[0])
                    idx.append(i - 1 if i > 0 else len(verts) + i)
                corners.extend(idx)
                sizes.append(len(idx))
    if not verts or not sizes:
        raise BolusError(f"{path}: no vertices or faces found")
    V = np.asarray(verts, dtype=np.float64) * float(scale)
    F, tri_face = triangulate_polygons(np.asarray(corners), np.asarray(sizes))
    return V, F, tri_face
