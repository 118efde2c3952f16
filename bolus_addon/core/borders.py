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

from .errors import BolusError
from .topology import MeshTopology

__all__ = ["Border", "border_components", "order_edges", "turning_per_mm", "hausdorff_mm", "edge_keys",
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
    list of `Border`, sorted by the pair (a, b), each with its edges (k,2) and its
    vertices in order along it (`order_edges`).

    Raises `BolusError` when ``labels`` has the wrong shape or when a border edge is
    shared by more than two faces (a border is only defined on a manifold surface).
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
        for ce in _edge_components(edges):
            order, closed = order_edges(ce)
            out.append(Border(a, b, ce, order, closed))
    return out


def _edge_components(edges: np.ndarray) -> list[np.ndarray]:
    """The edge-connected pieces (each (k_i,2)) of an edge set (k,2)."""
    verts, inv = np.unique(edges.ravel(), return_inverse=True)
    inv = inv.reshape(-1, 2)
    G = sp.coo_matrix((np.ones(len(inv)), (inv[:, 0], inv[:, 1])), shape=(len(verts),) * 2)
    ncomp, comp = connected_components(G, directed=False)
    return [edges[comp[inv[:, 0]] == c] for c in range(ncomp)]


def order_edges(edges: np.ndarray) -> tuple[np.ndarray | None, bool]:
    """Vertices of a connected edge set along it.

    Parameters
    ----------
    edges : (k,2) int vertex pairs, edge-connected.

    Returns
    -------
    (order, closed): order (j,) int64 the vertices along the edges (j = k + 1 for an
    open chain, k for a loop, whose closing edge is order[-1] -> order[0]), or None when
    the edges cannot be walked in one go (a real branch); closed True for a loop.

    A border may touch itself at a vertex (four border edges there, a "pinch" of the
    zig-zag); the walk then goes on along an edge not yet used, using every edge once
    (Hierholzer's algorithm on the undirected multigraph).  This walks an arbitrary
    edge set; the boundary of a set of faces is walked by `cutting.boundary_loops`.
    """
    nbr: dict[int, list[int]] = {}
    for u, v in np.asarray(edges).tolist():
        nbr.setdefault(u, []).append(v)
        nbr.setdefault(v, []).append(u)
    odd = [k for k, v in nbr.items() if len(v) % 2 == 1]
    if len(odd) not in (0, 2) or not nbr:
        return None, False
    closed = not odd
    path = _euler_walk(nbr, min(nbr) if closed else min(odd))
    if len(path) != len(edges) + 1:
        return None, False
    order = np.array(path[::-1], dtype=np.int64)
    return (order[:-1] if closed else order), closed


def _euler_walk(nbr: dict[int, list[int]], start: int) -> list[int]:
    """Hierholzer's walk from ``start`` using every edge of the adjacency lists once (reversed)."""
    adj = {k: list(v) for k, v in nbr.items()}
    stack, path = [start], []
    while stack:
        u = stack[-1]
        if adj[u]:
            v = adj[u].pop()
            adj[v].remove(u)
            stack.append(v)
        else:
            path.append(stack.pop())
    return path


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
