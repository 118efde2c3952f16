"""The bolus solid's mesher: marching cubes on the cubes the surface passes through.

The field is sampled on one cubic lattice (spacing ``sp`` (3,) mm, padded by a layer of
negative values so the surface closes at the box) and only the cubes whose eight corners
do not all have one sign are handed to libigl's sparse marching cubes (compiled; array in,
array out).  Nothing is called per lattice point from Python, so the mesher costs a few
numpy passes over the lattice plus the compiled marching, against manifold3d's level set,
which calls a Python function at each of the twice as many points of its body-centred
lattice.  libigl's case table gives a closed, edge-manifold mesh; corners exactly on the
surface are nudged inside-out by 1e-12 so no vertex is shared by two cube edges.

`marching_cubes_on` takes the crossing cubes and their corner values directly (the brick-stored
narrow band hands them over without a dense lattice).  Arrays: values (nx, ny, nz) float64,
positive inside the solid; out V (n,3) float64 mm, F (m,3) int64 wound outward.
"""
from __future__ import annotations

import numpy as np

import manifold3d as m3

from .manifold import to_manifold

__all__ = ["CUBE_CORNERS", "crossing_cubes", "marching_cubes", "marching_cubes_on", "marching_manifold",
           "marching_manifold_on"]

#: corner offsets of a cube in libigl's order (marching_cubes.cpp)
CUBE_CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                         [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=np.int64)


def crossing_cubes(inside: np.ndarray, chunk: int = 64) -> np.ndarray:
    """(k,3) int64 lower-corner indices of the cubes of the boolean lattice ``inside``
    (nx, ny, nz) whose corners are neither all inside nor all outside (x-slabs of ``chunk``)."""
    nx, ny, nz = inside.shape
    out = []
    for i0 in range(0, nx - 1, chunk):
        i1 = min(nx - 1, i0 + chunk)
        cnt = np.zeros((i1 - i0, ny - 1, nz - 1), dtype=np.uint8)
        for dx, dy, dz in CUBE_CORNERS:
            cnt += inside[i0 + dx:i1 + dx, dy:ny - 1 + dy, dz:nz - 1 + dz]
        ijk = np.argwhere((cnt > 0) & (cnt < 8))
        ijk[:, 0] += i0
        out.append(ijk)
    return np.concatenate(out) if out else np.zeros((0, 3), dtype=np.int64)


def marching_cubes(values: np.ndarray, origin, spacing, pad: bool = False):
    """Surface {values = 0} of a lattice (nx, ny, nz), positive inside: (V (n,3), F (m,3)) with
    the lattice point (i, j, k) at origin + (i, j, k) * spacing (mm), faces wound outward.
    pad: the lattice is taken as surrounded by one layer of -1 (no copy of it is made), so the
    surface closes at its box."""
    inside = values > 0  # a corner exactly on the surface counts as outside (nudged below)
    if pad:
        inside = np.pad(inside, 1)
    cubes = crossing_cubes(inside) - (1 if pad else 0)
    del inside
    corner = (cubes[:, None, :] + CUBE_CORNERS[None]).reshape(-1, 3)
    real = np.all((corner >= 0) & (corner < np.array(values.shape)), axis=1)
    S = np.full(len(corner), -1.0)
    S[real] = values[tuple(corner[real].T)]
    return marching_cubes_on(cubes, S.reshape(-1, 8), origin, spacing)


def marching_cubes_on(cubes: np.ndarray, corner_values: np.ndarray, origin, spacing):
    """The surface through given cubes only: lower corners cubes (k,3) int (lattice coordinates,
    any sign), their corner values (k,8) in CUBE_CORNERS order, positive inside; (V, F) as
    `marching_cubes`.  A corner shared by several cubes must carry one value in all of them."""
    import igl  # the compiled marching cubes (libigl)

    if len(cubes) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    cubes = np.asarray(cubes, dtype=np.int64)
    lo = cubes.min(axis=0)
    dims = cubes.max(axis=0) - lo + 2
    # a corner's key is its lower corner's plus the offset's (no (8k,3) array of corners)
    stride = np.array([dims[1] * dims[2], dims[2], 1], dtype=np.int64)
    gid = (((cubes - lo) @ stride)[:, None] + (CUBE_CORNERS @ stride)[None]).ravel()
    used, first, inv = np.unique(gid, return_index=True, return_inverse=True)
    GI = inv.reshape(-1, 8).astype(np.int64)
    S = np.asarray(corner_values, dtype=np.float64).ravel()[first].copy()
    S[S == 0.0] = -1e-12
    corner = cubes[first // 8] + CUBE_CORNERS[first % 8]
    GV = np.asarray(origin, dtype=np.float64) + corner * np.asarray(spacing, dtype=np.float64)
    res = igl.marching_cubes(np.ascontiguousarray(S), np.ascontiguousarray(GV), GI, 0.0)  # (V, F[, E2V]): libigl 2.6.3 adds the edge map
    V, F = np.asarray(res[0], dtype=np.float64), np.asarray(res[1], dtype=np.int64)
    return V, np.ascontiguousarray(F[:, ::-1])  # libigl winds {S > 0} inward


def marching_manifold(values: np.ndarray, origin, spacing, pad: bool = False) -> m3.Manifold:
    """`marching_cubes` as a manifold3d Manifold (empty when the surface is empty)."""
    V, F = marching_cubes(values, origin, spacing, pad)
    return to_manifold(V, F, "the marched solid")


def marching_manifold_on(cubes: np.ndarray, corner_values: np.ndarray, origin, spacing) -> m3.Manifold:
    """`marching_cubes_on` as a manifold3d Manifold."""
    V, F = marching_cubes_on(cubes, corner_values, origin, spacing)
    return to_manifold(V, F, "the marched solid")
