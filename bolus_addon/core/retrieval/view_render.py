"""Silhouettes (and depth) of a mesh from directions spread over the sphere, bpy-free.

* `fibonacci_directions(n)`: n unit vectors on the upper half sphere (z >= 0), the Fibonacci
  spiral (golden angle), evenly spread; a silhouette from -d is the mirror image of the one from d
  and the descriptors do not see mirrors, so a half sphere covers every view;
* `view_frame(d)`: (3,3) columns right, up, d of an orthographic camera looking along -d;
* `render_views(V, F, directions, size)`: (k, size, size) bool silhouettes (the projection fitted
  into the square with a margin, aspect kept) and, with ``depth``, the z-buffer (k, size, size) float
  (distance along -d from the model's centre plane; inf where empty).

The rasteriser is a vectorised scanline fill: every (triangle, pixel row) pair whose row centre lies
inside the triangle's y range gives an x span; spans are filled by a difference row and a cumulative
sum.  Each vertex also marks its pixel, so triangles smaller than a pixel leave no holes.  Depth: the
spans are expanded into pixels (np.repeat), each pixel's depth from its triangle's plane, kept by
``np.minimum.at`` (the z-buffer).  One numpy pass per view; no Python call per pixel or triangle.
"""
from __future__ import annotations

import numpy as np

from ..errors import BolusError

__all__ = ["row_spans", "fibonacci_directions", "view_frame", "render_views", "MARGIN_PX"]

MARGIN_PX = 2  #: empty pixels round the projection
GOLDEN = np.pi * (3.0 - np.sqrt(5.0))  #: the golden angle (rad)


def fibonacci_directions(n: int, offset: float = 0.0) -> np.ndarray:
    """(n,3) unit vectors on the half sphere z >= 0, a Fibonacci spiral: z_i = (i + 1/2) / n, azimuth
    i * golden angle + ``offset`` (rad)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise BolusError(f"the number of view directions must be an integer >= 1, got {n!r}")
    i = np.arange(int(n), dtype=np.float64)
    z = (i + 0.5) / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    a = i * GOLDEN + offset
    return np.column_stack([r * np.cos(a), r * np.sin(a), z])


def view_frame(direction) -> np.ndarray:
    """(3,3) columns right, up, back (= direction, from the object to the camera) of an orthographic
    camera; up is world +z made orthogonal (world +y when the view is along z)."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    up = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = up - d * float(up @ d)
    u /= np.linalg.norm(u)
    return np.column_stack([np.cross(u, d), u, d])


def row_spans(T: np.ndarray):
    """(triangle index, row j, x from, x to) of every row centre j + 0.5 inside each triangle T (m,3,2)."""
    j0 = np.ceil(T[:, :, 1].min(axis=1) - 0.5).astype(np.int64)
    j1 = np.floor(T[:, :, 1].max(axis=1) - 0.5).astype(np.int64)
    count = np.maximum(j1 - j0 + 1, 0)
    tri = np.repeat(np.arange(len(T)), count)
    first = np.cumsum(count) - count
    j = j0[tri] + np.arange(tri.size) - first[tri]
    cy = j + 0.5
    xl = np.full(tri.size, np.inf)
    xr = np.full(tri.size, -np.inf)
    for a, b in ((0, 1), (1, 2), (2, 0)):  # where each edge crosses the row
        ya, yb = T[tri, a, 1], T[tri, b, 1]
        xa, xb = T[tri, a, 0], T[tri, b, 0]
        ok = (yb != ya) & (cy >= np.minimum(ya, yb)) & (cy <= np.maximum(ya, yb))
        x = xa + (cy - ya) * (xb - xa) / np.where(ok, yb - ya, 1.0)
        np.minimum(xl, np.where(ok, x, np.inf), out=xl)
        np.maximum(xr, np.where(ok, x, -np.inf), out=xr)
    has = xl <= xr
    return tri[has], j[has], xl[has], xr[has]


def _one_view(P: np.ndarray, z: np.ndarray, F: np.ndarray, size: int, depth: bool):
    """Silhouette (size,size) bool (row 0 at the top) and z-buffer of points P (n,2) in pixels (y up)."""
    T = P[F]
    tri, j, xl, xr = row_spans(T)
    i0 = np.clip(np.ceil(xl - 0.5).astype(np.int64), 0, size)
    i1 = np.clip(np.floor(xr - 0.5).astype(np.int64) + 1, 0, size)
    rows = np.clip(size - 1 - j, 0, size - 1)
    keep = i1 > i0
    cells = size * (size + 1)
    diff = (np.bincount(rows[keep] * (size + 1) + i0[keep], minlength=cells)
            - np.bincount(rows[keep] * (size + 1) + i1[keep], minlength=cells)).reshape(size, size + 1)
    sil = np.cumsum(diff, axis=1)[:, :size] > 0
    px = np.clip(np.floor(P).astype(np.int64), 0, size - 1)
    sil[size - 1 - px[:, 1], px[:, 0]] = True  # sub-pixel triangles
    if not depth:
        return sil, None
    zbuf = np.full(size * size, np.inf)
    tri, rows, i0, i1 = tri[keep], rows[keep], i0[keep], i1[keep]
    n = i1 - i0
    t = np.repeat(np.arange(len(tri)), n)
    x = i0[t] + np.arange(t.size) - np.repeat(np.cumsum(n) - n, n)
    # the triangle's plane: z = a x + b y + c through its three corners
    Tz = z[F[tri]]
    A = np.concatenate([T[tri], np.ones((len(tri), 3, 1))], axis=2)
    ok = np.abs(np.linalg.det(A)) > 1e-12
    coef = np.zeros((len(tri), 3))
    coef[ok] = np.linalg.solve(A[ok], Tz[ok][..., None])[..., 0]
    coef[~ok, 2] = Tz[~ok].min(axis=1)
    yc = (size - 1 - rows[t]) + 0.5
    zz = coef[t, 0] * (x + 0.5) + coef[t, 1] * yc + coef[t, 2]
    np.minimum.at(zbuf, rows[t] * size + x, zz)
    np.minimum.at(zbuf, (size - 1 - px[:, 1]) * size + px[:, 0], z)  # the vertices' own pixels
    return sil, zbuf.reshape(size, size)


def render_views(V, F, directions, size: int = 128, depth: bool = False):
    """Orthographic silhouettes of the mesh V (n,3), F (m,3) seen from ``directions`` (k,3) (object ->
    camera) -> (k, size, size) bool, and the z-buffers (k, size, size) float (or None without ``depth``).

    Each view's projection is centred and scaled to fill size - 2 MARGIN_PX pixels across its longer
    side.  BolusError on a mesh without faces, whose faces have no area, or with no view that shows one."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise BolusError("the model has no faces to render")
    if not np.isfinite(V).all():
        raise BolusError("the model has NaN or infinite vertex coordinates")
    D = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    used = np.unique(F)
    ext = float(np.ptp(V[used], axis=0).max())
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    if not area > 1e-9 * ext * ext:
        raise BolusError("the model's faces have no area (a point, a line or degenerate triangles only)")
    Vc = V - (V[used].min(axis=0) + V[used].max(axis=0)) / 2.0
    sils = np.zeros((len(D), size, size), dtype=bool)
    zb = np.full((len(D), size, size), np.inf) if depth else None
    inner = size - 2 * MARGIN_PX
    for k, d in enumerate(D):
        R = view_frame(d)
        P = Vc @ R[:, :2]
        lo, hi = P[used].min(axis=0), P[used].max(axis=0)
        ext = float((hi - lo).max())
        if not ext > 0:
            continue
        s = inner / ext
        P = (P - (lo + hi) / 2.0) * s + size / 2.0
        sils[k], zk = _one_view(P, -(Vc @ R[:, 2]) * s, F, size, depth)
        if depth:
            zb[k] = zk
    if not sils.any():
        raise BolusError("the model is flat or a point: no view shows an area")
    return sils, zb
