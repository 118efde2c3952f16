"""Distance along the surface from a point on it (for `treatment_area`).

Method: front propagation with the unfolding ("two-circle", virtual source) triangle
update, as in fast marching on triangulated surfaces (Kimmel & Sethian 1998) with the
source-point update of Novotni & Klein (2002): for corner i of a triangle (i, j, l)
unfolded into the plane, the virtual source s lies at distance d_j from j and d_l from
l beyond edge jl; when the straight segment s-i crosses that edge, d_i = |i - s|,
otherwise the path runs along an edge (d_j + |ij|, d_l + |il|).  Starting from the
exact distances at the source triangle's corners, the update is repeated (d only
decreases) until no vertex changes.

Accuracy (tests/test_core_treatment_area.py): exact up to rounding on a flat mesh of
any triangulation (the unfolding of a plane is the plane itself: 2e-10 mm at 50 mm on
a jittered grid, where the heat method of Crane et al. with t = h^2 was off by 2.2 mm);
on a sphere cap of radius 100 mm with 3.8 mm triangles within 0.03 mm of the
great-circle distance up to 50 mm.  On a curved surface each triangle's unfolding is
flat, so the error is second order in the edge length; paths that bend around a saddle
vertex are taken along edges there (a slight over-estimate).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import BolusError
from .topology import as_mesh_arrays, check_mesh

__all__ = ["geodesic_distance", "barycentric", "closest_point_on_mesh"]


def barycentric(P: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Barycentric weights (k,3) of points P (k,3) in triangles T (k,3,3) (projected on their planes)."""
    a, b, c = T[:, 0], T[:, 1], T[:, 2]
    v0, v1, v2 = b - a, c - a, P - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = np.maximum(d00 * d11 - d01 * d01, 1e-300)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return np.stack([1.0 - v - w, v, w], axis=1)


def _closest_on_triangles(p: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Closest point (k,3) to p (3,) on each triangle T (k,3,3) (Ericson, Real-Time Collision Detection 5.1.5)."""
    a, b, c = T[:, 0], T[:, 1], T[:, 2]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    den = np.where(np.abs(va + vb + vc) > 1e-300, va + vb + vc, 1e-300)
    out = a + ab * (vb / den)[:, None] + ac * (vc / den)[:, None]  # inside the face
    with np.errstate(divide="ignore", invalid="ignore"):
        # edges (checked before vertices: the vertex regions below overwrite them)
        t_ab = d1 / (d1 - d3)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        out[m] = (a + ab * t_ab[:, None])[m]
        t_ac = d2 / (d2 - d6)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        out[m] = (a + ac * t_ac[:, None])[m]
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        out[m] = (b + (c - b) * t_bc[:, None])[m]
    m = (d1 <= 0) & (d2 <= 0)
    out[m] = a[m]
    m = (d3 >= 0) & (d4 <= d3)
    out[m] = b[m]
    m = (d6 >= 0) & (d5 <= d6)
    out[m] = c[m]
    return out


def closest_point_on_mesh(V: np.ndarray, F: np.ndarray, p) -> tuple[np.ndarray, int, float]:
    """The surface point nearest to p (3,): (point (3,), triangle index, distance).

    Exact point-triangle distance on every triangle (vectorised; about 20 ms per 100k
    triangles)."""
    V, F = as_mesh_arrays(V, F)
    p = np.asarray(p, dtype=np.float64).reshape(3)
    if len(F) == 0:
        raise BolusError("the surface has no triangles")
    Q = _closest_on_triangles(p, V[F])
    d2 = ((Q - p) ** 2).sum(1)
    d2[~np.isfinite(d2)] = np.inf  # a zero-area triangle (no closest point of its own)
    f = int(np.argmin(d2))
    return Q[f], f, float(np.sqrt(d2[f]))


def geodesic_distance(V, F, source_point, source_face: int, *, max_mm: float = np.inf) -> np.ndarray:
    """Distance along the surface (n,) mm from a point on triangle ``source_face``.

    Parameters
    ----------
    V : (n,3) mm; F : (m,3); source_point : (3,) a point on triangle ``source_face``
    (a point off it is taken at its projection on the triangle's plane, clamped into
    the triangle); max_mm : stop the front there (vertices farther away get ``inf``;
    those nearer are not affected, their shortest paths stay nearer).

    Returns d (n,): ``inf`` also on vertices not connected to the source triangle and
    on vertices in no triangle.  Raises `BolusError` for a broken mesh (`check_mesh`:
    NaN/inf, zero-area triangles, which have no unfolding) or a bad source.
    """
    V, F = check_mesh(V, F, "the surface")
    if not 0 <= int(source_face) < len(F):
        raise BolusError(f"source triangle {source_face} is not one of the {len(F)} triangles")
    p = np.asarray(source_point, dtype=np.float64).reshape(3)
    if not np.isfinite(p).all():
        raise BolusError("the source point has a non-finite coordinate")
    corners = F[int(source_face)]
    w = np.clip(barycentric(p[None], V[corners][None])[0], 0.0, None)
    p = (w / w.sum()) @ V[corners]
    d = np.full(len(V), np.inf)
    d[corners] = np.linalg.norm(V[corners] - p, axis=1)
    return _propagate(V, F, d, max_mm=float(max_mm))


def _propagate(V: np.ndarray, F: np.ndarray, d: np.ndarray, max_mm: float = np.inf) -> np.ndarray:
    """Relax d (n,) to the fixed point of the unfolding (two-circle) triangle update.

    For corner i of a triangle (i, j, l) laid flat with j at the origin and l on the x
    axis, the virtual source s is the point at distance d_j from j and d_l from l on the
    far side of edge jl; if the segment s-i crosses edge jl, |i - s| is a candidate for
    d_i, else d_j + |ij| and d_l + |il| are.  d only decreases; passes run until nothing
    changes (every pass only revisits the triangles next to a changed vertex).
    """
    n = len(V)
    I = np.concatenate([F[:, 0], F[:, 1], F[:, 2]])
    J = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    Lv = np.concatenate([F[:, 2], F[:, 0], F[:, 1]])
    a, e = V[I] - V[J], V[Lv] - V[J]
    L = np.linalg.norm(e, axis=1)
    xi = (a * e).sum(1) / L
    yi = np.linalg.norm(np.cross(a, e), axis=1) / L
    lij = np.linalg.norm(a, axis=1)
    lil = np.linalg.norm(V[I] - V[Lv], axis=1)
    # corners touching each vertex through j or l (to revisit after a change)
    touch = sp.csr_matrix((np.ones(2 * len(I)), (np.r_[J, Lv], np.r_[np.arange(len(I)), np.arange(len(I))])),
                          shape=(n, len(I)))
    active = np.nonzero(np.isfinite(d[J]) | np.isfinite(d[Lv]))[0]
    for _ in range(4 * n + 100):  # a pass moves the front by at least one ring: never reached
        if not len(active):
            break
        i, j, l = I[active], J[active], Lv[active]
        dj, dl = d[j], d[l]
        cand = np.minimum(dj + lij[active], dl + lil[active])
        both = np.isfinite(dj) & np.isfinite(dl)
        Ls = L[active]
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            sx = (dj * dj - dl * dl + Ls * Ls) / (2.0 * Ls)
            sy2 = dj * dj - sx * sx
            ok = both & (sy2 >= 0)
            sy = -np.sqrt(np.where(ok, sy2, 0.0))
            x, y = xi[active], yi[active]
            tt = -sy / np.maximum(y - sy, 1e-300)
            xc = sx + tt * (x - sx)
            ok &= (xc >= 0) & (xc <= Ls)
            direct = np.sqrt((x - sx) ** 2 + (y - sy) ** 2)
        cand = np.where(ok, np.minimum(cand, direct), cand)
        cand[cand > max_mm] = np.inf
        best = np.full(n, np.inf)
        np.minimum.at(best, i, cand)
        changed = best < d * (1.0 - 1e-12) - 1e-12
        if not changed.any():
            break
        d = np.where(changed, best, d)
        active = np.unique(touch[np.nonzero(changed)[0]].indices)
    return d
