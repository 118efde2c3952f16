"""The graphs of a contour and of a model for their spectral features (eqs. 5-8..5-11): samples, links, weights."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..analysis.spectral import gaussian_weights
from ..errors import BolusError
from ..mesh.topology import MeshTopology

NEIGHBOUR_SHARE, MIN_NEIGHBOURS = 0.10, 10  #: contour graph: each point joined to 10 % of the points (>= 10)

FEATURE_DIMENSIONS = 3  #: k of 5.2.1: eigenvectors after the constant one


CONTOUR_SAMPLES = 1500  #: contour graphs are built on at most this many points (`contour_samples`)


def _finite_points(P, d: int, what: str) -> np.ndarray:
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != d:
        raise BolusError(f"{what} must be an (n, {d}) array, got shape {P.shape}")
    if not np.isfinite(P).all():
        raise BolusError(f"{what} contain NaN or infinite coordinates")
    return P


def _symmetric(rows, cols, d, n) -> sp.csr_matrix:
    """Symmetric csr (n,n) of distances d on the pairs (rows, cols), duplicates and self pairs removed."""
    rows, cols, d = np.asarray(rows), np.asarray(cols), np.asarray(d, dtype=np.float64)
    keep = rows != cols
    lo, hi = np.minimum(rows[keep], cols[keep]), np.maximum(rows[keep], cols[keep])
    key, first = np.unique(lo.astype(np.int64) * n + hi, return_index=True)
    lo, hi, d = key // n, key % n, d[keep][first]
    return sp.coo_matrix((np.r_[d, d], (np.r_[lo, hi], np.r_[hi, lo])), shape=(n, n)).tocsr()


def link_components(points, D: sp.spmatrix) -> sp.csr_matrix:
    """A connected graph: D (n,n) symmetric sparse edge lengths on points (n,d), plus, while it is in pieces,
    for every piece the shortest pair (i in it, j outside it) (Boruvka's rule: each round at least halves the
    number of pieces).  Returns (n,n) csr of lengths; D itself when already connected.  Stored zeros (equal
    points) count as edges."""
    P = np.asarray(points, dtype=np.float64)
    n = len(P)
    D = sp.csr_matrix(D)
    pattern = sp.csr_matrix((np.ones(D.nnz), D.indices, D.indptr), shape=D.shape)
    ncomp, lab = connected_components(pattern, directed=False)
    if ncomp <= 1:
        return D
    tree = cKDTree(P)
    kq = min(n, 16)
    dist, idx = tree.query(P, k=kq)
    dist, idx = dist.reshape(n, kq), idx.reshape(n, kq)
    add_r, add_c, add_d = [], [], []
    while ncomp > 1:
        other = lab[idx] != lab[:, None]
        dd = np.where(other, dist, np.inf)
        j = np.argmin(dd, axis=1)
        best_d = dd[np.arange(n), j]
        best_j = idx[np.arange(n), j]
        pairs = []
        for c in range(ncomp):
            members = np.flatnonzero(lab == c)
            i = members[np.argmin(best_d[members])]
            if np.isfinite(best_d[i]):
                pairs.append((i, best_j[i], best_d[i]))
            else:  # no other piece among the 16 nearest of any member: search the rest directly
                rest = np.flatnonzero(lab != c)
                dq, jq = cKDTree(P[rest]).query(P[members])
                a = int(np.argmin(dq))
                pairs.append((members[a], rest[jq[a]], dq[a]))
        for i, jj, d in pairs:
            add_r.append(i)
            add_c.append(jj)
            add_d.append(d)
        A = pattern + _symmetric(np.array(add_r), np.array(add_c), np.ones(len(add_r)), n)
        ncomp, lab = connected_components(A, directed=False)
    C = D.tocoo()
    E = _symmetric(np.r_[C.row, add_r], np.r_[C.col, add_c], np.r_[C.data, add_d], n)
    return E


def _weights_from_lengths(D: sp.csr_matrix) -> sp.csr_matrix:
    """Gaussian weights (eqs. 5-8, 5-10) of a symmetric length matrix, sigma the mean over its edges."""
    U = sp.triu(D, 1).tocoo()
    w = gaussian_weights(U.data)
    n = D.shape[0]
    return sp.coo_matrix((np.r_[w, w], (np.r_[U.row, U.col], np.r_[U.col, U.row])), shape=(n, n)).tocsr()


def contour_samples(points2d, count: int = CONTOUR_SAMPLES) -> np.ndarray:
    """Indices (min(P, count),) of contour points spread evenly over points2d (P,2): farthest-point sampling
    from the point nearest the centroid (deterministic; every point when P <= count)."""
    P = _finite_points(points2d, 2, "contour points")
    n, count = len(P), int(count)
    if n <= count:
        return np.arange(n)
    chosen = np.empty(count, np.int64)
    chosen[0] = int(np.argmin(((P - P.mean(axis=0)) ** 2).sum(axis=1)))
    d2 = ((P - P[chosen[0]]) ** 2).sum(axis=1)
    for i in range(1, count):
        chosen[i] = int(np.argmax(d2))
        np.minimum(d2, ((P - P[chosen[i]]) ** 2).sum(axis=1), out=d2)
    return np.sort(chosen)


def contour_graph(points2d, neighbours: int | None = None) -> sp.csr_matrix:
    """Edge lengths (P,P) csr of the symmetrised kNN graph of contour pixels points2d (P,2) (eq. 5-9 distances;
    each pixel joined to its ``neighbours`` nearest, by default ``NEIGHBOUR_SHARE`` of the points and at least
    ``MIN_NEIGHBOURS``; pieces linked by `link_components`)."""
    P = _finite_points(points2d, 2, "contour points")
    n = len(P)
    if n < FEATURE_DIMENSIONS + 2:
        raise BolusError(f"the contour has {n} points, too few for a feature space (at least "
                         f"{FEATURE_DIMENSIONS + 2})")
    k = max(MIN_NEIGHBOURS, int(round(NEIGHBOUR_SHARE * n))) if neighbours is None else int(neighbours)
    if k < 1:
        raise BolusError(f"neighbours must be at least 1, got {neighbours}")
    k = min(k + 1, n)
    dist, idx = cKDTree(P).query(P, k=k)
    rows = np.repeat(np.arange(n), k)
    return link_components(P, _symmetric(rows, idx.ravel(), dist.ravel(), n))


def mesh_graph(V, F) -> sp.csr_matrix:
    """Edge lengths (n,n) csr of a triangle mesh's one-ring graph (eq. 5-11 on the edges of V (n,3), F (m,3));
    pieces linked by `link_components`."""
    topo = MeshTopology(V, F)  # shapes, finiteness and indices checked here
    if topo.n < FEATURE_DIMENSIONS + 2:
        raise BolusError(f"the model has {topo.n} vertices, too few for a feature space (at least "
                         f"{FEATURE_DIMENSIONS + 2})")
    E = topo.edges
    return link_components(topo.V, _symmetric(E[:, 0], E[:, 1], topo.edge_lengths, topo.n))
