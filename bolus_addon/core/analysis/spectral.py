"""Saliency-aware spectral segmentation (seed 3.2 and 4.1.1, eqs. 3-3..3-8, 4-5).

`segment` (V (n,3) mm, F (m,3), k patches) returns a `Segmentation` (face labels (m,)), in six steps:

1. vertex graph on the mesh edges, W_ij = exp(-d_ij^2 / (2 sigma^2)), sigma = mean d_ij (eq. 3-4),
   d_ij = eta |s'_i - s'_j| + e'_ij (eq. 4-5): s' the segmentation saliency (eq. 4-4) and e' the
   edge length, both mapped to [0, 1] (`unit_interval`); eta only where both ends have
   s' >= `HIGH_SALIENCY`; d clipped at `D_CLIP` sigma (`affinity`, `gaussian_weights`);
2. L = D - W (eqs. 3-3, 3-5, `graph_laplacian`);
3. the k eigenvectors of the smallest eigenvalues (eq. 3-8, the RatioCut relaxation of eq. 3-6),
   by shift-invert Lanczos seeded from ``rng`` (`smallest_eigenvectors`), or coarse to fine above
   `MULTILEVEL_MIN_VERTICES` vertices (`spectral_multilevel`);
4. k-means (default) or a Gaussian mixture on the rows of U (n,k) (`clustering.cluster_rows`);
5. vertex clusters -> face labels by majority vote of the corners (`faces_from_vertex_labels`),
   the triangles of one polygon kept together (`vote_groups`);
6. every label split into its edge-connected components, those below ``min_patch_fraction`` of
   the area merged into the neighbour with the longest shared border, numbered by area (`connected_patches`).

Design notes: docs/design/analysis.md.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import eigh
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import LinearOperator, eigsh, lobpcg, splu

from .clustering import cluster_rows  # re-exported: the one clustering step (clustering.py)
from ..errors import BolusError
from ..rng import as_rng
from .saliency import SaliencyResult, analyse, corner_angle_sums, flattenability, flattenability_value
from ..mesh.topology import MeshTopology, submesh  # submesh: re-exported (it lived here)
from .spectral_multilevel import (  # noqa: F401 (re-exported)
    AGGREGATE_SIZE,
    STRONG_WEIGHT,
    LOBPCG_TOL,
    LOBPCG_MAXITER,
    aggregate_vertices,
    multilevel_eigenvectors,
)
from .patch_table import PatchStats, patch_stats, patch_stats_on  # noqa: F401 (re-exported)

__all__ = [
    "HIGH_SALIENCY",
    "PatchStats",
    "Segmentation",
    "unit_interval",
    "affinity",
    "gaussian_weights",
    "graph_laplacian",
    "smallest_eigenvectors",
    "multilevel_eigenvectors",
    "cluster_rows",
    "faces_from_vertex_labels",
    "vote_groups",
    "connected_patches",
    "patch_stats",
    "segment",
    "submesh",
]

HIGH_SALIENCY = 0.25
#: Above this many vertices `segment` takes the eigenvectors coarse to fine
#: (`multilevel_eigenvectors`).  Measured on nefertiti x16 (560k vertices, 1.12M
#: triangles, eta 5, 3 mm): shift-invert Lanczos needed one SuperLU factorisation of
#: 31.6 s (50 s CPU under load; the symmetric MMD_AT_PLUS_A ordering was no better:
#: over 4 min CPU at 1M) and 21 solves of ~1 s; coarse to fine takes ~17 s CPU with
#: the same vertex clusters on 99.99 % of the vertices.  On nefertiti itself (35k
#: vertices, 3 patches) coarse to fine takes the eigenvectors in 0.4 s instead of 0.8 s,
#: the same patches on 99.99 % of the triangles.  Below it (a nose region, the small
#: test meshes) the exact shift-invert path is as fast and is kept.
MULTILEVEL_MIN_VERTICES = 20_000
#: ... and only for at most this many eigenvectors up to EXACT_MAX_VERTICES: LOBPCG's block
#: work grows with k^2, and at k = 13 the exact path was faster at every size measured
#: (eta 5, 3 mm, best of 2 at load 4-5: 21.7k vertices 1.5 s against 3.5 s, 35k 2.8 s against
#: 6.2 s, 140k 10.2 s against 16.9 s; at k = 3 coarse to fine stays faster, 0.67 / 1.19 s at 35k)
MULTILEVEL_MAX_K = 8
EXACT_MAX_VERTICES = 200_000
D_CLIP = 3.0  #: distances clipped at 3 sigma: every edge weight >= exp(-4.5) ~ 0.011 (see `gaussian_weights`)


def unit_interval(x: np.ndarray, lo_pct: float = 1.0, hi_pct: float = 99.0) -> np.ndarray:
    """Map x to [0,1]: (x - P_lo) / (P_hi - P_lo), clipped.  All zeros if x is constant."""
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return x.copy()
    lo, hi = np.percentile(x, [lo_pct, hi_pct])
    if not hi > lo:
        lo, hi = float(x.min()), float(x.max())
        if not hi > lo:
            return np.zeros_like(x)
    return np.clip((x - lo) / (hi - lo), 0.0, 1.0)


def affinity(
    topo: MeshTopology, saliency: np.ndarray, eta: float = 5.0, high: float = HIGH_SALIENCY
) -> sp.csr_matrix:
    """Adjacency W (n,n) of eqs. 3-4 and 4-5 on the mesh edges (see module doc)."""
    if eta < 0 or not np.isfinite(eta):
        raise BolusError(f"eta must be a non-negative number, got {eta}")
    E = topo.edges
    e_prime = unit_interval(topo.edge_lengths)
    s = np.asarray(saliency, dtype=np.float64)
    pos = s[s > 0]
    if pos.size:
        # s' = s / P99(s), with P99 over the whole region (zeros included) unless that is 0
        ref = np.percentile(s, 99.0)
        if ref <= 0:
            ref = pos.max()
        s_prime = np.clip(s / ref, 0.0, 1.0)
    else:
        s_prime = np.zeros_like(s)
    both_high = (s_prime[E[:, 0]] >= high) & (s_prime[E[:, 1]] >= high)
    d = np.where(both_high, eta, 0.0) * np.abs(s_prime[E[:, 0]] - s_prime[E[:, 1]]) + e_prime
    w = gaussian_weights(d)
    n = topo.n
    W = sp.coo_matrix((np.r_[w, w], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(n, n))
    return W.tocsr()


def gaussian_weights(d: np.ndarray) -> np.ndarray:
    """Eq. 3-4 (and the first term of eq. 6-22): w = exp(-d^2 / (2 sigma^2)), sigma = mean d, for
    graph-edge distances d (e,) >= 0 -> (e,).  All weights are 1 when every d is 0.

    Our addition: d is clipped at D_CLIP * sigma, i.e. W_ij >= exp(-4.5) ~ 0.011.  The
    saliency term still makes a salient edge ~100x cheaper to cut, but it can no longer
    cut the graph apart numerically (W ~ 1e-40), which made the eigen-solver return
    indicator vectors of a few noisy vertices instead of patches.
    """
    sigma = float(d.mean()) if d.size else 1.0
    if sigma <= 0:
        sigma = 1.0
    d = np.minimum(d, D_CLIP * sigma)
    return np.exp(-(d**2) / (2.0 * sigma**2))


def graph_laplacian(W: sp.spmatrix) -> sp.csr_matrix:
    """L = D - W with D_ii = sum_j W_ij (eqs. 3-3, 3-5)."""
    W = sp.csr_matrix(W)
    deg = np.asarray(W.sum(axis=1)).ravel()
    return (sp.diags(deg) - W).tocsr()


def smallest_eigenvectors(L: sp.spmatrix, k: int, rng=None, coords: np.ndarray | None = None
                          ) -> tuple[np.ndarray, np.ndarray]:
    """The k smallest eigenpairs of the symmetric PSD matrix L (eq. 3-8).

    Returns (values (k,), vectors (n,k)), values ascending, each vector of unit norm
    with its sign fixed (largest-magnitude entry positive) for reproducibility.
    coords (n,3), optional: vertex positions; with them a graph Laplacian of more than
    ``MULTILEVEL_MIN_VERTICES`` vertices is solved coarse to fine
    (`multilevel_eigenvectors`, L must then be a connected graph Laplacian), for k up to
    ``MULTILEVEL_MAX_K`` (any k below 20 above ``EXACT_MAX_VERTICES`` vertices).
    """
    n = L.shape[0]
    if k < 1 or k > n:
        raise BolusError(f"cannot take {k} eigenvectors of a graph with {n} vertices")
    rng = as_rng(rng)
    if n <= max(300, 4 * k):
        vals, vecs = eigh(L.toarray())
        vals, vecs = vals[:k], vecs[:, :k]
    elif coords is not None and n > MULTILEVEL_MIN_VERTICES and k < 20 and (
            k <= MULTILEVEL_MAX_K or n > EXACT_MAX_VERTICES):
        vals, vecs = multilevel_eigenvectors(L, k, coords, rng)
    else:
        scale = float(np.abs(L.diagonal()).mean()) or 1.0
        v0 = rng.standard_normal(n)
        # shift just below 0 (L is singular): L - sigma I is positive definite and the
        # wanted eigenvalues are the ones nearest the shift
        vals, vecs = eigsh(L.tocsc(), k=k, sigma=-1e-6 * scale, which="LM", v0=v0, tol=1e-10)
        order = np.argsort(vals)
        vals, vecs = vals[order], vecs[:, order]
    idx = np.argmax(np.abs(vecs), axis=0)
    signs = np.sign(vecs[idx, np.arange(vecs.shape[1])])
    signs[signs == 0] = 1.0
    return vals, vecs * signs


def vote_groups(labels: np.ndarray, face_groups: np.ndarray, areas: np.ndarray | None = None) -> np.ndarray:
    """One label per group: triangles with the same group id (the triangles of one
    polygon), labels (m,) int >= 0, face_groups (m,) int, areas (m,) optional (default 1)
    -> (m,) int64, each triangle given the label covering most of its group's area
    (ties: the smaller label)."""
    lab = np.asarray(labels, dtype=np.int64)
    face_groups = np.asarray(face_groups)
    if lab.shape != face_groups.shape or lab.ndim != 1:
        raise BolusError(f"labels {lab.shape} and face groups {face_groups.shape} must be one per triangle")
    if lab.size == 0:
        return lab.copy()
    if lab.min() < 0:
        raise BolusError("labels to vote must be >= 0")
    areas = np.ones(len(lab)) if areas is None else np.asarray(areas, dtype=np.float64)
    # area of each (group, label) pair; the label with the largest area wins
    nl = int(lab.max()) + 1
    ukey, inv = np.unique(face_groups.astype(np.int64) * nl + lab, return_inverse=True)
    uniq = np.stack([ukey // nl, ukey % nl], axis=1)
    inv = inv.reshape(-1)
    tot = np.bincount(inv, weights=areas)
    order = np.lexsort((-tot, uniq[:, 0]))  # by group, largest area first
    first = np.ones(len(order), dtype=bool)
    first[1:] = uniq[order[1:], 0] != uniq[order[:-1], 0]
    groups, g_inv = np.unique(face_groups, return_inverse=True)
    winner = np.empty(len(groups), dtype=np.int64)
    winner[np.searchsorted(groups, uniq[order[first], 0])] = uniq[order[first], 1]
    lab = winner[g_inv.reshape(-1)]
    return lab.astype(np.int64)


def faces_from_vertex_labels(
    F: np.ndarray, vlabels: np.ndarray, areas: np.ndarray | None = None, face_groups: np.ndarray | None = None
) -> np.ndarray:
    """Face labels (m,) from vertex labels (n,) by majority of the three corners.

    Three different corner labels: the smallest label wins (deterministic).
    face_groups (m,) optional: triangles with the same group id (the triangles of one
    polygon) get one label, the one covering most of the group's area.
    """
    L = vlabels[F]
    a, b, c = L[:, 0], L[:, 1], L[:, 2]
    lab = np.where((a == b) | (a == c), a, np.where(b == c, b, np.minimum(np.minimum(a, b), c)))
    if face_groups is not None:
        lab = vote_groups(lab, face_groups, areas)
    return lab.astype(np.int64)


def connected_patches(topo: MeshTopology, labels: np.ndarray, min_area: float = 0.0) -> np.ndarray:
    """Split labels into edge-connected patches and merge crumbs (step 6 of the module doc).

    labels (m,) int -> patch labels (m,) in 0..p-1, numbered by decreasing area.
    A component of area < ``min_area`` is merged into the adjacent component with which
    it shares the longest border (smallest crumbs first).
    """
    ncomp, comp = topo.face_components(labels)
    area = np.bincount(comp, weights=topo.areas, minlength=ncomp)
    # border pairs between different components, with the length of the shared edge
    P = topo.face_adjacency_pairs
    elen = topo.edge_lengths[topo.face_adjacency_edges]
    ca, cb = comp[P[:, 0]], comp[P[:, 1]]
    keep = ca != cb
    ca, cb, elen = ca[keep], cb[keep], elen[keep]
    alive = np.ones(ncomp, dtype=bool)
    stuck = np.zeros(ncomp, dtype=bool)  # crumbs with no neighbour (a separate part)
    while alive.sum() > 1:
        cand = np.nonzero(alive & ~stuck & (area < min_area))[0]
        if cand.size == 0:
            break
        c = cand[np.argmin(area[cand])]
        touch = (ca == c) | (cb == c)
        if not touch.any():
            stuck[c] = True
            continue
        other = np.where(ca[touch] == c, cb[touch], ca[touch])
        shared = np.bincount(other, weights=elen[touch], minlength=ncomp)
        target = int(np.argmax(shared))
        comp[comp == c] = target
        area[target] += area[c]
        area[c] = 0.0
        alive[c] = False
        ca[ca == c] = target
        cb[cb == c] = target
        keep = ca != cb
        ca, cb, elen = ca[keep], cb[keep], elen[keep]
    # renumber by decreasing area (ties by first face index)
    uniq, first_face = np.unique(comp, return_index=True)
    parea = np.bincount(comp, weights=topo.areas, minlength=ncomp)[uniq]
    order = np.lexsort((first_face, -parea))
    new = np.empty(comp.max() + 1, dtype=np.int64)
    new[uniq[order]] = np.arange(len(uniq))
    return new[comp]


@dataclass
class Segmentation:
    """Result of `segment` on a region with n vertices and m triangles."""

    face_labels: np.ndarray  #: (m,) patch of each triangle, 0..p-1
    vertex_clusters: np.ndarray  #: (n,) raw spectral cluster of each vertex
    eigenvalues: np.ndarray  #: (k,)
    embedding: np.ndarray  #: (n,k) spectral embedding U
    analysis: SaliencyResult
    patches: list[PatchStats] = field(default_factory=list)
    requested: int = 0

    @property
    def patch_count(self) -> int:
        return int(self.face_labels.max()) + 1 if self.face_labels.size else 0


def _given_analysis(analysis, topo: MeshTopology, smoothing_mm: float) -> SaliencyResult:
    """The preview handed to `segment` as a `SaliencyResult` (theta and V_analysis None
    when only the (varpi, saliency) pair was given); BolusError on wrong shapes or values."""
    if isinstance(analysis, SaliencyResult):
        varpi, sal = analysis.varpi, analysis.saliency
    else:
        try:
            varpi, sal = analysis
        except (TypeError, ValueError):
            raise BolusError("the precomputed analysis must be a SaliencyResult or a (varpi, saliency) pair") from None
    varpi = np.asarray(varpi, dtype=np.float64).reshape(-1)
    sal = np.asarray(sal, dtype=np.float64).reshape(-1)
    if varpi.shape != (topo.n,) or sal.shape != (topo.n,):
        raise BolusError(f"the precomputed flattenability and saliency must have one value per vertex ({topo.n}), "
                         f"got {varpi.shape} and {sal.shape}")
    if not (np.isfinite(varpi).all() and np.isfinite(sal).all()) or varpi.min(initial=0) < 0 or sal.min(initial=0) < 0:
        raise BolusError("the precomputed flattenability and saliency must be finite and >= 0")
    if isinstance(analysis, SaliencyResult):
        return analysis
    total = float(varpi.sum())
    return SaliencyResult(None, varpi, sal, total, flattenability_value(total), float(smoothing_mm), None)


def _check_segment_request(topo: MeshTopology, patches, face_groups) -> int:
    """The number of patches asked, after checking that the region can hold them: enough
    faces and vertices, no loose vertices, one connected piece."""
    k = int(patches)
    if k < 1:
        raise BolusError(f"ask for at least 1 patch, got {patches}")
    nfaces = len(np.unique(face_groups)) if face_groups is not None else topo.m
    if nfaces < k:
        raise BolusError(f"the region has {nfaces} faces, fewer than the {k} patches asked: ask for at most "
                         f"{nfaces} or select a larger region")
    if topo.n < k:
        raise BolusError(f"the region has {topo.n} vertices, too few for the {k} patches asked")
    if not topo.used_vertices.all():
        raise BolusError("the mesh has vertices that belong to no face (loose vertices)")
    ncomp, comp = topo.face_components()
    if ncomp > 1:
        if face_groups is None:
            sizes, unit = np.bincount(comp), "triangles"
        else:  # polygons, as the user sees them
            sizes, unit = np.bincount(np.unique(np.c_[comp, face_groups], axis=0)[:, 0]), "faces"
        raise BolusError(f"the region is made of {ncomp} separate parts ({', '.join(map(str, sorted(sizes)[::-1][:5]))}"
                         f"{', ...' if ncomp > 5 else ''} {unit}); segment one connected part at a time (select its "
                         "faces in Edit Mode: L over it), or, where the parts should be one surface, join them at "
                         "their duplicated vertices first (Mesh > Clean Up > Merge by Distance)")
    return k


def segment(
    V,
    F,
    patches: int = 3,
    eta: float = 5.0,
    smoothing_mm: float = 0.0,
    rng=0,
    method: str = "kmeans",
    min_patch_fraction: float = 0.02,
    face_groups: np.ndarray | None = None,
    high: float = HIGH_SALIENCY,
    progress=None,
    topo: MeshTopology | None = None,
    analysis: SaliencyResult | tuple | None = None,
) -> Segmentation:
    """Segment a connected triangle mesh into edge-connected patches (module doc).

    V (n,3) mm, F (m,3); patches = k, the number of clusters asked (the result may
    have more patches when a cluster falls apart, or fewer after crumbs are merged);
    eta: weight of the saliency term of eq. 4-5 (0 gives plain spectral clustering);
    smoothing_mm: analysis smoothing for the saliency (see saliency.py);
    face_groups (m,): polygon of each triangle, kept in one patch;
    topo: a `MeshTopology` of (V, F) already built by the caller (saves rebuilding it).
    analysis: the flattenability preview of this same (V, F) at this ``smoothing_mm``,
    reused instead of recomputed (17 s of 69 s at 1.12M triangles): the
    `saliency.analyse` result, or the pair (varpi (n,), saliency (n,)) as the preview
    stored them; the caller vouches that they belong to this mesh and smoothing
    (shapes and finiteness are checked here).  Ignored on a mesh with non-manifold
    vertices (their patch table needs the smoothed copy).
    Degenerate input: NaN/inf and zero-area triangles (coincident or collinear vertices,
    no angles for eq. 4-1) are refused by name (`MeshTopology.require_nondegenerate`); needle triangles
    and non-manifold edges are segmented as given (the Blender operator refuses the latter).
    Returns a `Segmentation` (face_labels (m,) 0..p-1).
    """
    report = progress or (lambda f, t: None)
    # zero-area triangles have no angles (eq. 4-1): refused by name before anything else
    topo = MeshTopology(V, F) if topo is None else topo  # NaN/inf and bad indices refused here
    topo.require_nondegenerate("the region")
    k = _check_segment_request(topo, patches, face_groups)
    report(0.05, "flattenability")
    manifold = not topo.nonmanifold_vertices.any()
    ana = _given_analysis(analysis, topo, smoothing_mm) if analysis is not None and manifold else None
    if ana is None:
        ana = analyse(topo.V, topo.F, smoothing_mm, topo=topo)
    rng = as_rng(rng)
    if k == 1:
        vclusters = np.zeros(topo.n, dtype=np.int64)
        vals, U = np.zeros(1), np.full((topo.n, 1), 1.0 / np.sqrt(topo.n))
    else:
        report(0.15, "Laplacian")
        L = graph_laplacian(affinity(topo, ana.saliency, eta=eta, high=high))
        report(0.25, "eigenvectors")
        vals, U = smallest_eigenvectors(L, k, rng, coords=topo.V)
        report(0.7, "clustering")
        vclusters = cluster_rows(U, k, method=method, rng=rng)
    report(0.85, "patches")
    flab = faces_from_vertex_labels(topo.F, vclusters, topo.areas, face_groups)
    labels = connected_patches(topo, flab, min_area=min_patch_fraction * float(topo.areas.sum()))
    report(0.9, "patch table")
    if manifold:
        stats = patch_stats_on(topo, labels, ana.varpi)
    else:
        stats = patch_stats(ana.V_analysis, topo.F, labels, topo.V)
    report(1.0, "done")
    return Segmentation(labels, vclusters, vals, U, ana, stats, k)
