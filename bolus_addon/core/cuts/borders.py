"""Patch borders: the common edges of two patches, ordered, and how much they turn (seed 4.1.2).

A *border* is one connected piece of the edges between the faces of patch a and the
faces of patch b (a < b).  `border_components` finds them and orders each along the
surface (an open chain, or a closed loop when one patch encloses the other);
`turning_per_mm` measures how much a border zig-zags (the figure `smooth_cuts` lowers);
`hausdorff_mm` how far a new cut lies from the old border.  All arrays in, arrays out.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..mesh.boundary import boundary_loops
from ..errors import BolusError
from ..mesh.topology import MeshTopology

__all__ = ["Border", "border_components", "turning_per_mm", "hausdorff_mm", "edge_keys",
           "edge_samples"]

#: points per edge sampled for the Hausdorff distance (the ends and 7 between: 1/8 edge apart)
HAUSDORFF_SAMPLES = 9


@dataclass
class Border:
    """One connected piece of the common border of patches a < b."""

    a: int
    b: int
    edges: np.ndarray  #: (k,2) vertex pairs
    order: np.ndarray | None  #: (j,) vertices along the border (None if it branches)
    closed: bool


def border_components(topo: MeshTopology, labels: np.ndarray) -> list[Border]:
    """Every connected piece of every border between two patches (labels >= 0).

    Parameters
    ----------
    topo : MeshTopology of the mesh (m faces); purely topological, so zero-area
        triangles are fine here.
    labels : (m,) int, the patch of each face; faces with a negative label are in no patch.

    Returns
    -------
    list of `Border`, sorted by the pair (a, b) and, within a pair, by the lowest vertex
    of each piece; each with its edges (k,2) (sorted pairs, in `topo.edges` order) and its
    vertices in order along it.  The order is the boundary of patch a walked by
    `cutting.boundary_loops` (the core's one boundary walker), so patch a lies on the left
    of the direction of travel on a consistently oriented mesh and a border that touches
    itself at a vertex (a "pinch" of the zig-zag) is passed through it along the surface;
    pieces of a's boundary that meet at a vertex (where a third patch or the mesh's edge
    interrupts a's boundary) are joined end to start.  ``order`` is None when a piece
    branches (three or more of its ends meet).

    Raises `BolusError` when ``labels`` has the wrong shape or when a face of a patch at a
    border has an edge shared by more than two faces (a border is only defined on a
    manifold surface).
    """
    labels = np.asarray(labels)
    if labels.shape != (topo.m,):
        raise BolusError(f"labels must give one patch per triangle ({topo.m}), got shape {labels.shape}")
    P = topo.face_adjacency_pairs
    E = topo.face_adjacency_edges
    la, lb = labels[P[:, 0]], labels[P[:, 1]]
    keep = (la != lb) & (la >= 0) & (lb >= 0)
    if topo.nonmanifold_edges[E[keep]].any():
        e = int(E[keep][np.argmax(topo.nonmanifold_edges[E[keep]])])
        u, v = (int(x) for x in topo.edges[e])
        raise BolusError(f"a patch border runs along a non-manifold edge (vertices {u}, {v}: more than two faces); "
                         "clean it up first (Select > Select All by Trait > Non Manifold)")
    lo, hi, E = np.minimum(la, lb)[keep], np.maximum(la, lb)[keep], E[keep]
    out: list[Border] = []
    for a, b in sorted(set(zip(lo.tolist(), hi.tolist()))):
        edges = topo.edges[np.unique(E[(lo == a) & (hi == b)])]
        for ce, order, closed in _pair_pieces(topo, labels, a, edges):
            out.append(Border(a, b, ce, order, closed))
    return out


def _pair_pieces(topo: MeshTopology, labels: np.ndarray, a: int, edges: np.ndarray):
    """[(edges (k_i,2), order or None, closed)] of each connected piece of the a|b edges (k,2).

    Runs of a|b edges along the boundary loops of patch a (only a's faces at the border:
    their fans at the border vertices are complete, so the walk there is a's), joined.
    """
    on = np.zeros(topo.n, dtype=bool)
    on[edges.ravel()] = True
    fa = np.nonzero((labels == a) & on[topo.F].any(axis=1))[0]
    keys = np.sort(edge_keys(edges))
    runs = []  # (vertices, closed)
    for lp in boundary_loops(topo.F[fa]):
        flag = np.isin(edge_keys(np.stack([lp, np.roll(lp, -1)], 1)), keys)
        if flag.all():
            runs.append((lp, True))
        elif flag.any():
            k = int(np.argmin(flag))  # a non-border edge: start the loop there so no run wraps
            r, f = np.r_[lp[k:], lp[:k], lp[k]], np.r_[flag[k:], flag[:k]]
            bounds = np.flatnonzero(np.diff(np.r_[0, f.astype(np.int8), 0]))
            runs += [(r[s : e + 1], False) for s, e in zip(bounds[0::2], bounds[1::2])]
    pieces = []
    for ce in _edge_components(edges):
        vs = set(ce.ravel().tolist())
        mine = [rn for rn in runs if rn[0][0] in vs]
        order, closed = _join_runs(mine)
        pieces.append((ce, order, closed))
    return pieces


def _join_runs(runs: list[tuple[np.ndarray, bool]]) -> tuple[np.ndarray | None, bool]:
    """One vertex chain from runs of one connected piece, joined where one ends and the next
    starts: (order, closed), or (None, False) when they do not make a single chain."""
    if len(runs) == 1 and runs[0][1]:
        return runs[0]
    if any(closed for _, closed in runs):
        return None, False
    starts: dict[int, list[int]] = {}
    for i, (rn, _) in enumerate(runs):
        starts.setdefault(int(rn[0]), []).append(i)
    if any(len(v) > 1 for v in starts.values()):
        return None, False
    ends = {int(rn[-1]) for rn, _ in runs}
    first = [i for i, (rn, _) in enumerate(runs) if int(rn[0]) not in ends] or [0]
    if len(first) > 1:
        return None, False
    chain, used, i = [runs[first[0]][0]], {first[0]}, first[0]
    while True:
        nxt = starts.get(int(runs[i][0][-1]), [])
        if not nxt or nxt[0] in used:
            break
        i = nxt[0]
        used.add(i)
        chain.append(runs[i][0][1:])
    if len(used) != len(runs):
        return None, False
    order = np.concatenate(chain)
    if order[0] == order[-1] and len(order) > 2:
        return order[:-1], True
    return order, False


def _edge_components(edges: np.ndarray) -> list[np.ndarray]:
    """The edge-connected pieces (each (k_i,2)) of an edge set (k,2), by their lowest vertex."""
    verts, inv = np.unique(edges.ravel(), return_inverse=True)
    inv = inv.reshape(-1, 2)
    G = sp.coo_matrix((np.ones(len(inv)), (inv[:, 0], inv[:, 1])), shape=(len(verts),) * 2)
    ncomp, comp = connected_components(G, directed=False)
    return [edges[comp[inv[:, 0]] == c] for c in range(ncomp)]


def turning_per_mm(V: np.ndarray, edges: np.ndarray, normals: np.ndarray | None = None) -> tuple[float, float]:
    """Mean absolute turning angle per mm of a border edge set, and its length.

    Parameters
    ----------
    V : (n,3) vertex positions, mm.
    edges : (k,2) int vertex pairs.
    normals : optional (n,3) unit vertex normals of the surface.

    Returns
    -------
    (turning, length): turning in rad/mm, length in mm (0.0, 0.0 for no edges).

    The turning angle is taken at every vertex joining exactly two of the edges: the
    angle between the incoming and the outgoing direction.  With ``normals`` both
    directions are first projected on the tangent plane, so the measure is the cut's
    geodesic turning, the bending a modeler sees on the skin, without the surface's
    own curvature (a straight cut over a curved nose has none); without them it is the
    plain 3D angle.  Ends and branch points are skipped, and so is a vertex where a
    direction has zero length (a zero-length edge, or an edge along the normal): it
    has no direction to turn from.  Summed and divided by the total length.
    Raises `BolusError` for NaN/inf positions on the edges.
    """
    edges = np.asarray(edges)
    if len(edges) == 0:
        return 0.0, 0.0
    if not np.isfinite(V[edges]).all():
        bad = int(edges.ravel()[np.argmax(~np.isfinite(V[edges.ravel()]).all(axis=1))])
        raise BolusError(f"border vertex {bad} has a non-finite (NaN or infinite) coordinate")
    d = V[edges[:, 1]] - V[edges[:, 0]]
    length = float(np.linalg.norm(d, axis=1).sum())
    mids, a_end, b_end = _two_edge_vertices(edges)
    if not len(mids):
        return 0.0, length
    di, dj = V[a_end] - V[mids], V[b_end] - V[mids]  # pointing away from the vertex
    if normals is not None:
        nrm = normals[mids]
        di = di - (di * nrm).sum(1, keepdims=True) * nrm
        dj = dj - (dj * nrm).sum(1, keepdims=True) * nrm
    ni, nj = np.linalg.norm(di, axis=1), np.linalg.norm(dj, axis=1)
    ok = (ni > 0) & (nj > 0)
    c = (di * dj).sum(1)[ok] / (ni * nj)[ok]
    total = float((np.pi - np.arccos(np.clip(c, -1.0, 1.0))).sum())
    return total / max(length, 1e-300), length


def _two_edge_vertices(edges: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mids, a_end, b_end): the vertices joining exactly two edges and the far ends of those edges."""
    inc: dict[int, list[int]] = {}
    for i, (u, v) in enumerate(edges.tolist()):
        inc.setdefault(u, []).append(i)
        inc.setdefault(v, []).append(i)
    mids, a_end, b_end = [], [], []
    for vtx, es in inc.items():
        if len(es) != 2:
            continue
        i, j = es
        mids.append(vtx)
        a_end.append(edges[i, 1] if edges[i, 0] == vtx else edges[i, 0])
        b_end.append(edges[j, 1] if edges[j, 0] == vtx else edges[j, 0])
    return np.array(mids, dtype=np.int64), np.array(a_end, dtype=np.int64), np.array(b_end, dtype=np.int64)


def edge_keys(E: np.ndarray) -> np.ndarray:
    """One int64 key (k,) per undirected edge of E (k,2) (vertex ids below 2**32)."""
    E = np.sort(E, axis=1)
    return E[:, 0] * (1 << 32) + E[:, 1]


def edge_samples(E: np.ndarray, V: np.ndarray, k: int = HAUSDORFF_SAMPLES) -> np.ndarray:
    """Points (len(E) * k, 3): k evenly spaced points on every edge of E (ends included)."""
    p, q = V[E[:, 0]], V[E[:, 1]]
    s = np.linspace(0.0, 1.0, k)
    return (p[:, None, :] + s[None, :, None] * (q - p)[:, None, :]).reshape(-1, 3)


def hausdorff_mm(E_old: np.ndarray, V_old: np.ndarray, E_new: np.ndarray, V_new: np.ndarray) -> float:
    """Symmetric Hausdorff distance (mm) between two edge sets (sampled on the edges); inf if one is empty."""
    if len(E_new) == 0 or len(E_old) == 0:
        return float("inf")
    A, B = edge_samples(E_old, V_old), edge_samples(E_new, V_new)
    return float(max(cKDTree(A).query(B)[0].max(), cKDTree(B).query(A)[0].max()))
