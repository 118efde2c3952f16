"""Cut a patch to a topological disk before unfolding (seed 4.5).

The seed's unfolding (4.5.1) grows a flat pattern triangle by triangle from a central
triangle; that only closes up without tearing when the patch is a disk.  Patches that
are not disks (a ring around a knee, a face patch with a mouth hole, a closed cap) are
cut here along short edge paths, and the result says where, for the user report:

- several boundary loops: every other loop is joined to the outer (longest) loop by
  the shortest interior edge path (Dijkstra on edge lengths), one loop at a time, each
  cut becoming boundary before the next is computed, so cuts never cross;
- closed surface of genus 0: one cut along a shortest path between two vertices far
  apart (at least two edges, so the result is a disk bounded by the doubled path);
- genus > 0, several parts, non-manifold edges or a non-orientable patch: `BolusError`.

Cutting duplicates vertices (`split_along_edges`): a vertex keeps its index for its
first wedge of corners, later wedges get new indices after the old ones, and
``vert_origin`` maps every new vertex back to the input.  Pinched ("bow-tie") vertices
are split the same way.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from ..errors import BolusError
from .topology import MeshTopology, check_mesh

__all__ = [
    "CutResult",
    "boundary_loops",
    "edge_paths",
    "loop_length",
    "surface_type",
    "split_along_edges",
    "cut_to_disk",
]


# ------------------------------------------------------------------- helpers
def _topology_of_faces(F) -> MeshTopology:
    """MeshTopology of a face array alone (vertex positions are not needed)."""
    F = np.asarray(F)
    n = int(F.max()) + 1 if F.size else 0
    return MeshTopology(np.zeros((n, 3)), F)


def _corner_wedges(topo: MeshTopology, cut=None) -> tuple[int, np.ndarray]:
    """Wedge label of every corner (3m,): corner 3f+k is vertex F[f, k].

    Corners of one vertex are joined across every edge their faces share (consecutive
    faces on a non-manifold edge, as in `MeshTopology.vertex_fan_count`) except the
    edges marked in ``cut`` (e,) bool.  A label never mixes vertices.
    """
    F, m = topo.F, topo.m
    P = topo.face_adjacency_pairs
    e = topo.face_adjacency_edges
    if cut is not None:
        keep = ~cut[e]
        P, e = P[keep], e[keep]
    fa, fb = P[:, 0], P[:, 1]
    rows, cols = [], []
    for end in (0, 1):
        v = topo.edges[e, end]
        rows.append(3 * fa + np.argmax(F[fa] == v[:, None], axis=1))
        cols.append(3 * fb + np.argmax(F[fb] == v[:, None], axis=1))
    rows = np.concatenate(rows)
    cols = np.concatenate(cols)
    G = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * m, 3 * m))
    return connected_components(G, directed=False)


def _edge_ids(topo: MeshTopology, pairs) -> np.ndarray:
    """Edge index of each vertex pair (k,2); BolusError if a pair is not a mesh edge."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if len(pairs) == 0:
        return np.zeros(0, dtype=np.int64)
    n = max(topo.n, 1)
    if pairs.min() < 0 or pairs.max() >= topo.n:
        raise BolusError("a cut edge refers to a vertex that is not in the mesh")
    E = topo.edges
    keys = E[:, 0] * n + E[:, 1]  # sorted (np.unique in MeshTopology)
    q = np.minimum(pairs[:, 0], pairs[:, 1]) * n + np.maximum(pairs[:, 0], pairs[:, 1])
    idx = np.searchsorted(keys, q)
    idx = np.minimum(idx, len(keys) - 1)
    bad = keys[idx] != q
    if bad.any():
        a, b = pairs[np.argmax(bad)]
        raise BolusError(f"cut edge ({a}, {b}) is not an edge of the mesh")
    return idx


def _wedge_ends_of_boundary(topo: MeshTopology):
    """Boundary edges (b,), their half-edge tail/head vertices and the wedge at each end."""
    if topo.nonmanifold_edges.any():
        i, j = (int(x) for x in topo.edges[np.argmax(topo.nonmanifold_edges)])
        raise BolusError(
            f"the mesh has {int(topo.nonmanifold_edges.sum())} edges shared by more than two faces (e.g. between "
            f"vertices {i} and {j}); clean them up first (Select > Select All by Trait > Non Manifold)"
        )
    F = topo.F
    b = np.nonzero(topo.boundary_edges)[0]
    f = topo.edge_faces[b, 0]
    k = np.argmax(topo.face_edges[f] == b[:, None], axis=1)
    k1 = (k + 1) % 3
    _, wedge = _corner_wedges(topo)
    return b, F[f, k], F[f, k1], wedge[3 * f + k], wedge[3 * f + k1]


# -------------------------------------------------------------- boundary loops
def boundary_loops(F, topo: MeshTopology | None = None) -> list[np.ndarray]:
    """Ordered vertex loops of the boundary, longest (most vertices) first.

    The one boundary walker of the core: every module that follows a boundary calls it.

    Parameters
    ----------
    F : (m,3) int triangles (vertex positions are not needed).
    topo : optional `MeshTopology` of the same triangles, to reuse its cached edges.

    Returns
    -------
    list of (k_i,) int64 arrays [v0, v1, ...], one per loop, the closing edge
    v_last -> v0 implied; [] for a closed surface (or no triangles).  Each loop runs along
    the half-edges of its triangles, so on a counter-clockwise disk the outer loop is
    counter-clockwise and holes are clockwise.  Consecutive boundary edges are chained
    through the fan (wedge) of corners at their shared vertex, so a vertex where two
    loops touch (or one loop touches itself) is passed once per wedge; the direction of a
    loop on a badly oriented mesh follows its lowest-numbered edge.  Purely topological:
    zero-area triangles do not matter.

    Raises `BolusError` for bad indices or triangles that repeat a vertex (naming the
    triangle) and for non-manifold edges (naming one).
    """
    if topo is None:
        topo = _topology_of_faces(F)
    b, tail, head, wt, wh = _wedge_ends_of_boundary(topo)
    nb = len(b)
    if nb == 0:
        return []
    # end j < nb: tail of edge j, end nb + j: head of edge j; ends in one wedge are partners
    end_vertex = np.r_[tail, head]
    end_wedge = np.r_[wt, wh]
    order = np.argsort(end_wedge, kind="stable")
    w_sorted = end_wedge[order]
    if len(order) % 2 or np.any(w_sorted[0::2] != w_sorted[1::2]) or np.any(w_sorted[1:-1:2] == w_sorted[2::2]):
        raise BolusError("the boundary of the mesh could not be followed (a fan with an odd number of boundary edges)")
    partner = np.empty(2 * nb, dtype=np.int64)
    partner[order[0::2]] = order[1::2]
    partner[order[1::2]] = order[0::2]
    visited = np.zeros(nb, dtype=bool)
    loops = []
    for i0 in range(nb):  # a walk over boundary edges only (O(sqrt m) of them)
        if visited[i0]:
            continue
        seq = []
        ent = i0
        for _ in range(nb + 1):
            i = ent % nb
            if visited[i]:
                break
            visited[i] = True
            seq.append(end_vertex[ent])
            ex = ent + nb if ent < nb else ent - nb
            ent = partner[ex]
        loops.append(np.asarray(seq, dtype=np.int64))
    loops.sort(key=len, reverse=True)
    return loops


def loop_length(V, loop) -> float:
    """Length of a closed vertex loop (including the closing edge), in V's units."""
    P = np.asarray(V)[np.asarray(loop)]
    return float(np.linalg.norm(P - np.roll(P, -1, axis=0), axis=1).sum())


def _orientation_info(topo: MeshTopology) -> tuple[bool, bool]:
    """(consistently oriented, orientable) from the faces sharing manifold edges."""
    F, m = topo.F, topo.m
    P = topo.face_adjacency_pairs
    e = topo.face_adjacency_edges
    man = topo.edge_face_count[e] == 2
    P, e = P[man], e[man]
    if len(P) == 0:
        return True, True
    u = topo.edges[e, 0]
    fwd = []
    for f in (P[:, 0], P[:, 1]):
        k = np.argmax(topo.face_edges[f] == e[:, None], axis=1)
        fwd.append(F[f, k] == u)  # half-edge runs u -> v in face f
    flip = fwd[0] == fwd[1]  # same direction in both faces: one of them is flipped
    if not flip.any():
        return True, True
    # orientable iff faces can be 2-coloured with "flip" edges changing the colour
    a, c = P[:, 0], P[:, 1]
    rows = np.r_[a, a + m]
    cols = np.r_[np.where(flip, c + m, c), np.where(flip, c, c + m)]
    G = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(2 * m, 2 * m))
    _, comp = connected_components(G, directed=False)
    return False, bool(np.all(comp[:m] != comp[m:]))


def surface_type(V, F) -> dict:
    """Topology of a patch: is it a disk that can be unfolded as it is?

    V (n,3), F (m,3); purely topological (zero-area triangles count like any other;
    NaN/inf coordinates or bad indices raise `BolusError` naming the vertex or triangle).
    Returns a dict:
      vertices, edges, faces          counts (vertices referenced by a face only)
      euler_characteristic            V - E + F
      boundary_loops                  number of loops (None with non-manifold edges)
      components                      edge-connected parts
      nonmanifold_edges, pinched_vertices   counts of edges with > 2 faces, bow-tie vertices
      consistently_oriented, orientable
      genus                           total handles, from chi = 2c - 2g - b computed after
                                      splitting pinched vertices (None if non-orientable
                                      or non-manifold)
      is_disk                         one manifold component with one loop and chi = 1
    """
    topo = MeshTopology(V, F)
    nv = int(topo.used_vertices.sum())
    ne = len(topo.edges)
    chi = nv - ne + topo.m
    n_nm_edges = int(topo.nonmanifold_edges.sum())
    fans = topo.vertex_fan_count
    pinched = int((fans > 1).sum())
    ncomp = int(topo.face_components()[0]) if topo.m else 0
    oriented, orientable = _orientation_info(topo)
    loops = None if n_nm_edges else len(boundary_loops(topo.F, topo))
    genus = None
    if loops is not None and orientable:
        chi_split = chi + int(fans.sum()) - nv  # each extra wedge of a pinched vertex is a vertex
        genus = (2 * ncomp - chi_split - loops) // 2
    is_disk = bool(n_nm_edges == 0 and pinched == 0 and ncomp == 1 and loops == 1 and chi == 1)
    return {
        "vertices": nv,
        "edges": ne,
        "faces": topo.m,
        "euler_characteristic": chi,
        "boundary_loops": loops,
        "components": ncomp,
        "nonmanifold_edges": n_nm_edges,
        "pinched_vertices": pinched,
        "consistently_oriented": oriented,
        "orientable": orientable,
        "genus": genus,
        "is_disk": is_disk,
    }


# ----------------------------------------------------------------- splitting
def split_along_edges(F, cut_edges, topo: MeshTopology | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Duplicate vertices so that the cut edges become boundary on both sides.

    F (m,3); cut_edges (k,2) vertex pairs that are edges of F (k may be 0).
    The corners of each vertex are grouped into wedges, joined only across shared
    edges that are not cut; every wedge gets its own vertex.  The wedge holding a
    vertex's lowest corner keeps the vertex's index, the others get n, n+1, ... in
    order of (vertex, lowest corner).  Pinched (bow-tie) vertices are split too.
    Returns F_new (m,3), same face order, and vert_origin (n_new,) with
    vert_origin[i] == i for i < n (n = F.max() + 1 or topo.n; unused vertices kept).
    """
    if topo is None:
        topo = _topology_of_faces(F)
    F = topo.F
    n, m = topo.n, topo.m
    cut = np.zeros(len(topo.edges), dtype=bool)
    cut[_edge_ids(topo, cut_edges)] = True
    ncomp, comp = _corner_wedges(topo, cut)
    corner_v = F.ravel()
    key = corner_v * max(ncomp, 1) + comp
    uniq, first, inv = np.unique(key, return_index=True, return_inverse=True)
    wv = uniq // max(ncomp, 1)
    order = np.lexsort((first, wv))
    wv_s = wv[order]
    is_first = np.ones(len(wv_s), dtype=bool)
    is_first[1:] = wv_s[1:] != wv_s[:-1]
    new_s = np.empty(len(wv_s), dtype=np.int64)
    new_s[is_first] = wv_s[is_first]
    extra = ~is_first
    new_s[extra] = n + np.arange(int(extra.sum()))
    new_id = np.empty_like(new_s)
    new_id[order] = new_s
    F_new = new_id[inv.reshape(-1)].reshape(m, 3)
    vert_origin = np.r_[np.arange(n, dtype=np.int64), wv_s[extra]]
    return F_new, vert_origin


# -------------------------------------------------------------------- cutting
@dataclass
class CutResult:
    """A patch cut to a disk: vertices may be duplicated along the cuts."""

    V: np.ndarray  #: (n2,3) positions, V_input[vert_origin]
    F: np.ndarray  #: (m,3) triangles, same order as the input's
    vert_origin: np.ndarray  #: (n2,) input vertex of every vertex (identity for i < n)
    cut_paths: list = field(default_factory=list)  #: vertex paths (input indices), one per cut
    cut_length_mm: float = 0.0  #: total length of the cuts (one side)
    description: str = "already a disk: no cut needed"  #: for the user report

    @property
    def was_cut(self) -> bool:
        return bool(self.cut_paths)


def _edge_graph(V: np.ndarray, topo: MeshTopology, allowed: np.ndarray) -> sp.csr_matrix:
    """Symmetric graph on the allowed edges weighted by length (never an explicit 0)."""
    E = topo.edges[allowed]
    L = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    L = np.maximum(L, 1e-12 * max(float(L.mean()) if len(L) else 1.0, 1e-300))
    n = len(V)
    return sp.coo_matrix((np.r_[L, L], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(n, n)).tocsr()


def _path_from(pred: np.ndarray, t: int) -> np.ndarray:
    path = [t]
    while pred[path[-1]] >= 0:
        path.append(int(pred[path[-1]]))
    return np.asarray(path, dtype=np.int64)


def _path_length(V, path) -> float:
    return float(np.linalg.norm(np.diff(V[path], axis=0), axis=1).sum())


def cut_to_disk(V, F) -> CutResult:
    """Cut a patch to a topological disk along short edge paths.

    Parameters
    ----------
    V : (n,3) mm.  F : (m,3) triangles of one patch.

    Returns
    -------
    `CutResult`: V (n2,3), F (m,3) in the input's face order, vert_origin (n2,), the cut
    paths (input vertex ids), their length and a description.  A disk comes back
    unchanged (no cut).  Other loops are joined to the outer (longest) loop by shortest
    interior paths; a closed genus-0 surface is cut between two far-apart vertices.  The
    result is checked to be one component with one boundary loop and Euler
    characteristic 1.  Zero-area triangles are fine here (the cut is topological; edge
    lengths only rank the paths).

    Raises `BolusError` for NaN/inf coordinates or bad indices (naming the vertex or
    triangle), several parts, handles (genus > 0), non-manifold edges or a
    non-orientable patch, with what to do about it.
    """
    V, F = check_mesh(V, F, "the patch", nondegenerate=False, min_faces=1)
    topo = MeshTopology(V, F)
    if topo.nonmanifold_edges.any():
        i, j = (int(x) for x in topo.edges[np.argmax(topo.nonmanifold_edges)])
        raise BolusError(
            f"the patch has {int(topo.nonmanifold_edges.sum())} edges shared by more than two faces (e.g. between "
            f"vertices {i} and {j}) and cannot be flattened; clean them up first "
            "(Select > Select All by Trait > Non Manifold)"
        )
    cut = _Cutter(V, F, np.arange(len(V), dtype=np.int64))
    notes = []
    pinched = np.nonzero(topo.vertex_fan_count > 1)[0]
    if len(pinched):
        cut.F, cut.origin = split_along_edges(F, np.zeros((0, 2), dtype=np.int64), topo)
        notes.append(f"split {len(pinched)} pinched vertex(es) (e.g. vertex {int(pinched[0])})")
    st = surface_type(cut.Vc, cut.F)
    if st["is_disk"] and not notes:  # nothing to cut (the checks below would find it unchanged)
        return CutResult(V=cut.Vc, F=cut.F, vert_origin=cut.origin, cut_paths=[], cut_length_mm=0.0,
                         description=cut.description(notes))
    _require_cuttable(st)
    if st["boundary_loops"] == 0:
        cut.open_closed_surface()
    cut.join_loops()
    if not surface_type(cut.Vc, cut.F)["is_disk"]:
        raise BolusError("internal error: cutting the patch did not give a disk; please report this mesh")
    return CutResult(V=cut.Vc, F=cut.F, vert_origin=cut.origin, cut_paths=cut.paths,
                     cut_length_mm=float(sum(cut.lengths)), description=cut.description(notes))


def _require_cuttable(st: dict) -> None:
    """BolusError for what no short cut opens to a disk: several parts, non-orientable, handles."""
    if st["components"] > 1:
        raise BolusError(
            f"the patch has {st['components']} separate parts; unfold each part on its own "
            "(Mesh > Separate > By Loose Parts) or segment into more patches"
        )
    if not st["orientable"]:
        raise BolusError(
            "the patch is not orientable (like a Moebius strip) and cannot be flattened as one piece; "
            "segment it into more patches"
        )
    if st["genus"] > 0:
        raise BolusError(
            f"the patch has {st['genus']} handle(s) (genus {st['genus']}, e.g. a ring closed over a tunnel) and "
            "cannot be opened to a disk by a short cut; segment it into more patches"
        )


@dataclass
class _Cutter:
    """The patch being cut: input V (n,3), current faces F (m,3) and vertex origins (n2,)."""

    V: np.ndarray
    F: np.ndarray
    origin: np.ndarray
    paths: list = field(default_factory=list)  #: cut paths in input vertex ids
    lengths: list = field(default_factory=list)
    parts: list = field(default_factory=list)  #: one description per cut

    @property
    def Vc(self) -> np.ndarray:
        return self.V[self.origin]

    def cut_along(self, path: np.ndarray, t: MeshTopology, text: str) -> None:
        """Open the current mesh along ``path`` (its vertex ids); record it in input ids."""
        Fn, vo = split_along_edges(self.F, np.stack([path[:-1], path[1:]], 1), t)
        p_in = self.origin[path]  # the first copies keep their ids, so path means the same before and after
        self.paths.append(p_in)
        self.lengths.append(_path_length(self.V, p_in))
        self.parts.append(text.format(self.lengths[-1], int(p_in[0]), int(p_in[-1])))
        self.F, self.origin = Fn, self.origin[vo]

    def open_closed_surface(self) -> None:
        """A closed genus-0 surface: one cut between two far-apart vertices (a double Dijkstra sweep)."""
        Vc = self.Vc
        t = MeshTopology(Vc, self.F)
        G = _edge_graph(Vc, t, np.ones(len(t.edges), dtype=bool))
        d0 = dijkstra(G, indices=int(self.F[0, 0]))
        a = int(np.argmax(np.where(np.isfinite(d0), d0, -1)))
        da, pred = dijkstra(G, indices=a, return_predecessors=True)
        b = int(np.argmax(np.where(np.isfinite(da), da, -1)))
        path = _path_from(pred, b)[::-1]  # a ... b
        if len(path) < 3:  # at least two edges, or the cut would not open anything
            nb = t.one_ring_vertices(int(path[-1]))
            path = np.r_[path, nb[nb != path[0]][0]]
        self.cut_along(path, t, "the surface is closed: cut along a {:.1f} mm path between vertices {} and {}")

    def join_loops(self) -> None:
        """Join every other boundary loop to the outer (longest) one, nearest first, by shortest interior paths."""
        while True:
            Vc = self.Vc
            t = MeshTopology(Vc, self.F)
            loops = boundary_loops(self.F, t)
            if len(loops) <= 1:
                return
            outer = int(np.argmax([loop_length(Vc, lp) for lp in loops]))
            G = _edge_graph(Vc, t, ~t.boundary_edges)
            dist, pred, _ = dijkstra(G, indices=loops[outer], min_only=True, return_predecessors=True)
            others = np.concatenate([lp for i, lp in enumerate(loops) if i != outer])
            d = dist[others]
            if not np.isfinite(d).any():
                raise BolusError("could not find a path inside the patch joining its boundary loops; "
                                 "segment it into more patches")
            path = _path_from(pred, int(others[np.argmin(d)]))  # inner loop vertex ... outer loop vertex
            self.cut_along(path, t, "cut along a {:.1f} mm path joining the boundary loops at vertices {} and {}")

    def description(self, notes: list[str]) -> str:
        """The user report: the cuts made (or that none was needed), after any notes."""
        if self.parts:
            each = "; ".join(p.removeprefix("cut along ") for p in self.parts)
            desc = (self.parts[0] if len(self.parts) == 1
                    else f"cut along {len(self.parts)} paths ({float(sum(self.lengths)):.1f} mm in all): {each}")
        else:
            desc = "already a disk: no cut needed"
        return "; ".join(notes + [desc]) if notes else desc


def edge_paths(edges) -> list[list[int]]:
    """Split an undirected graph of edges [(a, b), ...] into simple vertex paths: breaks at
    vertices of degree != 2; a cycle is opened at its smallest vertex (first == last then)."""
    adj: dict[int, list[int]] = {}
    for a, b in edges:
        adj.setdefault(a, []).append(b)
        adj.setdefault(b, []).append(a)
    used: set = set()
    out = []

    def walk(start, nxt):
        path, prev, cur = [start, nxt], start, nxt
        used.add(frozenset((start, nxt)))
        while len(adj[cur]) == 2 and cur != start:
            step = adj[cur][0] if adj[cur][0] != prev else adj[cur][1]
            if frozenset((cur, step)) in used:
                break
            used.add(frozenset((cur, step)))
            path.append(step)
            prev, cur = cur, step
        return path

    for v in sorted(adj):
        if len(adj[v]) != 2:
            for w in sorted(adj[v]):
                if frozenset((v, w)) not in used:
                    out.append(walk(v, w))
    for v in sorted(adj):  # what is left: cycles
        for w in sorted(adj[v]):
            if frozenset((v, w)) not in used:
                out.append(walk(v, w))
    return out
