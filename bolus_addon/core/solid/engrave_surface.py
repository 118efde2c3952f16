"""The outer face of a closed solid seen from outside, for engraving (core/engrave.py).

`_Surface` holds the solid V (n,3) mm, F (m,3) with face classes side (m,) SIDE_*: face normals,
smooth vertex normals of the outer face, spots (points sampled every SPOT_SPACING_MM on the outer
face), points on the rim / cut / connector faces, and the solid as a face-tracked Manifold.
`_Surface.project` finds, for points of a tangent plane, the first face met coming from outside
along its normal (the S(x, y) of engrave.py's docstring).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

import manifold3d as m3

from ..errors import BolusError
from .manifold import SIDE_CONNECTOR, SIDE_CUT, SIDE_OUTER, SIDE_RIM, to_manifold

#: spacing of the points sampled on the faces to find spots (mm)
SPOT_SPACING_MM = 1.0
#: sides that bound the outer face: the text keeps its distance from them
_BOUNDING_SIDES = (SIDE_RIM, SIDE_CUT, SIDE_CONNECTOR)


def _sample_faces(V, F, faces, spacing):
    """Points on the triangles ``faces`` at about ``spacing`` (barycentric grids): (points (s,3),
    face (s,), bary (s,3))."""
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    T = V[F[faces]]
    longest = np.max(np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2), axis=1)
    nsub = np.clip(np.ceil(longest / spacing), 1, 64).astype(np.int64)
    pts, fs, bs = [], [], []
    for n in np.unique(nsub):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = (i + j) <= n
        b = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], axis=1) / n
        b = np.r_[b, [[1 / 3, 1 / 3, 1 / 3]]]
        sel = np.nonzero(nsub == n)[0]
        P = np.einsum("kj,fjd->fkd", b, T[sel]).reshape(-1, 3)
        pts.append(P)
        fs.append(np.repeat(faces[sel], len(b)))
        bs.append(np.tile(b, (len(sel), 1)))
    return np.concatenate(pts), np.concatenate(fs), np.concatenate(bs)


def _thin_out(P, h):
    """Indices (sorted) of one point of P (k,3) per cube of side h."""
    if len(P) == 0:
        return np.zeros(0, dtype=np.int64)
    key = np.floor((P - P.min(axis=0)) / h).astype(np.int64)
    dims = key.max(axis=0) + 1
    flat = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
    return np.sort(np.unique(flat, return_index=True)[1])


def _locate_2d(Q, T):
    """All (point, triangle, barycentrics) with point Q[i] (k,2) inside triangle T[t] (c,3,2)
    (closed, edge-on triangles skipped), through a uniform grid of cells."""
    lo, hi = T.min(axis=1), T.max(axis=1)
    cell = max(float(np.median(np.max(hi - lo, axis=1))), 1e-6)
    qlo = Q.min(axis=0) - cell
    qhi = Q.max(axis=0) + cell
    keep = np.nonzero(np.all(hi >= qlo, axis=1) & np.all(lo <= qhi, axis=1))[0]
    empty = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
    if len(keep) == 0 or len(Q) == 0:
        return empty
    ncell = np.ceil((qhi - qlo) / cell).astype(np.int64) + 1
    i0 = np.clip(np.floor((lo[keep] - qlo) / cell).astype(np.int64), 0, ncell - 1)
    i1 = np.clip(np.floor((hi[keep] - qlo) / cell).astype(np.int64), 0, ncell - 1)
    span = i1 - i0 + 1
    cnt = span[:, 0] * span[:, 1]
    tri = np.repeat(keep, cnt)
    local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    w = np.repeat(span[:, 0], cnt)
    cid = (np.repeat(i0[:, 0], cnt) + local % w) * ncell[1] + np.repeat(i0[:, 1], cnt) + local // w
    order = np.argsort(cid, kind="stable")
    cid, tri = cid[order], tri[order]
    qc = np.clip(np.floor((Q - qlo) / cell).astype(np.int64), 0, ncell - 1)
    qid = qc[:, 0] * ncell[1] + qc[:, 1]
    a = np.searchsorted(cid, qid, "left")
    n = np.searchsorted(cid, qid, "right") - a
    qi = np.repeat(np.arange(len(Q)), n)
    ti = tri[np.repeat(a, n) + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)]
    A = T[ti, 0]
    e1, e2, q = T[ti, 1] - A, T[ti, 2] - A, Q[qi] - A
    den = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]
    scale = np.maximum(np.abs(e1).max(axis=1), np.abs(e2).max(axis=1)) ** 2
    ok = np.abs(den) > 1e-12 * scale
    den = np.where(ok, den, 1.0)
    b1 = (q[:, 0] * e2[:, 1] - e2[:, 0] * q[:, 1]) / den
    b2 = (e1[:, 0] * q[:, 1] - q[:, 0] * e1[:, 1]) / den
    b0 = 1.0 - b1 - b2
    eps = 1e-9
    inside = ok & (b0 >= -eps) & (b1 >= -eps) & (b2 >= -eps)
    return qi[inside], ti[inside], np.stack([b0, b1, b2], axis=1)[inside]


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-300, n, 1.0)


class _Surface:
    """A closed solid V, F with face classes ``side``: its outer face seen from outside."""

    def __init__(self, V, F, side, what="the solid"):
        self.V, self.F, self.side, self.what = V, F, side, what
        T = V[F]
        cr = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
        self.fn = _unit(cr)
        outer = np.nonzero(side == SIDE_OUTER)[0]
        vn = np.zeros_like(V)
        np.add.at(vn, F[outer].ravel(), np.repeat(cr[outer], 3, axis=0))
        self.vn = _unit(vn)
        spots, face, bary = _sample_faces(V, F, outer, SPOT_SPACING_MM)
        keep = _thin_out(spots, SPOT_SPACING_MM)
        self.spots, self.spot_face, self.spot_bary = spots[keep], face[keep], bary[keep]
        self.spot_tree = cKDTree(self.spots)
        bounds = _sample_faces(V, F, np.nonzero(np.isin(side, _BOUNDING_SIDES))[0], SPOT_SPACING_MM)[0]
        self.bounds = bounds[_thin_out(bounds, SPOT_SPACING_MM)]
        self.M, self.sid = _tracked_manifold(V, F, what)
        self.centroids = T.mean(axis=1)
        self.ctree = cKDTree(self.centroids)
        self.frad = float(np.linalg.norm(T - self.centroids[:, None], axis=2).max())
        Vc = V - V.mean(axis=0)
        self.axes = np.linalg.svd(Vc, full_matrices=False)[2] if len(V) >= 3 else np.eye(3)

    def normal_at(self, face, bary):
        """Smooth normal N (k,3) at points (face, bary) and c = N . n_face (k,) (> 0)."""
        N = _unit(np.einsum("kj,kjd->kd", bary, self.vn[self.F[face]]))
        N = np.where(np.linalg.norm(N, axis=1, keepdims=True) > 0.5, N, self.fn[face])
        c = np.einsum("kd,kd->k", N, self.fn[face])
        return N, c

    def project(self, p, n0, Q, reach):
        """The first face facing n0 met coming from outside along n0 through each point Q (k,3) of
        the plane through p normal to n0, within ``reach`` mm above / below it: face (k,) (-1: none),
        the hit X (k,3), barycentrics (k,3)."""
        k = len(Q)
        face = np.full(k, -1, dtype=np.int64)
        X = np.full((k, 3), np.nan)
        bary = np.zeros((k, 3))
        r = _unit(np.cross(n0, [1.0, 0.0, 0.0] if abs(n0[0]) < 0.9 else [0.0, 1.0, 0.0]))
        u = np.cross(n0, r)
        B = np.stack([r, u], axis=1)
        if k == 0:
            return face, X, bary
        rho = float(np.linalg.norm(Q - p, axis=1).max())
        near = np.asarray(self.ctree.query_ball_point(p, np.hypot(rho, reach) + self.frad), dtype=np.int64)
        # faces seen from outside along n0 (a fold over the spot shows up as a jump in height)
        near = near[(np.abs((self.centroids[near] - p) @ n0) <= reach + self.frad) & (self.fn[near] @ n0 > 0)]
        if len(near) == 0:
            return face, X, bary
        T = self.V[self.F[near]] - p
        qi, ti, b = _locate_2d((Q - p) @ B, T @ B)
        if len(qi) == 0:
            return face, X, bary
        ti = near[ti]
        Xh = np.einsum("kj,kjd->kd", b, self.V[self.F[ti]])
        hh = (Xh - p) @ n0
        order = np.lexsort((-hh, qi))
        first = order[np.r_[True, qi[order][1:] != qi[order][:-1]]]
        face[qi[first]] = ti[first]
        X[qi[first]] = Xh[first]
        bary[qi[first]] = b[first]
        return face, X, bary


def _tracked_manifold(V, F, what):
    """The solid as a Manifold whose faces remember their index in F through booleans:
    (Manifold, its run's original id)."""
    sid = int(m3.Manifold.reserve_ids(1))
    m = len(F)
    mesh = m3.Mesh64(vert_properties=np.array(V, dtype=np.float64, order="C"),
                     tri_verts=np.array(F, dtype=np.uint64, order="C"),
                     run_index=np.array([0, 3 * m], dtype=np.uint64),
                     run_original_id=np.array([sid], dtype=np.uint32),
                     face_id=np.arange(m, dtype=np.uint64))
    M = m3.Manifold(mesh)
    if str(M.status()).split(".")[-1] != "NoError":
        to_manifold(V, F, what)  # raises the named problem
        raise BolusError(f"{what} could not be read as a closed solid ({M.status()})")
    return M, sid
