"""Feature skeletons of photos' contours and of models, compared by ICP (seed 5.2-5.3, eqs. 5-8..5-14).

1. Feature spaces (5.2.1): a graph with Gaussian weights W_ij = exp(-d_ij^2 / (2 sigma^2)), sigma the
   mean d_ij over its edges (eqs. 5-8, 5-10), L = D - W (eq. 3-3); the k = 3 eigenvectors after the
   constant one.  Model vertices (`model_embedding`, eqs. 5-10, 5-11): the one-ring graph; contour
   pixels (`image_embedding`, eqs. 5-8, 5-9): a kNN graph joining each point to ``NEIGHBOUR_SHARE``
   (10 %) of at most ``CONTOUR_SAMPLES`` points (`contour_samples`).  Pieces are joined by
   `link_components`; the eigenproblem is `smallest_pairs` (shift-invert Lanczos, `nested_dissection`).
2. Skeletons (5.2.2, `skeleton`) of an embedding E (n,3), centred and scaled to unit RMS: centre
   vertex v0 (nearest the centroid), r_i = |E_i - E_v0|; GMM clusters (``DEFAULT_CLUSTERS`` = 6 or
   'auto': lowest BIC over ``AUTO_CLUSTERS``), clusters holding several branches divided; in each set
   the vertex farthest from v0 an 'end' or a 'branch' point; one shortest-path tree from v0 to the
   ends ('rendezvous' where paths part); points closer than ``MERGE_RADIUS`` along it merged.
3. `resample`: ``count`` (64) points evenly spaced by length along the skeleton's segments.
4. `icp` (eqs. 5-12, 5-13): Y moved onto X by closest-point pairs (Z^k) and Kabsch fits of (R, T), from
   the 48 signed permutation matrices (and random rotations by ``rng``); error: the RMS of eq. 5-14.
5. `dissimilarity`: both skeletons resampled, centred at v0, scaled to unit RMS radius
   (`skeleton_samples`), ICP both ways, the mean of the two RMS errors (0 for a skeleton and itself).
Design notes: docs/design/retrieval.md.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.sparse.linalg import LinearOperator, eigsh, splu
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from ..analysis.clustering import REG_COVAR
from ..errors import BolusError
from ..rng import as_rng
from ..analysis.spectral import gaussian_weights, graph_laplacian, smallest_eigenvectors
from ..mesh.topology import MeshTopology
from .skeleton_graphs import (  # noqa: F401 (re-exported)
    NEIGHBOUR_SHARE,
    MIN_NEIGHBOURS,
    FEATURE_DIMENSIONS,
    CONTOUR_SAMPLES,
    _finite_points,
    _symmetric,
    link_components,
    _weights_from_lengths,
    contour_samples,
    contour_graph,
    mesh_graph,
)
from .skeleton_icp import (  # noqa: F401 (re-exported)
    SAMPLES,
    Skeleton,
    resample,
    skeleton_samples,
    start_rotations,
    _kabsch,
    icp,
    dissimilarity,
)

__all__ = [
    "FEATURE_DIMENSIONS",
    "DEFAULT_CLUSTERS",
    "AUTO_CLUSTERS",
    "Skeleton",
    "link_components",
    "contour_samples",
    "contour_graph",
    "mesh_graph",
    "nested_dissection",
    "smallest_pairs",
    "spectral_embedding",
    "image_embedding",
    "model_embedding",
    "skeleton",
    "model_skeleton",
    "image_skeleton",
    "resample",
    "skeleton_samples",
    "start_rotations",
    "icp",
    "dissimilarity",
]

DEFAULT_CLUSTERS = 6  #: GMM clusters of `skeleton` (module doc)
AUTO_CLUSTERS = (3, 4, 5, 6, 7, 8)  #: clusters='auto': the count of lowest BIC among these
GMM_ROWS = 4000  #: the mixture is fitted on at most this many rows (drawn evenly), then labels all
GMM_RESTARTS = 2  #: mixture restarts (best likelihood)
BRANCH_SHARE = 0.10  #: a piece of a cluster's outer half is a branch when it holds >= 10 % of that half
END_MIN_RADIUS = 0.25  #: an end lies at >= 25 % of the largest distance from v0
MERGE_RADIUS = 0.02  #: skeleton points closer than 2 % of the RMS radius along the tree are one point
DENSE_MAX = 300  #: dense eigensolver up to this many vertices


# ---------------------------------------------------------------------------------------------- graphs


# ---------------------------------------------------------------------------------------------- embeddings


def nested_dissection(A: sp.spmatrix, coords, leaf: int = 32) -> np.ndarray:
    """A fill-reducing elimination order (n,) of the graph A (n,n) whose vertices sit at coords (n,d): split at
    the median of the longest extent, the vertices of one half touching the other half are the separator,
    ordered last, both halves recursively (geometric nested dissection; pieces of <= ``leaf`` vertices kept)."""
    A = sp.csr_matrix(A)
    A = sp.csr_matrix((np.ones(A.nnz), A.indices, A.indptr), shape=A.shape)  # the pattern (L has negative entries)
    X = np.asarray(coords, dtype=np.float64)
    n = A.shape[0]
    out, stack = [], [(np.arange(n), False)]
    while stack:  # post-order without recursion: left half, right half, separator
        idx, done = stack.pop()
        if done or len(idx) <= leaf:
            out.append(idx)
            continue
        P = X[idx]
        ax = int(np.argmax(P.max(axis=0) - P.min(axis=0)))
        left = P[:, ax] < np.median(P[:, ax])
        if left.all() or not left.any():
            out.append(idx)
            continue
        mask = np.zeros(n)
        mask[idx[left]] = 1.0
        rest = idx[~left]
        touch = (A[rest] @ mask) > 0
        stack.append((rest[touch], True))
        stack.append((rest[~touch], False))
        stack.append((idx[left], False))
    return np.concatenate(out)


def smallest_pairs(L: sp.spmatrix, k: int, rng=0, coords=None) -> tuple[np.ndarray, np.ndarray]:
    """The k smallest eigenpairs of a graph Laplacian L (n,n): (values (k,) ascending, vectors (n,k)), signs
    fixed as `spectral.smallest_eigenvectors` fixes them.  Above ``DENSE_MAX`` vertices: shift-invert Lanczos
    on one sparse LU factor, in the `nested_dissection` order of coords (n,d) when given, else SuperLU's
    symmetric minimum degree order; start vector from ``rng``.  Factor entries, 41k-vertex sphere: 4.3M
    (nested dissection, 0.3 s), 7.3M (SuperLU's default COLAMD), 11.8M (minimum degree); 50k-vertex torus:
    7.2M, 11.3M, 4.8M."""
    n = L.shape[0]
    if n <= DENSE_MAX or k >= n - 1:
        return smallest_eigenvectors(L, k, rng)
    L = sp.csr_matrix(L)
    scale = float(np.abs(L.diagonal()).mean()) or 1.0
    shift = -1e-6 * scale  # L is singular: L - shift I is positive definite (diagonal pivots are stable)
    M = L - shift * sp.identity(n, format="csr")
    if coords is not None:
        p = nested_dissection(L, coords)
        lu = splu(M[p][:, p].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        inv = np.empty(n, np.int64)
        inv[p] = np.arange(n)

        def solve(x):
            return lu.solve(np.ascontiguousarray(x[p]))[inv]
    else:
        lu = splu(M.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        solve = lu.solve
    op = LinearOperator((n, n), matvec=solve, dtype=np.float64)
    vals, vecs = eigsh(L, k=k, sigma=shift, which="LM", OPinv=op, v0=as_rng(rng).standard_normal(n), tol=1e-10)
    order = np.argsort(vals)
    vals, vecs = vals[order], vecs[:, order]
    idx = np.argmax(np.abs(vecs), axis=0)
    signs = np.sign(vecs[idx, np.arange(k)])
    signs[signs == 0] = 1.0
    return vals, vecs * signs


def spectral_embedding(D: sp.spmatrix, k: int = FEATURE_DIMENSIONS, rng=0, coords=None) -> np.ndarray:
    """Feature space (n,k) of a connected graph given by its edge lengths D (n,n): Gaussian weights, L = D - W,
    the eigenvectors of the k smallest non-zero eigenvalues (the constant one dropped).  coords (n,d),
    optional: vertex positions, for the elimination order (`smallest_pairs`)."""
    n = D.shape[0]
    k = int(k)
    if k < 1 or n < k + 2:
        raise BolusError(f"cannot take {k} feature dimensions from a graph of {n} vertices")
    _, U = smallest_pairs(graph_laplacian(_weights_from_lengths(sp.csr_matrix(D))), k + 1, rng, coords)
    return U[:, 1:]


def image_embedding(points2d, k: int = FEATURE_DIMENSIONS, neighbours: int | None = None, rng=0) -> np.ndarray:
    """Feature space (P,k) of contour pixels points2d (P,2) (eqs. 5-8, 5-9 on a kNN graph, module doc).  Above
    ``CONTOUR_SAMPLES`` points the graph is built on `contour_samples` and every point takes the feature
    coordinates of its nearest sample."""
    P = _finite_points(points2d, 2, "contour points")
    idx = contour_samples(P)
    U = spectral_embedding(contour_graph(P[idx], neighbours), k, rng, P[idx])
    if len(idx) == len(P):
        return U
    return U[cKDTree(P[idx]).query(P)[1]]


def model_embedding(V, F, k: int = FEATURE_DIMENSIONS, rng=0) -> np.ndarray:
    """Feature space (n,k) of a triangle mesh's vertices V (n,3), F (m,3) (eqs. 5-10, 5-11, one-ring W)."""
    V = np.asarray(V, dtype=np.float64)
    return spectral_embedding(mesh_graph(V, F), k, rng, V)


# ---------------------------------------------------------------------------------------------- skeleton


def _gmm(X: np.ndarray, count, rng: np.random.Generator, means_init=None) -> np.ndarray:
    """Labels (n,) of a Gaussian mixture on the rows of X (n,d); count an int or 'auto' (module doc)."""
    from sklearn.mixture import GaussianMixture

    n = len(X)
    fit = X if n <= GMM_ROWS else X[np.sort(rng.choice(n, GMM_ROWS, replace=False))]
    seed = int(rng.integers(0, 2**31 - 1))

    def model(c):
        kw = {"means_init": means_init, "n_init": 1} if means_init is not None else {"n_init": GMM_RESTARTS}
        return GaussianMixture(n_components=c, covariance_type="full", reg_covar=REG_COVAR, random_state=seed,
                               **kw).fit(fit)

    if count == "auto":
        fits = [model(c) for c in AUTO_CLUSTERS if c <= len(fit)]
        gm = min(fits, key=lambda g: g.bic(fit))
    else:
        gm = model(min(int(count), len(fit)))
    lab = gm.predict(X)
    _, lab = np.unique(lab, return_inverse=True)  # empty components dropped
    return lab.reshape(-1).astype(np.int64)


def _branch_pieces(members: np.ndarray, r: np.ndarray, A: sp.csr_matrix) -> list[np.ndarray]:
    """The graph-connected pieces of a set's outer half holding >= BRANCH_SHARE of it (module doc)."""
    rm = r[members]
    lo, hi = float(rm.min()), float(rm.max())
    outer = members[rm >= 0.5 * (lo + hi)]
    if len(outer) < 2:
        return [outer]
    nc, lab = connected_components(A[outer][:, outer], directed=False)
    if nc == 1:
        return [outer]
    sizes = np.bincount(lab, minlength=nc)
    return [outer[lab == c] for c in np.flatnonzero(sizes >= BRANCH_SHARE * len(outer))]


def _ring(A: sp.csr_matrix, v: int) -> np.ndarray:
    return A.indices[A.indptr[v]:A.indptr[v + 1]]


def _tree_path(pred: np.ndarray, v: int, root: int) -> np.ndarray:
    """Vertices from v to root along the predecessor tree (v first)."""
    path = [v]
    while path[-1] != root:
        path.append(int(pred[path[-1]]))
    return np.array(path, dtype=np.int64)


def _uphill(A: sp.csr_matrix, r: np.ndarray, v: int) -> int:
    """From v, steepest ascent of r over graph neighbours to a local maximum."""
    while True:
        nb = _ring(A, v)
        if len(nb) == 0:
            return v
        u = int(nb[np.argmax(r[nb])])
        if r[u] <= r[v]:
            return v
        v = u


_PRIORITY = {"centre": 3, "end": 2, "rendezvous": 1, "branch": 0}


def _merge_close(kind: dict, pred: np.ndarray, X: np.ndarray, v0: int) -> tuple[list, dict]:
    """Skeleton nodes (kind: vertex -> kind) joined to the next node towards v0 along the tree; two nodes
    closer than MERGE_RADIUS along it become one (the lower kind of centre > end > rendezvous > branch merged
    into the other, ends never into each other).  Returns (kept vertices, v0 first; parent of each kept vertex
    but v0).  ``kind`` loses the merged vertices."""
    parent, gap = {}, {}
    for v in kind:
        if v == v0:
            continue
        u, length = v, 0.0
        while True:
            p = int(pred[u])
            length += float(np.linalg.norm(X[u] - X[p]))
            u = p
            if u in kind:
                break
        parent[v], gap[v] = u, length
    merged = {}

    def root(v):
        while v in merged:
            v = merged[v]
        return v

    for v in sorted(parent, key=lambda v: (gap[v], v)):  # shortest segments first
        if gap[v] >= MERGE_RADIUS:
            break
        a, b = root(v), root(parent[v])
        if a == b or kind[a] == kind[b] == "end":
            continue
        if _PRIORITY[kind[a]] > _PRIORITY[kind[b]]:
            a, b = b, a
        merged[a] = b  # a (lower kind, or the child of two equal kinds) goes into b
    keep = sorted((v for v in kind if v not in merged), key=lambda v: (v != v0, v))
    out = {}
    for v in parent:
        a, b = root(v), root(parent[v])
        if a != b:
            out[a] = b
    for v in merged:
        del kind[v]
    return keep, out


def skeleton(embedding, graph, clusters=DEFAULT_CLUSTERS, rng=0) -> Skeleton:
    """The feature skeleton (5.2.2 steps 1-3, module doc) of an embedding (n,d) whose rows are the vertices of
    graph (n,n) (sparse; its pattern gives the edges, e.g. `mesh_graph` or `contour_graph`).

    clusters: the number of GMM clusters (int >= 1) or 'auto' (BIC over ``AUTO_CLUSTERS``).  Deterministic for
    a fixed ``rng``."""
    E = _checked_embedding(embedding, graph, clusters)
    n = len(E)
    rng = as_rng(rng)
    X = E - E.mean(axis=0)
    rms = float(np.sqrt((X**2).sum(axis=1).mean()))
    v0 = int(np.argmin((X**2).sum(axis=1)))
    if rms <= 0:  # every vertex at one point of the feature space
        return Skeleton(E[[v0]].copy(), np.zeros((0, 2), np.int64), 0, ("centre",), np.array([v0]),
                        np.zeros(n, np.int64))
    X = X / rms
    D, A = _feature_graph(X, graph)
    r = np.linalg.norm(X - X[v0], axis=1)
    sets = _branch_sets(X, r, A, clusters, rng)
    set_labels = np.empty(n, np.int64)
    for s, members in enumerate(sets):
        set_labels[members] = s
    feature, ends = _feature_points(sets, r, A, v0)
    pred, path_of, kind = _connection(D, v0, ends)
    # the other feature points: uphill to the end of their branch, marked where that branch's path passes nearest
    for f in feature:
        if f in kind:
            continue
        tip = _uphill(A, r, f)
        if tip in path_of:
            path = path_of[tip]
            kind.setdefault(int(path[np.argmin(np.linalg.norm(X[path] - X[f], axis=1))]), "branch")
    keep, parent = _merge_close(kind, pred, X, v0)
    index = {v: i for i, v in enumerate(keep)}
    edges = sorted((min(index[v], index[p]), max(index[v], index[p])) for v, p in parent.items())
    verts = np.array(keep, dtype=np.int64)
    return Skeleton(E[verts].copy(), np.array(edges, dtype=np.int64).reshape(-1, 2), 0,
                    tuple(kind[v] for v in keep), verts, set_labels)


def _checked_embedding(embedding, graph, clusters) -> np.ndarray:
    """The embedding as a finite float (n,d) array, n >= 2, after checking that graph is a sparse
    (n,n) matrix and clusters a whole number >= 1 or 'auto' (BolusError otherwise)."""
    E = np.asarray(embedding, dtype=np.float64)
    if E.ndim != 2 or E.shape[0] < 2 or E.shape[1] < 1 or not np.isfinite(E).all():
        raise BolusError(f"the feature space must be a finite (n, d) array with n >= 2, got shape {E.shape}")
    n = len(E)
    if not sp.issparse(graph) or graph.shape != (n, n):
        raise BolusError(f"the graph must be a sparse ({n}, {n}) matrix, one row per embedding row")
    if clusters != "auto":
        try:
            ok = int(clusters) == clusters and int(clusters) >= 1
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise BolusError(f"clusters must be a whole number >= 1 or 'auto', got {clusters!r}")
    return E


def _feature_graph(X: np.ndarray, graph) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """The graph's edges (symmetrised) with lengths measured in the normalised feature space X (n,d),
    its pieces joined by `link_components`: (D (n,n) edge lengths, A (n,n) its 0/1 pattern)."""
    n = len(X)
    G = sp.csr_matrix(graph)
    G = sp.csr_matrix((np.ones(G.nnz), G.indices.copy(), G.indptr.copy()), shape=(n, n))
    G = (G + G.T).tocoo()
    lengths = np.linalg.norm(X[G.row] - X[G.col], axis=1)
    D = link_components(X, _symmetric(G.row, G.col, np.maximum(lengths, 1e-12), n))
    A = sp.csr_matrix((np.ones(D.nnz), D.indices, D.indptr), shape=(n, n))
    return D, A


def _branch_sets(X: np.ndarray, r: np.ndarray, A: sp.csr_matrix, clusters, rng) -> list[np.ndarray]:
    """Steps 1-2 of 5.2.2: GMM clusters of the rows of X (n,d), each cluster holding several
    branches (`_branch_pieces` of its outer half, r (n,) the distance from v0) divided by a GMM
    started at the pieces' means.  Returns the sets' vertex indices."""
    with threadpool_limits(1):  # 3x3 covariances: threads only wait on each other
        labels = _gmm(X, clusters, rng)
    sets = []
    for c in range(int(labels.max()) + 1):
        members = np.flatnonzero(labels == c)
        pieces = _branch_pieces(members, r, A)
        if len(pieces) > 1:
            means = np.array([X[p].mean(axis=0) for p in pieces])
            with threadpool_limits(1):
                sub = _gmm(X[members], len(pieces), rng, means_init=means)
            sets.extend(members[sub == s] for s in range(int(sub.max()) + 1))
        else:
            sets.append(members)
    return sets


def _feature_points(sets, r: np.ndarray, A: sp.csr_matrix, v0: int) -> tuple[list, list]:
    """The farthest vertex from v0 of each set (v0 and repeats left out), and those of them that
    are ends: no graph neighbour farther from v0 and r >= END_MIN_RADIUS of the largest r.
    Returns (feature points, ends), vertex indices."""
    rmax = float(r.max())
    feature, ends = [], []
    for members in sets:
        f = int(members[np.argmax(r[members])])
        if f == v0 or f in feature:
            continue
        feature.append(f)
        if not (r[_ring(A, f)] > r[f]).any() and r[f] >= END_MIN_RADIUS * rmax:
            ends.append(f)
    return feature, ends


def _connection(D: sp.csr_matrix, v0: int, ends: list) -> tuple[np.ndarray, dict, dict]:
    """Step 3 of 5.2.2: one shortest-path tree from v0 over the edge lengths D (n,n), the path of
    each end to v0, and the kinds of the tree's nodes: v0 'centre', the ends 'end', vertices where
    two paths part 'rendezvous'.  Returns (predecessors (n,), {end: path (end first)}, {vertex: kind})."""
    n = D.shape[0]
    _, pred = dijkstra(D, directed=False, indices=v0, return_predecessors=True)
    path_of = {e: _tree_path(pred, e, v0) for e in ends}
    on_tree = np.zeros(n, bool)
    children = np.zeros(n, np.int64)
    on_tree[v0] = True
    for e in ends:
        for child, p in zip(path_of[e][:-1], path_of[e][1:]):
            if not on_tree[child]:
                on_tree[child] = True
                children[p] += 1
    kind = {v0: "centre"}
    kind.update((e, "end") for e in ends)
    for v in np.flatnonzero(children >= 2):
        kind.setdefault(int(v), "rendezvous")
    return pred, path_of, kind


def model_skeleton(V, F, clusters=DEFAULT_CLUSTERS, k: int = FEATURE_DIMENSIONS, rng=0) -> Skeleton:
    """`skeleton` of a triangle mesh's feature space (`model_embedding`)."""
    V = np.asarray(V, dtype=np.float64)
    D = mesh_graph(V, F)
    return skeleton(spectral_embedding(D, k, rng, V), D, clusters, rng)


def image_skeleton(points2d, clusters=DEFAULT_CLUSTERS, k: int = FEATURE_DIMENSIONS, neighbours: int | None = None,
                   rng=0) -> Skeleton:
    """`skeleton` of contour pixels' feature space (`image_embedding`), computed on `contour_samples`; its
    ``vertices`` and ``labels`` refer to the given points (labels: those of the nearest sample)."""
    P = _finite_points(points2d, 2, "contour points")
    idx = contour_samples(P)
    D = contour_graph(P[idx], neighbours)
    sk = skeleton(spectral_embedding(D, k, rng, P[idx]), D, clusters, rng)
    if len(idx) < len(P):
        sk.vertices = idx[sk.vertices]
        sk.labels = sk.labels[cKDTree(P[idx]).query(P)[1]]
    return sk


# ---------------------------------------------------------------------------------------------- comparison


