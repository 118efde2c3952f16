"""Cutting the triangles near a border along a level set phi = 0 (seed 4.1.2, Figure 4-2).

A cut surface S is given as the zero set of phi (a function of points, or values at
the vertices, linear along the edges).  `cut_band` splits the faces of a band around
a border of patches a and b along it: every edge that changes sign gets a new vertex
where phi = 0 (by bisection, so the vertex lies on the edge: on the original surface,
exactly), every crossed triangle is split as in Figure 4-2 (b) into a triangle and a
quadrilateral, the quadrilateral into two triangles along the diagonal with the larger
smallest angle (`split_faces`), and the band faces are relabelled by their side.

Snapping: a cut point within ``snap`` (a fraction of the edge) of an edge end moves
onto that vertex (phi := 0 there), so no slivers; a triangle with an angle under
SLIVER_DEG that is still created gets its nearest cut point snapped (up to
SLIVER_SNAP of the edge) and the split is redone.  Cut points on edges shared with a
third patch, or with faces outside the segmented region, are always snapped to a
vertex, so those faces are never split.  `check_cut` refuses a result that breaks a
rule (a patch vanishes or falls apart, a jagged piece of the border remains).

`CutState` carries the mesh being cut together with the map back to the input
(``parent``, barycentric ``vsrc``/``vw``), so every attribute can be interpolated.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .borders import Border
from ..mesh.topology import MeshTopology

__all__ = ["CutState", "CutFailed", "cut_band", "split_faces", "band_faces", "check_cut", "min_angles"]

SNAP = 0.05  #: cut points closer than this fraction of the edge to an end snap onto it
SLIVER_DEG = 1.0  #: smallest angle tolerated in a new triangle when snapping can avoid it
SLIVER_SNAP = 0.25  #: a sliver's cut point snaps to its vertex if within this fraction of the edge
SNAP_ROUNDS = 12  #: rounds of snapping and re-cutting (each round only moves cut points onto vertices)
BISECTION_STEPS = 48  #: bisection steps for phi = 0 on an edge (2**-48 of the edge: float precision)
BAND_SAMPLES = 5  #: points per border edge (ends included) for the distance of a face to the border


@dataclass
class CutState:
    """A mesh being cut, with its map back to the input mesh (V0, F0)."""

    V0: np.ndarray  #: (n,3) input vertices
    F0: np.ndarray  #: (m,3) input triangles
    V: np.ndarray  #: (n',3) current vertices, the first n are V0
    F: np.ndarray  #: (m',3) current triangles
    labels: np.ndarray  #: (m',) patch of each face
    parent: np.ndarray  #: (m',) input triangle of each face
    unchanged: np.ndarray  #: (m',) bool face identical to its input triangle
    vsrc: np.ndarray  #: (n',3) input vertices of the weights
    vw: np.ndarray  #: (n',3) barycentric weights
    vparent: np.ndarray  #: (n',) input triangle of each new vertex, -1 for input vertices

    @classmethod
    def start(cls, V: np.ndarray, F: np.ndarray, labels: np.ndarray) -> CutState:
        """The uncut mesh: every face its own parent, every vertex its own source."""
        n, m = len(V), len(F)
        eye = np.zeros((n, 3))
        eye[:, 0] = 1.0
        return cls(V, F, V.copy(), F.copy(), labels, np.arange(m), np.ones(m, dtype=bool),
                   np.repeat(np.arange(n)[:, None], 3, axis=1), eye, np.full(n, -1, dtype=np.int64))


class CutFailed(Exception):
    """A cut broke a rule; the message says which (for the border's report)."""


def min_angles(P: np.ndarray) -> np.ndarray:
    """Smallest angle (deg) of triangles P (k,3,3)."""
    out = np.full(len(P), 180.0)
    for k in range(3):
        u = P[:, (k + 1) % 3] - P[:, k]
        w = P[:, (k + 2) % 3] - P[:, k]
        c = (u * w).sum(1) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1), 1e-300)
        out = np.minimum(out, np.degrees(np.arccos(np.clip(c, -1, 1))))
    return out


# ----------------------------------------------------------------- cut_band
def cut_band(st: CutState, topo: MeshTopology, band: np.ndarray, a: int, b: int, phi_fn, linear: bool,
             snap: float = SNAP):
    """Split the band faces along phi = 0 and relabel them (Figure 4-2 (b)).

    Parameters
    ----------
    st : the current mesh; topo : its MeshTopology; band : (m',) bool faces that may be
    split (faces of a and b near the border); a, b : the two patches.
    phi_fn : a function of points (k,3) -> (k,), or an array (n',) of values at the
    vertices (then phi is linear along the edges).  linear : phi_fn is linear along
    straight lines (a plane), so the crossing is interpolated instead of bisected.
    snap : fraction of the edge within which a cut point moves onto the edge's end.

    Returns
    -------
    (new_state, phi (n',) at the old vertices (0 on the cut), from_face (m'',) the old
    face each new face comes from).  Raises `CutFailed` when the cut leaves the band
    or snapping does not settle.
    """
    bf = np.nonzero(band)[0]
    phi = _phi_at_band_vertices(st, bf, phi_fn)
    linear = linear or not callable(phi_fn)
    E, hard, may_cross = _band_edges(st, topo, band, bf, a, b)
    for _ in range(SNAP_ROUNDS):
        s = np.sign(phi[E])
        crossing = s[:, 0] * s[:, 1] < 0
        if _snap_to_nearer_end(phi, E[crossing & hard]):
            continue  # an edge a face of no concern shares is never split
        if (crossing & ~may_cross).any():
            raise CutFailed("the cut leaves the band around the border")
        ce = E[crossing]
        t = _crossing_params(st.V, phi, ce, phi_fn, linear)
        near_u, near_v = t < snap, t > 1.0 - snap
        if near_u.any() or near_v.any():
            phi[ce[near_u, 0]] = 0.0
            phi[ce[near_v, 1]] = 0.0
            continue
        new_st, pieces_P, piece_face, from_face = split_faces(st, bf, phi, ce, t, a, b)
        if _snap_slivers(st.F, phi, ce, t, pieces_P, piece_face):
            continue
        return new_st, phi, from_face
    raise CutFailed("snapping did not settle")  # pragma: no cover - defensive


def _phi_at_band_vertices(st: CutState, bf: np.ndarray, phi_fn) -> np.ndarray:
    """phi (n',) at the vertices of the band faces bf, NaN elsewhere."""
    bverts = np.unique(st.F[bf])
    phi = np.full(len(st.V), np.nan)
    phi[bverts] = phi_fn(st.V[bverts]) if callable(phi_fn) else phi_fn[bverts]
    return phi


def _band_edges(st: CutState, topo: MeshTopology, band: np.ndarray, bf: np.ndarray, a: int, b: int):
    """(E (k,2), hard (k,), may_cross (k,)) for the edges of the band faces.

    hard: shared with a face outside patches a and b (a cut point there snaps to a vertex);
    may_cross: not shared with a face of a or b outside the band (the cut may cross it).
    """
    in_u = (st.labels == a) | (st.labels == b)
    bedges = np.unique(topo.face_edges[bf].ravel())
    ef = topo.edge_faces[bedges]
    may_cross = np.ones(len(bedges), dtype=bool)
    hard = np.zeros(len(bedges), dtype=bool)
    for col in range(2):
        f = ef[:, col]
        has = f >= 0
        fs = np.where(has, f, 0)
        hard |= has & ~in_u[fs]
        may_cross &= ~(has & in_u[fs] & ~band[fs])
    return topo.edges[bedges], hard, may_cross


def _snap_to_nearer_end(phi: np.ndarray, E: np.ndarray) -> bool:
    """Set phi := 0 at the end nearer to the zero of every edge in E (k,2); True if any."""
    for u, v in E:
        if abs(phi[u]) <= abs(phi[v]):
            phi[u] = 0.0
        else:
            phi[v] = 0.0
    return len(E) > 0


def _crossing_params(V: np.ndarray, phi: np.ndarray, ce: np.ndarray, phi_fn, linear: bool) -> np.ndarray:
    """Edge parameter t (k,) of phi = 0 on each crossing edge ce (k,2) (0 at ce[:, 0])."""
    fu, fv = phi[ce[:, 0]], phi[ce[:, 1]]
    if linear:
        return fu / (fu - fv)
    pu, pv = V[ce[:, 0]], V[ce[:, 1]]
    lo, hi = np.zeros(len(ce)), np.ones(len(ce))
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        same = np.sign(phi_fn(pu + mid[:, None] * (pv - pu))) == np.sign(fu)
        lo = np.where(same, mid, lo)
        hi = np.where(same, hi, mid)
    return 0.5 * (lo + hi)


def _snap_slivers(F: np.ndarray, phi: np.ndarray, ce: np.ndarray, t: np.ndarray, pieces_P: np.ndarray,
                  piece_face: np.ndarray) -> bool:
    """Snap the nearest cut point of each new sliver (angle < SLIVER_DEG) to its vertex; True if one moved."""
    bad = min_angles(pieces_P) < SLIVER_DEG
    if not bad.any():
        return False
    changed = False
    key = {(int(u), int(v)): k for k, (u, v) in enumerate(ce.tolist())}
    for f in np.unique(piece_face[bad]):
        tri = F[f]
        for k in range(3):
            u, v = int(tri[k]), int(tri[(k + 1) % 3])
            kk = key.get((min(u, v), max(u, v)))
            if kk is None:
                continue
            if t[kk] < SLIVER_SNAP and phi[ce[kk, 0]] != 0:
                phi[ce[kk, 0]] = 0.0
                changed = True
            elif t[kk] > 1.0 - SLIVER_SNAP and phi[ce[kk, 1]] != 0:
                phi[ce[kk, 1]] = 0.0
                changed = True
    return changed


# --------------------------------------------------------------- split_faces
def split_faces(st: CutState, bf: np.ndarray, phi: np.ndarray, ce: np.ndarray, t: np.ndarray, a: int, b: int):
    """Re-triangulate the band faces along the cut (Figure 4-2 (b)) and relabel them.

    Parameters
    ----------
    bf : (f,) band faces; phi : (n',) at the vertices (0 on snapped ones); ce : (k,2)
    the crossing edges (sorted pairs) and t : (k,) where phi = 0 on them.

    Returns
    -------
    (new_state, pieces (p,3,3) the corner positions of the new faces, piece_face (p,) the
    band face each came from, from_face (m'',) the old face of every face of the new state).
    """
    n = len(st.V)
    Fb = st.F[bf]
    xs, hit = _side_crossings(Fb, ce, n)
    new_v, new_w, new_parent = _crossing_vertices(st, bf, ce, t, xs, hit)
    Vall = np.vstack([st.V, new_v])
    ncross = (xs >= 0).sum(axis=1)
    one, pieces1 = _split_one_side(Fb, xs, ncross)
    two, pieces2 = _split_two_sides(Fb, xs, ncross, Vall)
    new_F, out_from = _assemble(bf, one, pieces1, two, pieces2)
    keep = np.ones(len(st.F), dtype=bool)
    keep[bf[ncross > 0]] = False
    F2 = np.vstack([st.F[keep], new_F])
    from_face = np.r_[np.nonzero(keep)[0], out_from]
    labels2 = _side_labels(st, bf, np.r_[phi, np.zeros(len(ce))], F2, from_face, a, b)
    new_st = CutState(
        st.V0, st.F0, Vall, F2, labels2,
        np.r_[st.parent[keep], st.parent[out_from]],
        np.r_[st.unchanged[keep], np.zeros(len(new_F), dtype=bool)],
        np.vstack([st.vsrc, st.F0[new_parent]]),
        np.vstack([st.vw, new_w]),
        np.r_[st.vparent, new_parent],
    )
    pieces = Vall[new_F] if len(new_F) else np.zeros((0, 3, 3))
    return new_st, pieces, out_from, from_face


def _side_crossings(Fb: np.ndarray, ce: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(xs, hit), each (f,3): the new vertex (n + j for crossing edge j) on side k (Fb[k] -> Fb[k+1]), -1 if none."""
    if not len(ce):
        return np.full(Fb.shape, -1), np.zeros(Fb.shape, dtype=bool)
    ce_key = np.minimum(ce[:, 0], ce[:, 1]) * n + np.maximum(ce[:, 0], ce[:, 1])
    order = np.argsort(ce_key)
    u, v = Fb, np.roll(Fb, -1, axis=1)
    side_key = np.minimum(u, v) * n + np.maximum(u, v)
    pos = np.clip(np.searchsorted(ce_key[order], side_key), 0, len(ce) - 1)
    hit = ce_key[order][pos] == side_key
    return np.where(hit, n + order[pos], -1), hit


def _crossing_vertices(st: CutState, bf: np.ndarray, ce: np.ndarray, t: np.ndarray, xs: np.ndarray,
                       hit: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions (k,3), barycentric weights (k,3), parent input triangle (k,)) of the new vertices.

    The weights are on the corners of the input triangle of the first band face holding the
    edge; the position is computed from them, so a new vertex lies on the input surface.
    """
    n = len(st.V)
    fi, _ = np.nonzero(hit)
    jj = xs[hit] - n
    first = np.unique(jj, return_index=True)[1]
    e_face = np.empty(len(ce), dtype=np.int64)
    e_face[jj[first]] = bf[fi[first]]
    new_parent = st.parent[e_face]
    corners = st.F0[new_parent]  # (k,3)
    new_w = np.zeros((len(ce), 3))
    for end_, wt in ((0, 1.0 - t), (1, t)):
        src, w = st.vsrc[ce[:, end_]], st.vw[ce[:, end_]]  # (k,3) each
        for c in range(3):
            new_w[:, c] += wt * np.where(src == corners[:, c : c + 1], w, 0.0).sum(axis=1)
    return np.einsum("kc,kcd->kd", new_w, st.V0[corners]), new_w, new_parent


def _split_one_side(Fb: np.ndarray, xs: np.ndarray, ncross: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Faces with one crossed side k (p, q, r; x on p-q): (rows, pieces (c,2,3)) = (p, x, r), (x, q, r)."""
    one = np.nonzero(ncross == 1)[0]
    k1 = np.argmax(xs[one] >= 0, axis=1)
    p1, q1, r1 = Fb[one, k1], Fb[one, (k1 + 1) % 3], Fb[one, (k1 + 2) % 3]
    x1 = xs[one, k1]
    return one, np.stack([np.stack([p1, x1, r1], 1), np.stack([x1, q1, r1], 1)], 1)


def _split_two_sides(Fb: np.ndarray, xs: np.ndarray, ncross: np.ndarray, Vall: np.ndarray):
    """Faces with two crossed sides around the lone vertex p: (rows, pieces (c,3,3)).

    The triangle (p, x, y) and the quadrilateral (x, q, r, y) split along the diagonal
    whose two triangles have the larger smallest angle (Figure 4-2 (b)).
    """
    two = np.nonzero(ncross == 2)[0]
    both = (xs[two] >= 0) & (np.roll(xs[two], 1, axis=1) >= 0)  # side k and side k-1
    k2 = np.argmax(both, axis=1)
    p2, q2, r2 = Fb[two, k2], Fb[two, (k2 + 1) % 3], Fb[two, (k2 + 2) % 3]
    x2, y2 = xs[two, k2], xs[two, (k2 - 1) % 3]  # x on p-q, y on r-p
    opt1 = np.stack([np.stack([x2, q2, r2], 1), np.stack([x2, r2, y2], 1)], 1)
    opt2 = np.stack([np.stack([x2, q2, y2], 1), np.stack([q2, r2, y2], 1)], 1)
    m1 = min_angles(Vall[opt1.reshape(-1, 3)]).reshape(-1, 2).min(axis=1) if len(two) else np.zeros(0)
    m2 = min_angles(Vall[opt2.reshape(-1, 3)]).reshape(-1, 2).min(axis=1) if len(two) else np.zeros(0)
    rest = np.where((m1 >= m2)[:, None, None], opt1, opt2)
    return two, np.concatenate([np.stack([p2, x2, y2], 1)[:, None, :], rest], axis=1)


def _assemble(bf, one, pieces1, two, pieces2) -> tuple[np.ndarray, np.ndarray]:
    """(new faces (p,3), band face of each (p,)), in the order of the band faces they replace."""
    count = np.zeros(len(bf), dtype=np.int64)
    count[one], count[two] = 2, 3
    start = np.r_[0, np.cumsum(count)[:-1]]
    new_F = np.empty((int(count.sum()), 3), dtype=np.int64)
    for i in range(2):
        new_F[start[one] + i] = pieces1[:, i]
    for i in range(3):
        new_F[start[two] + i] = pieces2[:, i]
    return new_F, np.repeat(bf, count)


def _side_labels(st: CutState, bf: np.ndarray, phi_all: np.ndarray, F2: np.ndarray, from_face: np.ndarray,
                 a: int, b: int) -> np.ndarray:
    """Labels (m'',) of the new faces: band faces by their side of the cut, others as before.

    The side that is patch a is the one where most of a's band area was (area-weighted
    vote of the old band faces' centroid sign).
    """
    F, V = st.F, st.V
    band2 = np.zeros(len(F), dtype=bool)
    band2[bf] = True
    side = phi_all[F2].sum(axis=1)
    Fb = F[bf]
    area0 = np.linalg.norm(np.cross(V[Fb[:, 1]] - V[Fb[:, 0]], V[Fb[:, 2]] - V[Fb[:, 0]]), axis=1)
    cent_phi = phi_all[Fb].mean(axis=1)
    sa = np.sum(area0 * np.sign(cent_phi) * np.where(st.labels[bf] == a, 1.0, -1.0))
    a_sign = 1.0 if sa >= 0 else -1.0
    labels2 = st.labels[from_face].copy()
    sided = band2[from_face] & (side != 0)
    labels2[sided] = np.where(np.sign(side[sided]) == a_sign, a, b)
    return labels2


# ------------------------------------------------------------- band, checks
def band_faces(st: CutState, topo: MeshTopology, border: Border, all_borders: list[Border], R: float) -> np.ndarray:
    """(m',) bool: faces of patches a, b whose centroid is within R of this border
    (and nearer to it than to another a|b border)."""
    samples, owner = [], []
    for i, other in enumerate(all_borders):
        if (other.a, other.b) != (border.a, border.b):
            continue
        p, q = st.V[other.edges[:, 0]], st.V[other.edges[:, 1]]
        for s in np.linspace(0.0, 1.0, BAND_SAMPLES):
            samples.append(p + s * (q - p))
            owner.append(np.full(len(p), i))
    pts, own = np.vstack(samples), np.concatenate(owner)
    me = next(i for i, o in enumerate(all_borders) if o is border)
    C = topo.centroids
    box = np.all((C >= pts.min(axis=0) - R) & (C <= pts.max(axis=0) + R), axis=1)
    faces = np.nonzero(box & ((st.labels == border.a) | (st.labels == border.b)))[0]
    dist, idx = cKDTree(pts).query(C[faces], distance_upper_bound=R * (1 + 1e-12) + 1e-300)
    near = np.isfinite(dist) & (dist <= R)
    out = np.zeros(len(st.F), dtype=bool)
    out[faces[near]] = own[idx[near]] == me
    return out


def check_cut(st: CutState, phi: np.ndarray, a: int, b: int,
              band_faces_new: np.ndarray) -> tuple[np.ndarray, MeshTopology]:
    """The new a|b cut edges (k,2) and the topology of the faces of a, b and their neighbours.

    Raises `CutFailed` if the result breaks a rule: a patch vanishes or falls apart, the
    cut does not separate the two patches, or a jagged piece of the border remains.
    Only patches a and b and the faces touching them are looked at (the vertex normals of
    their vertices are those of the whole mesh), so a cut costs the size of the pair.
    """
    ab = (st.labels == a) | (st.labels == b)
    verts = np.zeros(len(st.V), dtype=bool)
    verts[st.F[ab]] = True
    sub = np.nonzero(verts[st.F].any(axis=1))[0]
    topo = MeshTopology(st.V, st.F[sub])
    labels = st.labels[sub]
    _require_whole_patches(topo, labels, a, b)
    P = topo.face_adjacency_pairs
    la, lb = labels[P[:, 0]], labels[P[:, 1]]
    ab = ((la == a) & (lb == b)) | ((la == b) & (lb == a))
    on_cut = np.r_[phi, np.zeros(len(st.V) - len(phi))] == 0
    edges = topo.edges[topo.face_adjacency_edges[ab]]
    touches_band = band_faces_new[sub][P[ab, 0]] | band_faces_new[sub][P[ab, 1]]
    if not touches_band.any():
        raise CutFailed("the cut does not separate the two patches")
    cut = on_cut[edges[:, 0]] & on_cut[edges[:, 1]]
    if (touches_band & ~cut).any():
        raise CutFailed("a jagged piece of the border would remain")
    return edges[touches_band], topo


def _require_whole_patches(topo: MeshTopology, labels: np.ndarray, a: int, b: int) -> None:
    """CutFailed if patch a or b has no face or more than one edge-connected piece."""
    side = np.where(labels == a, 1, np.where(labels == b, 2, 0))
    comp = None
    for lab, code in ((a, 1), (b, 2)):
        mask = side == code
        if not mask.any():
            raise CutFailed(f"patch {lab} would vanish")
        if comp is None:
            _, comp = topo.face_components(side)
        if len(np.unique(comp[mask])) > 1:
            raise CutFailed(f"patch {lab} would fall apart")
