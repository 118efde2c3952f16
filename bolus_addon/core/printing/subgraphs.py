"""Sub-graph data structure of the learned print segmentation (seed 6.4.1, Figure 6-15).

A mesh V (n,3) mm, F (m,3) is pre-segmented into sub-graphs of ``size`` (seed: 30) edge-connected
triangles, each described by a row of 3 x size numbers: the printing features (Q', U', K') of its
triangles in the seed's search order (Figure 6-15 (b), (c): the seed triangle, then breadth-first
through adjacent triangles), zero-padded.  The rows feed the stacked auto-encoder (`autoencoder`).

* `build_subgraphs`: breadth-first growth from seed triangles laid front by front; a polygon
  (``face_groups``) is never cut; a growth walled in early is kept when it holds at least
  ``min_fill`` triangles, else its triangles are left unused (-1); the central triangle g
  (eq. 3-14) is the one nearest the sub-graph's area-weighted centroid;
* `print_features`, per triangle at the build direction b of least WQ + WU (eqs. 6-7, 6-14):
  Q(f) = h |n_f . b| (eq. 6-1) and U(f) = c_f . b - z0 on overhangs, 0 elsewhere
  (eqs. 6-9..6-11), each min-max normalised (eqs. 6-6, 6-13); K(f) the Moreton-Sequin normal
  curvature mapped to [0, 1] (eq. 6-20, `analysis.curvature`).

Design notes: docs/design/printing.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse.csgraph import breadth_first_order, connected_components

from ..analysis.curvature import normal_curvature
from ..errors import BolusError
from .measures import CRITICAL_ANGLE_DEG, LAYER_MM, unit_rows
from ..mesh.topology import MeshTopology, check_mesh

__all__ = ["SIZE", "FEATURES", "SubGraphs", "build_subgraphs", "print_features", "minmax", "subgraph_rows"]

SIZE = 30  #: triangles per sub-graph (seed 6.4.2)
FEATURES = 3  #: Q', U', K' per triangle (seed 6.4.1)


@dataclass
class SubGraphs:
    """Result of `build_subgraphs` on a mesh with m triangles: N sub-graphs."""

    faces: np.ndarray  #: (N, size) int, the triangles of each sub-graph in search order, -1 padded
    owner: np.ndarray  #: (m,) int, the sub-graph of each triangle, -1 for unused triangles
    centre: np.ndarray  #: (N,) int, the central triangle of each sub-graph (eq. 3-14's g)
    size: int

    @property
    def count(self) -> int:
        return int(len(self.faces))

    @property
    def usage_rate(self) -> float:
        """Share of the triangles that lie in some sub-graph (seed Table 6-3)."""
        return float((self.owner >= 0).mean()) if self.owner.size else 0.0

    @property
    def fill(self) -> np.ndarray:
        """(N,) triangles in each sub-graph's row (size, or fewer when zero-padded)."""
        return (self.faces >= 0).sum(axis=1)


def _groups_csr(face_groups, m: int):
    """(order, starts): the triangles of each polygon, for taking a polygon whole."""
    g = np.asarray(face_groups)
    if g.shape != (m,):
        raise BolusError(f"face groups must be one per triangle ({m}), got shape {g.shape}")
    _, inv = np.unique(g, return_inverse=True)
    inv = inv.reshape(-1)
    order = np.argsort(inv, kind="stable")
    starts = np.r_[0, np.cumsum(np.bincount(inv))]
    return inv, order, starts


def build_subgraphs(topo: MeshTopology, size: int = SIZE, min_fill: int | None = None,
                    face_groups=None) -> SubGraphs:
    """Pre-segment the mesh of ``topo`` (m triangles) into sub-graphs of ``size`` triangles
    (seed 6.4.1; growth, seeds and leftovers as in the module doc) -> `SubGraphs`."""
    size = int(size)
    if size < 1:
        raise BolusError(f"a sub-graph needs at least 1 triangle, got {size}")
    min_fill = max(1, size // 2) if min_fill is None else int(min_fill)
    if not 1 <= min_fill <= size:
        raise BolusError(f"min_fill must lie in 1..{size}, got {min_fill}")
    m = topo.m
    A = topo.face_adjacency
    indptr, indices = A.indptr, A.indices
    if face_groups is not None:
        ginv, gorder, gstarts = _groups_csr(face_groups, m)
    ncomp, comp = connected_components(A, directed=False)
    # one breadth-first order of every component, from its lowest-index triangle
    first = np.full(ncomp, m, dtype=np.int64)
    np.minimum.at(first, comp, np.arange(m))
    sweep = np.concatenate([breadth_first_order(A, int(s), directed=False, return_predecessors=False)
                            for s in np.sort(first)]) if m else np.zeros(0, dtype=np.int64)
    owner = np.full(m, -1, dtype=np.int64)
    taken = np.zeros(m, dtype=bool)
    rows: list[list[int]] = []
    for s in sweep.tolist():
        if taken[s]:
            continue
        got: list[int] = []
        queue = [s]
        head = 0
        while head < len(queue) and len(got) < size:
            t = queue[head]
            head += 1
            if taken[t]:
                continue
            mates = [t] if face_groups is None else [t] + [u for u in gorder[gstarts[ginv[t]]:gstarts[ginv[t] + 1]]
                                                          .tolist() if u != t and not taken[u]]
            for u in mates:
                taken[u] = True
                got.append(u)
                queue.extend(indices[indptr[u]:indptr[u + 1]].tolist())
        if len(got) >= min_fill:
            owner[got] = len(rows)
            rows.append(got)
    N = len(rows)
    faces = np.full((N, size), -1, dtype=np.int64)
    centre = np.zeros(N, dtype=np.int64)
    C, a = topo.centroids, topo.areas
    for i, got in enumerate(rows):
        faces[i, :min(size, len(got))] = got[:size]
        g = np.asarray(got)
        w = a[g] if a[g].sum() > 0 else np.ones(len(g))
        mid = (C[g] * w[:, None]).sum(axis=0) / w.sum()
        centre[i] = g[np.argmin(((C[g] - mid) ** 2).sum(axis=1))]
    return SubGraphs(faces, owner, centre, size)


def minmax(x) -> np.ndarray:
    """Eqs. 6-6, 6-13: (x - min x) / (max x - min x) -> [0, 1]; all zeros when x is constant."""
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return x.copy()
    lo, hi = float(x.min()), float(x.max())
    return (x - lo) / (hi - lo) if hi > lo else np.zeros_like(x)


def print_features(V, F, direction, topo: MeshTopology | None = None, h: float = LAYER_MM,
                   critical_angle_deg: float = CRITICAL_ANGLE_DEG) -> np.ndarray:
    """(m, 3) per-triangle printing features (Q', U', K') in [0, 1] for the build direction
    ``direction`` (3,) on V (n,3) mm, F (m,3) (module doc; eqs. 6-1, 6-6, 6-9..6-13, 6-20)."""
    topo = MeshTopology(*check_mesh(V, F, nondegenerate=False)) if topo is None else topo
    b = unit_rows(direction)
    N = topo.face_normals
    nb = N @ b
    Q = float(h) * np.abs(nb)  # eq. 6-1 per unit area
    z0 = float((topo.V[topo.used_vertices] @ b).min()) if topo.used_vertices.size else 0.0
    over = nb < -np.cos(np.radians(critical_angle_deg))
    U = np.where(over, topo.centroids @ b - z0, 0.0)  # eqs. 6-9..6-11 per unit area
    K = normal_curvature(topo.V, topo.F, topo).face_normalised  # eq. 6-20
    return np.stack([minmax(Q), minmax(U), K], axis=1)


def subgraph_rows(features, sub: SubGraphs) -> np.ndarray:
    """(N, 3 size) rows of Figure 6-15 (c): [1Q, 1U, 1K, 2Q, 2U, 2K, ...] of each sub-graph's
    triangles in search order, zeros where the sub-graph has fewer triangles."""
    Fe = np.asarray(features, dtype=np.float64)
    if Fe.ndim != 2 or Fe.shape[1] != FEATURES:
        raise BolusError(f"features must be (m, {FEATURES}), got {Fe.shape}")
    idx = sub.faces
    out = np.where((idx >= 0)[:, :, None], Fe[np.maximum(idx, 0)], 0.0)
    return out.reshape(len(idx), FEATURES * sub.size)
