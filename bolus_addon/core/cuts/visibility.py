"""Openness of a surface: how much of the sky above each face is free (for `treatment_area`).

Definition ("seen from outside").  The openness of a triangle f with unit normal n and
centroid c is the cosine-weighted fraction of the hemisphere above it from which c can
be seen, the ambient-occlusion integral

    O(f) = (1/pi) * integral over {w : n.w > 0} of  vis(c, w) (n.w) dw,

vis(c, w) = 1 when the ray c + s w (s > 0) meets no triangle of the surface given.  O = 1
on a flat or convex piece, about 0.5 at the bottom of a right-angled crease, near 0
deep in a pocket whose opening is small (the inside of a nostril, an ear canal): such
faces face inward, towards the other walls of the pocket.  Both sides of the surface
are measured (n and -n); `treatment_area` takes the normals' side as the outside
unless the back is much more open (a mesh wound inside out).

Computation: K directions w spread evenly over the sphere (a Fibonacci lattice); for each
one the surface is rasterised orthographically along w into a height buffer (numpy;
the highest point along w in every pixel, vertices splatted too so no thin triangle
slips between pixel centres); c sees the sky along w when nothing in its pixel lies
higher than c by more than a tolerance that grows with the slope of f seen from w
(half a pixel on faces seen face-on, plus 0.75 pixel times the slope: f's own plane
within its pixel).  The integral is the weighted mean over the
directions in f's hemisphere.  With K = 96 directions the sampling error of O is about
0.05.
"""
from __future__ import annotations

import numpy as np

from ..errors import BolusError
from ..mesh.topology import as_mesh_arrays, face_normals, submesh

__all__ = ["fibonacci_directions", "openness", "DEFAULT_DIRECTIONS"]

#: directions over the whole sphere (half of them fall in a face's hemisphere)
DEFAULT_DIRECTIONS = 96
#: largest height buffer side (pixels): a coarser pixel is used on large surfaces
MAX_PIXELS_SIDE = 1024
#: largest default pixel (mm): a cavity a few pixels wide is resolved (a nostril is 8-10 mm across)
MAX_PIXEL_MM = 2.0


def fibonacci_directions(k: int) -> np.ndarray:
    """k unit vectors (k,3) spread evenly over the sphere (Fibonacci lattice)."""
    i = np.arange(k) + 0.5
    z = 1.0 - 2.0 * i / k
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _basis(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) perpendicular to w and to each other."""
    a = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(w, a)
    u /= np.linalg.norm(u)
    return u, np.cross(w, u)


def _height_buffer(P2: np.ndarray, H: np.ndarray, F: np.ndarray, origin: np.ndarray, pixel: float,
                   shape: tuple[int, int]) -> np.ndarray:
    """Highest H in every pixel (shape) of the triangles F on points P2 (n,2), -inf where none."""
    nx, ny = shape
    zbuf = np.full(nx * ny, -np.inf)
    T = P2[F]  # (m,3,2)
    lo = np.floor((T.min(axis=1) - origin) / pixel - 0.5).astype(np.int64) + 1
    hi = np.floor((T.max(axis=1) - origin) / pixel - 0.5).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [nx - 1, ny - 1])
    cx, cy = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0), np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    count = cx * cy
    tri = np.repeat(np.arange(len(F)), count)
    if len(tri):
        k = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
        ix = lo[tri, 0] + k % cx[tri]
        iy = lo[tri, 1] + k // cx[tri]
        q = origin + (np.stack([ix, iy], axis=1) + 0.5) * pixel
        a, b, c = T[tri, 0], T[tri, 1], T[tri, 2]
        v0, v1, v2 = b - a, c - a, q - a
        den = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):  # a triangle seen edge-on (den = 0) covers nothing
            s = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / den
            t = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / den
            inside = (s >= -1e-9) & (t >= -1e-9) & (s + t <= 1 + 1e-9) & (den != 0)
            Ht = H[F[tri]]
            h = Ht[:, 0] + s * (Ht[:, 1] - Ht[:, 0]) + t * (Ht[:, 2] - Ht[:, 0])
        np.maximum.at(zbuf, (ix * ny + iy)[inside], h[inside])
    iv = np.floor((P2 - origin) / pixel).astype(np.int64)
    okv = (iv[:, 0] >= 0) & (iv[:, 0] < nx) & (iv[:, 1] >= 0) & (iv[:, 1] < ny)
    np.maximum.at(zbuf, (iv[:, 0] * ny + iv[:, 1])[okv], H[okv])  # vertices: no thin triangle slips through
    return zbuf


def openness(V, F, faces=None, *, directions: int = DEFAULT_DIRECTIONS, pixel_mm: float | None = None,
             progress=None) -> tuple[np.ndarray, np.ndarray]:
    """Openness of triangles on both sides: (front (k,), back (k,)), each in [0, 1].

    Parameters
    ----------
    V : (n,3) mm; F : (m,3) the whole surface that may hide a face (the occluders);
    faces : (k,) indices of the triangles to measure (default all); directions : number
    of view directions over the sphere; pixel_mm : height-buffer pixel (default the
    median edge length of the faces measured, at most 2 mm, coarser only if the buffer
    would exceed 1024 pixels a side; half of it gave the same cavities on the ICT face in
    twice the time);
    progress : callable(fraction, text) or None.

    front is measured on the side of the triangle's normal (right-hand winding), back on
    the other side.  Zero-area triangles get openness 1 on both sides (no normal).
    """
    V, F = as_mesh_arrays(V, F)
    if len(F) == 0:
        raise BolusError("openness needs a surface with triangles")
    faces = np.arange(len(F)) if faces is None else np.asarray(faces, dtype=np.int64)
    F, used = submesh(F, slice(None))  # only the vertices of the triangles: the buffer spans just them
    V = V[used]
    if directions < 8:
        raise BolusError(f"openness needs at least 8 view directions, got {directions}")
    Fq = F[faces] if len(faces) else F
    E = np.r_[Fq[:, [0, 1]], Fq[:, [1, 2]]]
    edge = float(np.median(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)))  # of the faces measured
    span = float((V.max(axis=0) - V.min(axis=0)).max())
    pixel = float(pixel_mm) if pixel_mm else max(min(edge, MAX_PIXEL_MM), span * np.sqrt(3.0) / MAX_PIXELS_SIDE, 1e-9)
    C = V[F[faces]].mean(axis=1)
    N = face_normals(V, F)[faces]
    has_normal = np.isfinite(N).all(axis=1) & (np.linalg.norm(N, axis=1) > 0.5)
    N = np.where(has_normal[:, None], N, 0.0)
    seen = np.zeros((2, len(faces)))
    total = np.zeros((2, len(faces)))
    W = fibonacci_directions(int(directions))
    for k, w in enumerate(W):
        if progress is not None and k % 8 == 0:
            progress(k / len(W), "openness")
        u, v = _basis(w)
        P2 = np.stack([V @ u, V @ v], axis=1)
        H = V @ w
        origin = P2.min(axis=0) - pixel
        shape = tuple(int(x) for x in np.ceil((P2.max(axis=0) + pixel - origin) / pixel))
        zbuf = _height_buffer(P2, H, F, origin, pixel, shape)
        cos = N @ w
        c2 = np.stack([C @ u, C @ v], axis=1)
        ic = np.clip(np.floor((c2 - origin) / pixel).astype(np.int64), 0, [shape[0] - 1, shape[1] - 1])
        a = np.abs(cos)
        slope = np.sqrt(np.maximum(0.0, 1.0 - a * a)) / np.maximum(a, 1e-3)
        tol = pixel * (0.5 + 0.75 * np.minimum(slope, 4.0))  # f's own plane within its pixel: 0.71 px * slope
        vis = zbuf[ic[:, 0] * shape[1] + ic[:, 1]] <= C @ w + tol
        front = cos > 0
        seen[0] += np.where(front, cos * vis, 0.0)
        total[0] += np.where(front, cos, 0.0)
        seen[1] += np.where(~front, a * vis, 0.0)
        total[1] += np.where(~front, a, 0.0)
    out = np.where(total > 0, seen / np.maximum(total, 1e-300), 1.0)
    out[:, ~has_normal] = 1.0
    return out[0], out[1]
