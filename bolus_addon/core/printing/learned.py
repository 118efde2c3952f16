"""Print segmentation from learned features (seed 6.4, Algorithm 6-2; eqs. 3-9..3-14).

`learned_segmentation` splits a mesh V (n,3) mm, F (m,3) into print parts (labels (m,)):

1. printing features (Q', U', K') per triangle at the whole mesh's best build direction
   (`subgraphs.print_features`, eqs. 6-6, 6-13, 6-20) and the sub-graphs of 30 triangles
   (`subgraphs.build_subgraphs`, 6.4.1), one 90-vector each;
2. hidden features pf (N, 20) of every sub-graph from the stacked auto-encoder
   (`autoencoder`, trained weights in ``assets/print_sae.npz``, Algorithm 6-1);
3. the similarity of eq. 3-14 between sub-graphs (`similarity`): a Gaussian kernel on the
   central triangles' distance plus one on the hidden features' distance;
4. affinity propagation (eqs. 3-9..3-13, Algorithm 6-2: damping 0.9, at most 10,000
   iterations, 15 stable ones; scikit-learn's ``AffinityPropagation``), the preference the
   smallest similarity; above ``max_exemplar_set`` sub-graphs on that many spread evenly;
5. every triangle takes its sub-graph's cluster, unused ones that of the nearest sub-graph;
   each cluster is split into its edge-connected parts and parts under ``min_part_fraction``
   of the area are merged into a neighbour (``spectral.connected_patches``).

Design notes: docs/design/printing.md.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import BolusError
from .orientation import orient
from .segments import MIN_PART_FRACTION, PrintSegmentation
from ..rng import as_rng
from ..analysis.spectral import connected_patches, vote_groups
from .subgraphs import SIZE, SubGraphs, build_subgraphs, print_features, subgraph_rows
from ..mesh.topology import MeshTopology, check_mesh

__all__ = [
    "DAMPING",
    "MAX_ITER",
    "CONVERGENCE_ITER",
    "SIMILARITIES",
    "default_sae_path",
    "load_default_sae",
    "similarity",
    "affinity_propagation",
    "LearnedSegmentation",
    "learned_segmentation",
]

DAMPING = 0.9  #: Algorithm 6-2's attenuation coefficient
MAX_ITER = 10_000  #: Algorithm 6-2's T
CONVERGENCE_ITER = 15  #: Algorithm 6-2's IT: exemplars unchanged for this many iterations
MAX_EXEMPLAR_SET = 1_500  #: sub-graphs affinity propagation runs on at most (module doc, "scale")
SIMILARITIES = ("learned", "geometric")
MANY_PARTS = 6  #: more learned parts than this are warned about (`LearnedSegmentation.count_note`)
SAE_FILE = "print_sae.npz"

_sae_cache: dict = {}


def default_sae_path() -> Path:
    """``assets/print_sae.npz`` beside the add-on package (in the repository and in the extension)."""
    return Path(__file__).resolve().parents[3] / "assets" / SAE_FILE


def load_default_sae():
    """The shipped stacked auto-encoder (loaded once per file version)."""
    from .autoencoder import StackedAutoEncoder  # noqa: PLC0415

    p = default_sae_path()
    if not p.exists():
        raise BolusError(f"the trained auto-encoder {p} is missing: reinstall the add-on, or train it with "
                         "scripts/train_print_sae.py")
    key = (str(p), p.stat().st_mtime_ns)
    if key not in _sae_cache:
        _sae_cache.clear()
        _sae_cache[key] = StackedAutoEncoder.load(p)
    return _sae_cache[key]


def _sq_dists(X: np.ndarray) -> np.ndarray:
    """(N, N) squared Euclidean distances between the rows of X (N, d), >= 0."""
    s = np.einsum("ij,ij->i", X, X)
    D = s[:, None] + s[None, :] - 2.0 * (X @ X.T)
    np.maximum(D, 0.0, out=D)
    np.fill_diagonal(D, 0.0)
    return D


def _kernel(D: np.ndarray, mean: float | None = None) -> tuple[np.ndarray, float]:
    """exp(-D / (2 mean)) of squared distances D and the width ``mean`` used: by default the mean of the
    square matrix D off its diagonal (module doc); all ones when that is 0."""
    if mean is None:
        n = len(D)
        mean = D.sum() / max(n * (n - 1), 1)
    return (np.exp(-D / (2.0 * mean)) if mean > 0 else np.ones_like(D)), mean


def _similarity(g, pf=None) -> tuple[np.ndarray, tuple]:
    """`similarity` and its kernel widths (the mean squared distances of g and of pf)."""
    S, wg = _kernel(_sq_dists(np.asarray(g, dtype=np.float64)))
    wf = None
    if pf is not None:
        Sf, wf = _kernel(_sq_dists(np.asarray(pf, dtype=np.float64)))
        S += Sf
    return S, (wg, wf)


def similarity(g, pf=None) -> np.ndarray:
    """Eq. 3-14 (as read in the module doc): (N, N) similarity of N sub-graphs from their
    central triangles' centroids g (N, 3) and hidden features pf (N, d) (None: geometric only)."""
    return _similarity(g, pf)[0]


def affinity_propagation(S, rng=0, damping: float = DAMPING, max_iter: int = MAX_ITER,
                         convergence_iter: int = CONVERGENCE_ITER, preference="min"
                         ) -> tuple[np.ndarray, np.ndarray, int]:
    """Eqs. 3-9..3-13 (Algorithm 6-2) on a similarity S (N, N) with scikit-learn; the preference
    "min" (default, module doc) or "median" of S off the diagonal, or a number -> (labels (N,) 0..c-1, exemplars (c,),
    iterations)."""
    from sklearn.cluster import AffinityPropagation  # noqa: PLC0415
    from sklearn.exceptions import ConvergenceWarning  # noqa: PLC0415

    S = np.asarray(S, dtype=np.float64)
    N = len(S)
    if N == 1:
        return np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), 0
    off = S[~np.eye(N, dtype=bool)]
    if np.ptp(off) <= 1e-12 * max(1.0, float(np.abs(off).max())):  # e.g. two sub-graphs: nothing to tell apart
        return np.zeros(N, dtype=np.int64), np.zeros(1, dtype=np.int64), 0
    pref = {"median": np.median, "min": np.min}[preference](off) if isinstance(preference, str) else preference
    seed = int(as_rng(rng).integers(2**31 - 1))
    ap = AffinityPropagation(affinity="precomputed", damping=damping, max_iter=int(max_iter),
                             convergence_iter=int(convergence_iter), preference=float(pref),
                             random_state=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        ap.fit(S)
    ex = np.asarray(ap.cluster_centers_indices_, dtype=np.int64)
    if ex.size == 0 or ap.n_iter_ >= max_iter:
        raise BolusError(f"affinity propagation did not converge in {ap.n_iter_:,} iterations on {N:,} sub-graphs; "
                         "split with the ABcut method instead")
    return np.asarray(ap.labels_, dtype=np.int64), ex, int(ap.n_iter_)


def _spread(g: np.ndarray, k: int, rng) -> np.ndarray:
    """k indices of the rows of g (N, 3) in farthest-point order from a random start."""
    N = len(g)
    pick = np.empty(k, dtype=np.int64)
    pick[0] = int(as_rng(rng).integers(N))
    d = ((g - g[pick[0]]) ** 2).sum(axis=1)
    for i in range(1, k):
        pick[i] = int(np.argmax(d))
        d = np.minimum(d, ((g - g[pick[i]]) ** 2).sum(axis=1))
    return np.sort(pick)


def _cluster_subgraphs(g, pf, rng, max_exemplar_set: int, **ap_kw) -> tuple[np.ndarray, int, int]:
    """Cluster of each sub-graph (N,), clusters, AP iterations (module doc, steps 3-4 and "scale")."""
    N = len(g)
    if N <= max_exemplar_set:
        lab, ex, it = affinity_propagation(similarity(g, pf), rng, **ap_kw)
        return lab, len(ex), it
    rng = as_rng(rng)
    sub = _spread(g, max_exemplar_set, rng)
    S_sub, (wg, wf) = _similarity(g[sub], None if pf is None else pf[sub])
    lab_s, ex, it = affinity_propagation(S_sub, rng, **ap_kw)
    exemplars = sub[ex]

    def to_exemplars(X, width):  # eq. 3-14 between every sub-graph and each exemplar, the sample's widths
        return _kernel(((X[:, None, :] - X[exemplars][None, :, :]) ** 2).sum(axis=2), width)[0]

    S = to_exemplars(g, wg)
    if pf is not None:
        S += to_exemplars(pf, wf)
    lab = np.argmax(S, axis=1)  # eq. 3-13 with the exemplars fixed
    lab[sub] = lab_s
    return lab.astype(np.int64), len(ex), it


def _spread_to_unused(topo: MeshTopology, labels: np.ndarray) -> np.ndarray:
    """Labels (m,) with -1 on unused triangles -> every triangle labelled: an unused one takes the
    label of a labelled neighbour across an edge, repeatedly; a piece with no labelled triangle gets
    a new label of its own."""
    lab = labels.copy()
    P = topo.face_adjacency_pairs
    while True:
        a, b = lab[P[:, 0]], lab[P[:, 1]]
        fa = (a < 0) & (b >= 0)
        fb = (b < 0) & (a >= 0)
        if not (fa.any() or fb.any()):
            break
        lab[P[fa, 0]] = b[fa]
        lab[P[fb, 1]] = a[fb]
    if (lab < 0).any():
        ncomp, comp = topo.face_components(np.where(lab < 0, -1, 0))
        free = np.unique(comp[lab < 0])
        nxt = int(lab.max()) + 1 if (lab >= 0).any() else 0
        for j, c in enumerate(free):
            lab[(comp == c) & (lab < 0)] = nxt + j
    return lab


@dataclass
class LearnedSegmentation(PrintSegmentation):
    """Result of `learned_segmentation`: a `PrintSegmentation` (labels (m,) 0..p-1 by decreasing
    area; ``requested`` 0: the count came from the data) plus what the learned method found."""

    subgraphs: SubGraphs | None = None
    hidden: np.ndarray | None = None  #: (N, 20) hidden features pf (None for the geometric similarity)
    direction: np.ndarray = field(default_factory=lambda: np.zeros(3))  #: (3,) build direction of the features
    ap_clusters: int = 0  #: clusters affinity propagation found
    ap_iterations: int = 0
    similarity_kind: str = "learned"
    seconds: dict = field(default_factory=dict)  #: time per step

    def count_note(self) -> str | None:
        """A warning when the data called for many parts (more than `MANY_PARTS`): every joint of a
        printed bolus is a seam that must close exactly on the skin; None otherwise."""
        p = self.part_count
        if p <= MANY_PARTS:
            return None
        return (f"the learned split made {p} parts (from {self.ap_clusters} clusters): every joint is a seam that "
                f"must meet exactly on the skin; check them on the planning CT, or split with ABcut into fewer parts")

    def summary(self) -> str:
        """One line for the user: clusters, parts, sub-graphs, usage rate."""
        sg = self.subgraphs
        text = (f"affinity propagation found {self.ap_clusters} clusters of {sg.count:,} sub-graphs of "
                f"{sg.size} triangles (triangle usage rate {100 * sg.usage_rate:.1f} %), {self.part_count} "
                f"connected parts")
        if self.part_count == 1:
            text += "; nothing in its printing features calls for a split (ABcut splits into as many as asked)"
        return text

    def table(self, V, F, topo: MeshTopology | None = None) -> dict:
        t = super().table(V, F, topo)
        sg = self.subgraphs
        t.update(requested=None, ap_clusters=self.ap_clusters, subgraphs=sg.count, usage_rate=sg.usage_rate,
                 similarity=self.similarity_kind)
        return t


def learned_segmentation(
    V,
    F,
    rng=0,
    topo: MeshTopology | None = None,
    sae=None,
    similarity_kind: str = "learned",
    size: int = SIZE,
    min_part_fraction: float = MIN_PART_FRACTION,
    face_groups=None,
    direction=None,
    max_exemplar_set: int = MAX_EXEMPLAR_SET,
    progress=None,
    **ap_kw,
) -> LearnedSegmentation:
    """Split V (n,3) mm, F (m,3) into print parts by the learned method (module doc, steps 1-5).

    ``sae`` a `autoencoder.StackedAutoEncoder` (default: the shipped one); ``similarity_kind``
    "learned" (eq. 3-14) or "geometric" (the seed's comparison: centroid distance only);
    ``direction`` (3,) the build direction of the features (default: the whole mesh's best,
    `orientation.orient`); ``face_groups`` (m,) the polygon of each triangle (a polygon
    stays in one sub-graph).  Returns a `LearnedSegmentation`.
    """
    report = progress or (lambda f, t: None)
    if similarity_kind not in SIMILARITIES:
        raise BolusError(f"unknown similarity {similarity_kind!r}; use 'learned' or 'geometric'")
    if not 0.0 <= min_part_fraction < 1.0:
        raise BolusError(f"min_part_fraction must lie in [0, 1), got {min_part_fraction}")
    topo = MeshTopology(*check_mesh(V, F, nondegenerate=False, min_faces=0)) if topo is None else topo
    if topo.m == 0:
        raise BolusError("the mesh has no faces; select the faces to split")
    total = float(topo.areas.sum())
    if not total > 0:
        raise BolusError("the mesh has zero area (all its faces are degenerate); check the mesh")
    if similarity_kind == "learned" and sae is None:
        sae = load_default_sae()
    rng = as_rng(rng)
    secs = {}
    t0 = time.perf_counter()
    report(0.05, "best build direction of the whole")
    b = orient(topo.V, topo.F, topo=topo, rng=rng).direction if direction is None else np.asarray(direction, float)
    report(0.3, "sub-graphs and printing features")
    fe = print_features(topo.V, topo.F, b, topo)
    sg = build_subgraphs(topo, size, face_groups=face_groups)
    if sg.count == 0:
        raise BolusError(f"the region has {topo.m} triangles and no {max(1, size // 2)} of them connected: too "
                         f"small for the learned split (sub-graphs of {size} triangles); use ABcut")
    X = subgraph_rows(fe, sg)
    secs["features"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    pf = None
    if similarity_kind == "learned":
        if sae.sizes[0] != X.shape[1]:
            raise BolusError(f"the auto-encoder takes {sae.sizes[0]} numbers per sub-graph, the sub-graphs of "
                             f"{size} triangles give {X.shape[1]}")
        pf = sae.encode(X)
    secs["encode"] = time.perf_counter() - t1
    report(0.45, f"affinity propagation on {sg.count:,} sub-graphs")
    t2 = time.perf_counter()
    g = topo.centroids[sg.centre]
    sub_lab, n_ap, it = _cluster_subgraphs(g, pf, rng, max_exemplar_set, **ap_kw)
    secs["cluster"] = time.perf_counter() - t2
    report(0.9, "parts")
    lab = np.where(sg.owner >= 0, sub_lab[np.maximum(sg.owner, 0)], -1)
    clusters = _spread_to_unused(topo, lab)
    if face_groups is not None:  # sub-graphs hold whole polygons; an unused polygon may still be torn
        clusters = vote_groups(clusters, face_groups, topo.areas)
    labels = connected_patches(topo, clusters, min_area=min_part_fraction * total)
    secs["total"] = time.perf_counter() - t0
    report(1.0, "done")
    return LearnedSegmentation(
        labels=labels, clusters=clusters, eigenvalues=np.zeros(0), embedding=np.zeros((topo.m, 0)),
        method="learned", requested=0, min_part_fraction=min_part_fraction, subgraphs=sg, hidden=pf,
        direction=b, ap_clusters=n_ap, ap_iterations=it, similarity_kind=similarity_kind, seconds=secs,
    )
