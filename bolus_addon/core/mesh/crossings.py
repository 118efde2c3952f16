"""Triangles of one mesh that cross each other, found without a Python call per pair.

Two triangles that share no vertex cross when an edge of one passes strictly through the
other (coplanar overlaps and touches are left out: the check is for a mesher's closed solid).
An edge (a, b) passes through (p, q, r) when a and b lie strictly on opposite sides of the
plane of (p, q, r) (signed volumes) and the line ab passes inside the triangle (the three
volumes (a, b, p, q), (a, b, q, r), (a, b, r, p) share one sign).  Candidate pairs are those whose
bounding spheres (centroid, farthest corner) meet, from k-d trees of the centroids.
Arrays: V (n,3) float64, F (m,3) int; pairs (k,2) int64.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["crossing_pairs"]

_CHUNK = 500_000  #: candidate pairs tested at a time
#: volumes within this share of the pair's extent cubed count as zero (rounding)
REL_EPS = 1e-9


def _vol(a, b, c, d) -> np.ndarray:
    """(k,) six times the signed volume of the tetrahedra (a, b, c, d), each (k,3)."""
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)


def _edge_through(a, b, p, q, r, eps) -> np.ndarray:
    """(k,) bool: the segment a-b passes through the triangle (p, q, r), each (k,3): its ends
    strictly on either side of the plane and the line strictly inside the three edges (signed
    volumes beyond eps (k,): a touch is not a crossing)."""
    sa, sb = _vol(p, q, r, a), _vol(p, q, r, b)
    across = ((sa > eps) & (sb < -eps)) | ((sa < -eps) & (sb > eps))
    v1, v2, v3 = _vol(a, b, p, q), _vol(a, b, q, r), _vol(a, b, r, p)
    inside = ((v1 > eps) & (v2 > eps) & (v3 > eps)) | ((v1 < -eps) & (v2 < -eps) & (v3 < -eps))
    return across & inside


def _cross(V, F, i, j) -> np.ndarray:
    """(k,) bool: triangles F[i] and F[j] cross (an edge of either through the other, by more
    than `REL_EPS` of the pair's extent cubed in every volume: rounding)."""
    A, B = V[F[i]], V[F[j]]
    apart = np.any((A.min(axis=1) > B.max(axis=1)) | (B.min(axis=1) > A.max(axis=1)), axis=1)
    A, B = A[~apart], B[~apart]
    L = np.maximum(np.ptp(A, axis=1).max(axis=1), np.ptp(B, axis=1).max(axis=1))
    eps = REL_EPS * L ** 3
    hit = np.zeros(len(A), dtype=bool)
    for T, S in ((A, B), (B, A)):
        for e in range(3):
            hit |= _edge_through(T[:, e], T[:, (e + 1) % 3], S[:, 0], S[:, 1], S[:, 2], eps)
    out = np.zeros(len(i), dtype=bool)
    out[np.nonzero(~apart)[0]] = hit
    return out


def _candidates(cen, rad, sel):
    """(i, j) (k,) each: triangles i of sel and j whose bounding spheres (centroid cen (m,3),
    radius rad (m,)) meet, j != i.  The triangles are binned by radius in powers of two and
    each pair of bins is searched with its own bound (k-d trees, pairs gathered in compiled
    code), so a few large ones (a merged plane) do not widen the search around the small ones."""
    level = np.ceil(np.log2(np.maximum(rad, 1e-12))).astype(np.int64)
    bins = {lv: np.nonzero(level == lv)[0] for lv in np.unique(level)}
    mine = {lv: m for lv in np.unique(level[sel]) if len(m := sel[level[sel] == lv])}
    trees = {lv: cKDTree(cen[m]) for lv, m in bins.items()}
    I, J = [], []
    for la, a in mine.items():
        ta = cKDTree(cen[a])
        for lb, b in bins.items():
            pairs = ta.sparse_distance_matrix(trees[lb], float(rad[a].max() + rad[b].max()),
                                              output_type="ndarray")
            i, j = a[pairs["i"]], b[pairs["j"]]
            keep = (i != j) & (pairs["v"] <= rad[i] + rad[j])
            I.append(i[keep])
            J.append(j[keep])
    if not I:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate(I), np.concatenate(J)


def crossing_pairs(V, F, among=None, float32: bool = False) -> np.ndarray:
    """(k,2) pairs (i, j), i < j, of triangles of (V, F) that cross and share no vertex index
    (two triangles that only meet at one position do not cross); among: (a,) triangle
    indices: only pairs with at least one of them (all when None); float32: test the
    positions as a float32 file (STL) or Blender's checks hold them."""
    V = np.asarray(V, dtype=np.float64)
    if float32:
        V = V.astype(np.float32).astype(np.float64)
    F = np.asarray(F, dtype=np.int64)
    if len(F) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    P = V[F]
    cen = P.mean(axis=1)
    rad = np.linalg.norm(P - cen[:, None], axis=2).max(axis=1)
    sel = np.arange(len(F)) if among is None else np.unique(np.asarray(among, dtype=np.int64))
    i, j = _candidates(cen, rad, sel)
    out = []
    for s in range(0, len(i), _CHUNK):
        a, b = i[s:s + _CHUNK], j[s:s + _CHUNK]
        shared = (F[a][:, :, None] == F[b][:, None, :]).any(axis=(1, 2))
        a, b = a[~shared], b[~shared]
        hit = _cross(V, F, a, b)
        out.append(np.sort(np.stack([a[hit], b[hit]], axis=1), axis=1))
    pairs = np.concatenate(out) if out else np.zeros((0, 2), dtype=np.int64)
    return np.unique(pairs, axis=0) if len(pairs) else pairs.reshape(0, 2)
