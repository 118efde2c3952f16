"""Area-balanced spectral print segmentation (seed 6.2, eqs. 6-21..6-36).

`print_segmentation` splits a mesh V (n,3) mm, F (m,3) into about ``parts`` print parts:

1. dual graph: one node per triangle, an edge between triangles that share a mesh edge;
2. weights (eq. 6-22)  W_ij = exp(-e'_ij^2 / (2 sigma^2)) + eta_q q'_ij + eta_u u'_ij, e_ij =
   |c_i - c_j|^2 (eq. 6-21, c the centroids), q' the surface quality and u' the support term
   (eqs. 6-23, 6-24: three levels each, from the normals and the concavity);
3. "abcut" (default): L = D - W, L' = F^-1/2 L F^-1/2 with F = diag(face areas)
   (eqs. 6-26..6-36), the k smallest eigenvectors U of L', U' = F^-1/2 U; "ratiocut"
   (the seed's "traditional method"): the k smallest eigenvectors of L itself;
4. Gaussian mixture on the rows of the embedding (`clustering.cluster_rows`), every row
   weighted by its face's area for "abcut", once for "ratiocut"; with ``face_groups`` the
   triangles of one polygon take the label covering most of its area (`spectral.vote_groups`);
5. each cluster split into its edge-connected parts, parts under ``min_part_fraction`` of the
   area merged into the neighbour with the longest shared border (``spectral.connected_patches``);
   parts numbered by decreasing area (separate pieces of the mesh may give more than asked).

Design notes: docs/design/printing.md.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import BolusError
from ..analysis.curvature import normal_curvature
from ..analysis.spectral import (
    as_rng,
    cluster_rows,
    connected_patches,
    gaussian_weights,
    graph_laplacian,
    smallest_eigenvectors,
    vote_groups,
)
from .segments import MIN_PART_FRACTION, PrintPart, PrintSegmentation, area_balance, part_stats
from ..mesh.topology import MeshTopology, check_mesh

__all__ = [
    "METHODS",
    "PrintPart",
    "PrintSegmentation",
    "dual_graph_weights",
    "abcut_laplacian",
    "print_segmentation",
    "print_segment",
    "part_stats",
    "area_balance",
]

METHODS = ("abcut", "ratiocut", "learned")  #: "learned": learned_segmentation.py (seed 6.4)
ALIKE_DEG, APART_DEG = 30.0, 60.0  #: q' = 1 under 30 deg between normals, 0.5 under 60, else 0 (seed's 3 levels)
CONCAVE_PER_MM = 0.02  #: u': a face is concave with a radius of curvature under 50 mm (eq. 6-19's eps)
AREA_FLOOR = 1e-3  #: F^-1/2 of a (nearly) zero-area face uses 1e-3 x the median area: finite, tiny weight


def _three_level(ok_i: np.ndarray, ok_j: np.ndarray) -> np.ndarray:
    return 0.5 * (ok_i.astype(np.float64) + ok_j.astype(np.float64))


def dual_graph_weights(
    topo: MeshTopology, eta_quality: float = 1.0, eta_support: float = 1.0, concave_per_mm: float = CONCAVE_PER_MM
) -> sp.csr_matrix:
    """Weighted adjacency W (m,m) sparse of the triangle dual graph of ``topo`` (m triangles),
    eqs. 6-21..6-25 (module doc)."""
    for name, val in (("eta_quality", eta_quality), ("eta_support", eta_support)):
        if not (val >= 0 and np.isfinite(val)):
            raise BolusError(f"{name} must be a non-negative number, got {val}")
    P = topo.face_adjacency_pairs
    i, j = P[:, 0], P[:, 1]
    C = topo.centroids
    e = np.einsum("ij,ij->i", C[i] - C[j], C[i] - C[j])  # eq. 6-21
    ref = np.percentile(e, 99.0) if e.size else 0.0
    e1 = np.clip(e / ref, 0.0, 1.0) if ref > 0 else np.zeros_like(e)  # eq. 6-25 (scale, see doc)
    w = gaussian_weights(e1)  # eq. 6-22's first term, clipped at 3 sigma like eq. 3-4's
    N = topo.face_normals
    cosang = np.einsum("ij,ij->i", N[i], N[j])
    alike, apart = np.cos(np.radians(ALIKE_DEG)), np.cos(np.radians(APART_DEG))
    q = np.where(cosang > alike, 1.0, np.where(cosang > apart, 0.5, 0.0))
    w = w + eta_quality * q  # eq. 6-23 (module doc)
    if eta_support > 0:
        convex = ~normal_curvature(topo.V, topo.F, topo).concave(concave_per_mm)
        w = w + eta_support * _three_level(convex[i], convex[j])  # eq. 6-24 (module doc)
    m = topo.m
    W = sp.coo_matrix((np.r_[w, w], (np.r_[i, j], np.r_[j, i])), shape=(m, m))
    return W.tocsr()


def abcut_laplacian(L: sp.spmatrix, areas: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """L' = F^-1/2 L F^-1/2 (eq. 6-36) with F = diag(areas) (eq. 6-30).

    L (m,m) sparse Laplacian, areas (m,) -> (L' (m,m) sparse symmetric, F^-1/2 diagonal (m,))."""
    a = np.asarray(areas, dtype=np.float64)
    a = np.maximum(a, AREA_FLOOR * float(np.median(a)))
    s = 1.0 / np.sqrt(a)
    S = sp.diags(s)
    Lp = (S @ sp.csr_matrix(L) @ S).tocsr()
    return (0.5 * (Lp + Lp.T)).tocsr(), s


def print_segmentation(
    V,
    F,
    parts: int = 3,
    method: str = "abcut",
    rng=0,
    topo: MeshTopology | None = None,
    eta_quality: float = 1.0,
    eta_support: float = 1.0,
    concave_per_mm: float = CONCAVE_PER_MM,
    min_part_fraction: float = MIN_PART_FRACTION,
    clustering: str = "gmm",
    face_groups=None,
    progress=None,
) -> PrintSegmentation:
    """Split the mesh V (n,3) mm, F (m,3) into about ``parts`` edge-connected print parts.

    method "abcut" (area-balanced, eqs. 6-26..6-36) or "ratiocut" (unnormalised L); "learned"
    hands over to `learned_segmentation.learned_segmentation` (seed 6.4: the number of parts comes
    from the data, ``parts`` is not used; returns a `LearnedSegmentation`).
    Parts below ``min_part_fraction`` of the area are merged into a neighbour, so the
    result can have fewer parts than asked (or more, when a cluster falls apart into
    large pieces).  ``face_groups`` (m,) int, optional: the polygon of each triangle;
    a polygon's triangles end up in one part.  See the module doc for the weights.
    Returns a `PrintSegmentation` (labels (m,) 0..p-1 by decreasing area).
    """
    report = progress or (lambda f, t: None)
    k = _check_request(parts, method, min_part_fraction)
    if method == "learned":  # the number of parts comes from the data: ``parts`` is not used
        from .learned import learned_segmentation  # noqa: PLC0415 (loaded only when asked for)

        return learned_segmentation(V, F, rng=rng, topo=topo, min_part_fraction=min_part_fraction,
                                    face_groups=face_groups, progress=progress)
    topo = MeshTopology(*check_mesh(V, F, nondegenerate=False, min_faces=0)) if topo is None else topo
    if topo.m == 0:
        raise BolusError("the mesh has no faces; select the faces to split")
    if face_groups is not None and np.shape(face_groups) != (topo.m,):
        raise BolusError(f"face groups must be one per triangle ({topo.m}), got shape {np.shape(face_groups)}")
    faces = topo.m if face_groups is None else len(np.unique(face_groups))
    if faces < k:
        raise BolusError(f"the mesh has {faces} {'faces' if face_groups is not None else 'triangles'}, "
                         f"fewer than the {k} parts asked: ask for at most {faces} or select a larger region")
    total = float(topo.areas.sum())
    if not total > 0:
        raise BolusError("the mesh has zero area (all its faces are degenerate); check the mesh")
    rng = as_rng(rng)
    m = topo.m
    if k == 1:
        clusters = np.zeros(m, dtype=np.int64)
        vals, U = np.zeros(1), np.full((m, 1), 1.0 / np.sqrt(m))
    else:
        report(0.1, "dual graph and eigenvectors")
        W = dual_graph_weights(topo, eta_quality, eta_support, concave_per_mm)
        vals, U = _embedding(graph_laplacian(W), topo.areas, k, method, rng)
        report(0.7, "clustering")
        # ABcut balances area: every row counts with its face's area; RatioCut counts rows
        weights = topo.areas if method == "abcut" else None
        clusters = cluster_rows(U, k, method=clustering, rng=rng, weights=weights)
    if face_groups is not None:
        clusters = vote_groups(clusters, face_groups, topo.areas)
    report(0.9, "parts")
    labels = connected_patches(topo, clusters, min_area=min_part_fraction * total)
    report(1.0, "done")
    return PrintSegmentation(labels, clusters, vals, U, method, k, min_part_fraction)


def _check_request(parts, method: str, min_part_fraction: float) -> int:
    """The number of parts asked, after checking it, the method and the crumb fraction."""
    if method not in METHODS:
        raise BolusError(f"unknown print segmentation method {method!r}; use 'abcut', 'ratiocut' or 'learned'")
    try:
        k = int(parts)
    except (TypeError, ValueError):
        raise BolusError(f"the number of parts must be a whole number, got {parts!r}") from None
    if k != parts or k < 1:
        raise BolusError(f"ask for at least 1 part (a whole number), got {parts}")
    if not 0.0 <= min_part_fraction < 1.0:
        raise BolusError(f"min_part_fraction must lie in [0, 1), got {min_part_fraction}")
    return k


def _embedding(L, areas: np.ndarray, k: int, method: str, rng) -> tuple[np.ndarray, np.ndarray]:
    """(eigenvalues (k,), embedding (m,k)): U' = F^-1/2 U of L' (ABcut, eq. 6-36) or U of L (RatioCut)."""
    if method == "abcut":
        Lp, s = abcut_laplacian(L, areas)
        vals, U = smallest_eigenvectors(Lp, k, rng)
        return vals, U * s[:, None]
    return smallest_eigenvectors(L, k, rng)


def print_segment(V, F, parts: int = 3, method: str = "abcut", rng=0, topo: MeshTopology | None = None,
                  **kwargs) -> np.ndarray:
    """Part labels (m,) int 0..p-1 of `print_segmentation` (kwargs go there)."""
    return print_segmentation(V, F, parts, method=method, rng=rng, topo=topo, **kwargs).labels
