"""Minimal Wavefront OBJ reader for tests, benchmarks and scripts (no Blender needed).

`load_obj(path)` returns ``V`` (n,3) float64, ``F`` (m,3) int64 fan-triangulated and
``tri_face`` (m,) the OBJ polygon of each triangle.  Only ``v`` and ``f`` records are
read (texture/normal indices after ``/`` are ignored, negative indices resolved).
"""
from __future__ import annotations

import numpy as np

from ..errors import BolusError
from .topology import as_mesh_arrays, triangulate_polygons

__all__ = ["load_obj"]


def load_obj(path, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read an OBJ file; ``scale`` multiplies the coordinates (e.g. 10 for cm -> mm).

    Returns V (n,3) float64, F (m,3) int64, tri_face (m,) int64.  A record that cannot be
    read, an index outside the vertices or a non-finite coordinate raises `BolusError`
    naming the file and line (or vertex)."""
    verts: list[list[float]] = []
    corners: list[int] = []
    sizes: list[int] = []
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            try:
                _read_record(line, verts, corners, sizes)
            except (ValueError, IndexError) as exc:
                raise BolusError(f"{path}, line {lineno}: cannot read {line.strip()[:40]!r} ({exc})") from None
    if not verts or not sizes:
        raise BolusError(f"{path}: no vertices or faces found")
    V = np.asarray(verts, dtype=np.float64) * float(scale)
    F, tri_face = triangulate_polygons(np.asarray(corners), np.asarray(sizes))
    try:
        V, F = as_mesh_arrays(V, F)
    except BolusError as exc:
        raise BolusError(f"{path}: {exc}") from None
    return V, F, tri_face


def _read_record(line: str, verts: list, corners: list, sizes: list) -> None:
    """Append one ``v`` or ``f`` record (other records are ignored)."""
    if line.startswith("v "):
        xyz = [float(x) for x in line.split()[1:4]]
        if len(xyz) != 3:
            raise ValueError("a vertex needs three coordinates")
        verts.append(xyz)
    elif line.startswith("f "):
        idx = []
        for tok in line.split()[1:]:
            i = int(tok.split("/")[0])
            if i == 0:
                raise ValueError("OBJ indices start at 1")
            idx.append(i - 1 if i > 0 else len(verts) + i)
        if len(idx) < 3:
            raise ValueError("a face needs three corners")
        corners.extend(idx)
        sizes.append(len(idx))
