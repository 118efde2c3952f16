"""Darts and splits: a patch made into sheet pieces that meet a length-error target.

A patch whose pattern stretches more than ``max_el`` (EL, eq. 3-30) is refined.  The
remedy follows the sign of the angle defect 2 pi - theta (eq. 4-1) diffused at the
analysis scale (`piece_advice.diffused_defect`, seed 4.1.1; the rule of `piece_advice`,
applied point by point):

* at an angle deficit (nose tip, chin: theta < 2 pi) a DART: the shortest path along
  mesh edges (Dijkstra on edge lengths) from the piece's boundary to the vertex, through
  interior vertices only; the piece is cut along it (`cutting.split_along_edges`) and
  the cut opens into a V in the pattern;
* at an angle excess (grooves, pocket rims: theta > 2 pi) a SPLIT: boundary -> vertex w
  -> boundary, the shortest interior path from w to the boundary, then the shortest one
  from w to the same boundary loop that leaves w on the other side (`_split_paths`);
  the two sides become separate pieces.  Splits go only through vertices at least
  `SPLIT_DEPTH` of the piece's largest boundary distance deep, and the second leg's
  nearest ends are tried until each side keeps `MIN_SPLIT_SHARE` of the area and
  `MIN_PIECE_TRIANGLES` triangles (else the split is refused as too small);
* a dome that no dart helped is split through its deficit points (smaller pieces carry
  less of it).

The loop (`sheet_pieces`), early decision first (issue point 2): every piece is judged
from its angle sums, D and X the diffused deficit and excess: above EL_PER_RAD
max(D, X) > max_el it misses for sure and is refined at once; at EL_HIGH_PER_RAD
max(D, X) <= max_el it gets the full `unfold.unfold_patch` at once; in between a cheap
trial decides (conformal start, `TRIAL_ITERS` L-BFGS iterations with the flip penalty,
one short L1 refinement round, no overlap correction: 15-25 % of a full unfolding):
above `TRIAL_SLACK` max_el it is refined without the full unfolding.  A piece misses
when EL > max_el, EA > `EA_PER_EL` max_el, or any triangle is flipped or overlapping.
The worst piece (trial score max(EL / max_el, EA / (EA_PER_EL max_el))) is refined
first: its candidates (`_Run.candidates`: the `CANDIDATES` strongest local extremes of
each sign by |defect|, then the splits through deficit points) are tried in order, at
most `MAX_TRIES` of them unfolded, and the FIRST whose trial lowers the piece's score by
`MIN_GAIN` is kept (first, not best: each try costs a trial).  If none does, the piece
stays as it is and the reason is recorded.  Limits: `MAX_PIECES` pieces per patch
(``max_pieces``), `MAX_DARTS` darts per piece.  A piece with a hole is cut to a disk once
(`cutting.cut_to_disk`).  Every final piece gets one full unfolding (a piece refined after
its full unfolding missed gets another one when it is final).

Measured on the 17 hard patches (bench/hard_patches.py;
noses with nostrils, a nostril pocket, a finger tip; 122-2207 triangles) at max_el 2 %:
all 17 meet EL <= 2 % and EA <= 3 % with 0 flipped / overlapping triangles, in 1-7
pieces; one piece alone had EL 1.0-45 %.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from ..mesh.boundary import boundary_loops, cut_to_disk, split_along_edges
from ..errors import BolusError
from .initial_unfolding import conformal_unfolding
from .measures import length_area_errors
from .overlap import signed_areas
from .piece_advice import EXCESS_SHARE, diffused_defect
from .refine import refine_lengths_l1
from .relax import relax_lbfgs
from ..analysis.saliency import DEFAULT_SMOOTHING_MM
from .springs import build_springs
from ..mesh.topology import MeshTopology, check_mesh, misoriented_text, submesh
from .unfold import Unfolding, labelled_patches, unfold_patch

__all__ = ["Dart", "Split", "SheetPieces", "sheet_pieces", "iter_sheet_pieces", "MAX_PIECES", "MAX_DARTS",
           "EA_PER_EL", "MIN_MAX_EL"]

#: pieces per patch at most (splits stop there)
MAX_PIECES = 8
#: darts per piece at most (on the 17 hard patches no piece kept more than 3)
MAX_DARTS = 3
#: EA target per EL target: the benchmark's target is EL <= 2 % with EA < 3 %, the same ratio
#: for any max_el.  One-piece unfoldings have EA / EL 0.74 (60 degree cap) to 1.6 (nose
#: patches), so the EA test decides only where the areas are off more than the lengths
EA_PER_EL = 1.5
#: the smallest target (a fraction): 0.1 %; below it (but above 0) `sheet_pieces` refuses
MIN_MAX_EL = 0.001
#: the cheap trial: L-BFGS iterations from the conformal start and one L1 refinement round
#: of `REFINE_TRIAL_ITERS` iterations.  Its EL was 1.05-1.26 x the full unfolding's (cone
#: 9.1 / 7.2 %, saddle 3.3 / 2.9 %, half saddle 0.82 / 0.67 %, 60 degree cap 3.75 / 3.56 %)
#: at 15-25 % of the time
TRIAL_ITERS = 40
TRIAL_REFINE_ROUNDS = 1
REFINE_TRIAL_ITERS = 10
TRIAL_TOL = 1e-7
TRIAL_FLIP_WEIGHT = 100.0  # the flip penalty of unfold's relaxation from a flip-free start
#: a trial EL above TRIAL_SLACK x max_el misses the target for sure: the full unfolding is
#: skipped and the piece refined at once (trial / full EL on the 13 hard nose patches that are
#: not hopeless: 1.04-1.21, mean 1.15).  1.1 rather than 1.25: a full unfolding that then
#: misses is wasted (it costs 2-4 trials); on the 17 hard patches 1.1 took 13 % less time
#: than 1.25, with one more piece on two of them
TRIAL_SLACK = 1.1
#: the angle-sum test (early, before any unfolding), with D / X the diffused deficit /
#: excess in radians (where both are large they partly cancel, hence max(D, X), not D + X).
#: Measured EL / max(D, X) of the full unfolding: cone (point deficit) 0.032, 60 and 30
#: degree caps 0.011 and 0.010, 100 mm saddle 0.011, its half 0.0052; the 17 hard nose,
#: pocket and finger hard patches 0.0029-0.012 where one piece can meet 2 %, 0.035-0.069
#: where it cannot (nostril pockets, finger tip).  So EL >= EL_PER_RAD max(D, X) (refine at
#: once, no unfolding) and EL <= about EL_HIGH_PER_RAD max(D, X) (the full unfolding at once,
#: no trial); in between the trial decides
EL_PER_RAD = 0.0025
EL_HIGH_PER_RAD = 0.012
#: below this total |defect| (rad) a piece is developable: no trial, the full unfold at once
FLAT_RAD = 1e-3
#: a change is kept when it lowers the piece's score by at least this share
MIN_GAIN = 0.02
#: candidate vertices per sign (local extremes of the diffused defect)
CANDIDATES = 3
#: changes unfolded (trial) per refinement step at most
MAX_TRIES = 4
#: a split's smaller side must have at least this share of the piece's area and this many
#: triangles: a smaller sliver is more work to cut and place than the stretch it saves, and
#: its trial unfolding says little
MIN_SPLIT_SHARE = 0.08
MIN_PIECE_TRIANGLES = 24
#: splits go through vertices at least this share of the piece's largest boundary distance deep
SPLIT_DEPTH = 0.3
#: a split's second leg may not start on the first leg's side of the worst vertex within this
#: share of the first leg's length (at least SPLIT_BLOCK_EDGES mean edge lengths): `_split_paths`
SPLIT_BLOCK = 0.5
SPLIT_BLOCK_EDGES = 3.0
#: second legs tried per split point (to the nearest boundary vertices first) until both sides are big enough
SPLIT_ENDS = 16
PROGRESS_EVERY = 0.5  # seconds between progress calls in the loop


@dataclass
class Dart:
    """A dart: piece (index into `SheetPieces.unfoldings`), path (k,) int vertex indices into
    the V given along mesh edges, from a boundary vertex of the piece (its outline, the side
    of an earlier dart, or the cut that opened a hole) to the apex (apex last), defect: the
    diffused angle defect at the apex (rad, > 0: deficit)."""

    piece: int
    path: np.ndarray
    defect: float


@dataclass
class Split:
    """A split: pieces (a, b) it separates (indices at the end of the run: the pieces on
    either side of its worst point, if a piece was split again later), path (k,) int vertex
    indices into V along mesh edges from boundary to boundary (boundary as for `Dart`),
    excess: the diffused angle excess at its worst point (rad; 0 for a split through a
    deficit point)."""

    pieces: tuple
    path: np.ndarray
    excess: float


@dataclass
class SheetPieces:
    """The pieces of one patch.

    piece (m,) int: the piece of every triangle of F (0..p-1, every triangle in exactly one);
    unfoldings: p `unfold.Unfolding`s, unfoldings[j].F row i = the i-th triangle of
    np.nonzero(piece == j)[0], vert_origin = rows of the V given (dart and split vertices
    appear more than once); darts, splits: what was cut; met: every piece has EL <= max_el,
    EA <= EA_PER_EL max_el, 0 flipped, 0 overlapping triangles (always True with max_el 0:
    no target); reason: "" when met, else the pieces that miss, their EL / EA and why;
    seconds: wall time of the run.
    """

    piece: np.ndarray
    unfoldings: list
    darts: list
    splits: list
    met: bool
    reason: str
    seconds: float


# ------------------------------------------------------------------ internals
@dataclass
class _Mesh:
    """One piece with its darts cut open, as a disk: Vc (k,3), Fc (f,3) (the piece's triangles in
    order), origin (k,) row of the caller's V of every vertex, topo of (Vc, Fc)."""

    Vc: np.ndarray
    Fc: np.ndarray
    origin: np.ndarray
    topo: MeshTopology
    cut: str = ""  # how a piece with a hole was cut to a disk ("" if it was one)
    disk_edges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))  # those cuts (V ids)
    locked: np.ndarray | None = None  # (e,) bool, edges of topo inside one face group (a quad's diagonal)

    def with_groups(self, groups: np.ndarray | None) -> "_Mesh":
        """Lock the edges whose two triangles have the same group (groups (f,) per row of Fc,
        e.g. the source polygon of every triangle): no dart or split runs along them."""
        if groups is not None:
            ef = self.topo.edge_faces
            both = (ef >= 0).all(axis=1)
            self.locked = both & (groups[np.maximum(ef[:, 0], 0)] == groups[np.maximum(ef[:, 1], 0)])
        return self


@dataclass
class _Diagnosis:
    """Angle sums of a piece: Kd (k,) the diffused defect 2 pi - theta (rad, interior
    vertices of the cut piece), D / X its deficit / excess sums, kind from `piece_advice`."""

    Kd: np.ndarray
    D: float
    X: float
    kind: str


@dataclass(eq=False)  # compared by identity (list.index)
class _Piece:
    faces: np.ndarray  # (f,) sorted triangle ids into F
    mesh: _Mesh | None = None
    diag: _Diagnosis | None = None
    trial: tuple | None = None  # (EL, EA)
    full: Unfolding | None = None
    stuck: str = ""  # why no change helped ("" while refinement may still help)
    ndarts: int = 0


@dataclass
class _DartRec:
    path: np.ndarray  # V ids, boundary first, apex last
    defect: float
    face: int  # a triangle (id into F) on the dart's last edge


@dataclass
class _SplitRec:
    path: np.ndarray
    excess: float
    faces: tuple  # one triangle id into F on each side, at the worst vertex


class _Progress:
    """progress(fraction, text), never decreasing: at every dart / split tried and the end (force),
    else at most every PROGRESS_EVERY s."""

    def __init__(self, progress):
        self.progress = progress
        self.last_t = -1e9
        self.last_f = 0.0

    def __call__(self, f: float, text: str, force: bool = False) -> None:
        if self.progress is None:
            return
        now = time.perf_counter()
        if not force and now - self.last_t < PROGRESS_EVERY:
            return
        self.last_t = now
        self.last_f = max(self.last_f, min(max(float(f), 0.0), 1.0))
        self.progress(self.last_f, text)

    def sub(self, lo: float, hi: float, head: str):
        """A progress callback for one unfold_patch call mapped into [lo, hi]."""
        if self.progress is None:
            return None
        return lambda f, text: self(lo + (hi - lo) * min(max(float(f), 0.0), 1.0), f"{head}: {text}")


def _check_max_el(max_el) -> float:
    try:
        x = float(max_el)
    except (TypeError, ValueError):
        raise BolusError(f"max_el must be 0 (off) or at least {100 * MIN_MAX_EL:g} %, got {max_el!r}") from None
    if not np.isfinite(x) or x < 0 or 0 < x < MIN_MAX_EL:
        raise BolusError(f"max_el must be 0 (off) or at least {100 * MIN_MAX_EL:g} % (a fraction: 0.02 = 2 %), "
                         f"got {x:g}")
    return x


def _edge_keys(pairs: np.ndarray, n: int) -> np.ndarray:
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    return np.minimum(pairs[:, 0], pairs[:, 1]) * n + np.maximum(pairs[:, 0], pairs[:, 1])


def _is_disk(topo: MeshTopology) -> bool:
    """One edge-connected manifold piece with Euler characteristic V - E + F = 1: a disk."""
    chi = int(topo.used_vertices.sum()) - len(topo.edges) + topo.m
    return bool(chi == 1 and not (topo.vertex_fan_count > 1).any() and not topo.nonmanifold_edges.any()
                and topo.face_components()[0] == 1)


def _piece_mesh(V, F, faces, dart_edges, disk_edges=(), cut_text: str = "") -> _Mesh:
    """The piece's triangles F[faces] with every dart edge (d,2) (caller's V ids) inside it cut
    open, then, if that is no disk (a hole), cut to one (`cutting.cut_to_disk`, once per piece:
    darts and splits then see those cuts as boundary; disk_edges (c,2), cut_text: such a cut
    made before on the same triangles, cut again like a dart)."""
    F_local, verts = submesh(F, faces)
    Vc, Fc, origin, topo = V[verts], F_local, verts, MeshTopology(V[verts], F_local)
    dart_edges = np.r_[np.asarray(dart_edges, dtype=np.int64).reshape(-1, 2),
                       np.asarray(disk_edges, dtype=np.int64).reshape(-1, 2)]
    if len(dart_edges):
        n = len(V)
        loc = np.full(n, -1, dtype=np.int64)
        loc[verts] = np.arange(len(verts))
        de = loc[np.asarray(dart_edges, dtype=np.int64)]
        de = de[(de >= 0).all(axis=1)]
        if len(de):
            keys = topo.edges[:, 0] * len(verts) + topo.edges[:, 1]
            q = _edge_keys(de, len(verts))
            idx = np.minimum(np.searchsorted(keys, q), len(keys) - 1)
            hit = (keys[idx] == q) & (topo.edge_face_count[idx] == 2)
            cut = topo.edges[idx[hit]]
            if len(cut):
                Fc, vo = split_along_edges(F_local, cut, topo)
                origin = verts[vo]
                Vc = V[origin]
                topo = MeshTopology(Vc, Fc)
    if _is_disk(topo):
        return _Mesh(Vc, Fc, origin, topo, cut_text, np.asarray(disk_edges, dtype=np.int64).reshape(-1, 2))
    cut = cut_to_disk(Vc, Fc)
    disk = np.concatenate([np.stack([origin[c[:-1]], origin[c[1:]]], 1) for c in cut.cut_paths]
                          + [np.zeros((0, 2), dtype=np.int64)])  # no path: a disk but for a bow-tie vertex
    origin = origin[cut.vert_origin]
    return _Mesh(cut.V, cut.F, origin, MeshTopology(cut.V, cut.F), cut.description if cut.was_cut else "", disk)


def _diagnose(mesh: _Mesh, sigma_mm: float) -> _Diagnosis:
    """Diffused defect of the (cut) piece and its kind (`piece_advice`, module doc there)."""
    topo = mesh.topo
    K = np.where(topo.interior_vertices, 2.0 * np.pi - topo.angle_sums, 0.0)
    Kd = diffused_defect(topo, K, sigma_mm)
    D, X = float(np.maximum(Kd, 0.0).sum()), float(np.maximum(-Kd, 0.0).sum())
    kind = "flat" if D + X < FLAT_RAD else ("excess" if X >= EXCESS_SHARE * (D + X) else "deficit")
    return _Diagnosis(Kd, D, X, kind)


def _trial(mesh: _Mesh, refine: bool = True) -> tuple[float, float]:
    """(EL, EA) of the cheap trial unfolding (module doc): conformal start, a short relaxation
    with the flip penalty, one short L1 refinement round (refine: as the full unfolding will:
    refine_rounds 0 skips it); no overlap correction."""
    Vd, Fd, topo = mesh.Vc, mesh.Fc, mesh.topo  # a disk (`_piece_mesh`)
    UV = conformal_unfolding(topo)
    springs = build_springs(topo)
    flip_free = not np.any(signed_areas(UV, topo.F) <= 0)
    UV, _, _ = relax_lbfgs(UV, springs, max_iter=TRIAL_ITERS, tol=TRIAL_TOL, F=topo.F if flip_free else None,
                           A0=topo.areas, flip_weight=TRIAL_FLIP_WEIGHT if flip_free else 0.0)
    if refine and TRIAL_REFINE_ROUNDS:
        flip_free = not np.any(signed_areas(UV, topo.F) <= 0)
        UV, _ = refine_lengths_l1(UV, springs, topo.edge_face_count.astype(np.float64), rounds=TRIAL_REFINE_ROUNDS,
                                  max_iter=REFINE_TRIAL_ITERS, F=topo.F if flip_free else None, A0=topo.areas)
    return length_area_errors(Vd, Fd, UV)


def _local_extremes(topo: MeshTopology, Kd: np.ndarray, sign: float, count: int, allowed=None) -> np.ndarray:
    """Up to ``count`` interior vertices where sign * Kd is a positive local maximum, strongest
    first; with ``allowed`` (n,) bool only those (and if none of them is a local maximum, the
    strongest allowed vertex with sign * Kd > 0)."""
    s = sign * Kd
    E = topo.edges
    nb = np.full(topo.n, -np.inf)
    np.maximum.at(nb, E[:, 0], s[E[:, 1]])
    np.maximum.at(nb, E[:, 1], s[E[:, 0]])
    pos = topo.interior_vertices & (s > 0)
    if allowed is not None:
        pos &= allowed
    idx = np.nonzero(pos & (s >= nb))[0]
    if not len(idx) and allowed is not None and pos.any():
        idx = np.nonzero(pos)[0]
        idx = idx[[int(np.argmax(s[idx]))]]
    return idx[np.argsort(-s[idx], kind="stable")][:count]


def _depth(mesh: _Mesh) -> np.ndarray:
    """(k,) distance of every vertex from the piece's boundary along mesh edges (mm)."""
    topo = mesh.topo
    E, L = topo.edges, np.maximum(topo.edge_lengths, 1e-12)
    G = sp.csr_matrix((np.r_[L, L], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(topo.n, topo.n))
    b = np.nonzero(topo.boundary_vertices)[0]
    if not len(b):
        return np.full(topo.n, np.inf)
    return dijkstra(G, indices=b, min_only=True)


def _interior_graph(mesh: _Mesh, blocked=None) -> sp.csr_matrix:
    """Directed edge-length graph: no edge leaves a boundary vertex (paths stop at the
    boundary), none touches a blocked vertex and none is locked (inside a source polygon)."""
    topo = mesh.topo
    E, L = topo.edges, np.maximum(topo.edge_lengths, 1e-12)
    rows, cols, w = np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]], np.r_[L, L]
    keep = ~topo.boundary_vertices[rows]
    if mesh.locked is not None:
        keep &= ~np.r_[mesh.locked, mesh.locked]
    if blocked is not None:
        keep &= ~blocked[rows] & ~blocked[cols]
    return sp.csr_matrix((w[keep], (rows[keep], cols[keep])), shape=(topo.n, topo.n))


def _path_to(pred: np.ndarray, t: int) -> np.ndarray:
    """[t, ..., source] from a Dijkstra predecessor array."""
    path = [int(t)]
    while pred[path[-1]] >= 0:
        path.append(int(pred[path[-1]]))
    return np.asarray(path, dtype=np.int64)


def _dart_path(mesh: _Mesh, apex: int) -> np.ndarray | None:
    """Shortest interior path (local ids) boundary vertex -> apex, or None."""
    bnd = mesh.topo.boundary_vertices
    dist, pred = dijkstra(_interior_graph(mesh), indices=apex, return_predecessors=True)
    d = np.where(bnd & np.isfinite(dist), dist, np.inf)
    if not np.isfinite(d).any():
        return None
    return _path_to(pred, int(np.argmin(d)))  # boundary ... apex


def _tangent(topo: MeshTopology, Vc: np.ndarray, w: int, P: np.ndarray) -> np.ndarray:
    """Unit directions (k,3) from w towards the points P (k,3) in w's tangent plane (zero where undefined)."""
    nrm = topo.vertex_normals[w]
    u = P - Vc[w]
    u = u - np.outer(u @ nrm, nrm)
    return u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)


def _split_paths(mesh: _Mesh, w: int):
    """Boundary -> w -> boundary paths (local ids), the legs leaving on opposite sides, shortest first.

    Leg 1: the shortest interior path from w to the boundary.  Leg 2: the shortest from w
    to the same boundary loop with leg 1's vertices blocked and also every vertex within
    `SPLIT_BLOCK` x leg 1's length (at least `SPLIT_BLOCK_EDGES` mean edges) of w that
    lies on leg 1's side of w (tangent plane, direction to leg 1's vertex at that
    distance): the second leg leaves in the opposite half-plane (on a finger tip both legs
    run down the finger, on a saddle they leave the centre in opposite directions).  Yields
    up to `SPLIT_ENDS` such paths, by the second leg's length (none if w reaches no boundary)."""
    topo, Vc = mesh.topo, mesh.Vc
    bnd = topo.boundary_vertices
    dist, pred = dijkstra(_interior_graph(mesh), indices=w, return_predecessors=True)
    d = np.where(bnd & np.isfinite(dist), dist, np.inf)
    if not np.isfinite(d).any():
        return
    leg1 = _path_to(pred, int(np.argmin(d)))  # b1 ... w
    b1 = int(leg1[0])
    loop = next(lp for lp in boundary_loops(mesh.Fc, topo) if b1 in set(lp.tolist()))
    r = max(SPLIT_BLOCK * float(dist[b1]), SPLIT_BLOCK_EDGES * float(topo.edge_lengths.mean()))
    along = leg1[dist[leg1] <= r]
    t1 = _tangent(topo, Vc, w, Vc[along[0]][None])[0]  # leg 1's vertex farthest from w within r
    near = np.nonzero(dist <= r)[0]
    blocked = np.zeros(topo.n, dtype=bool)
    blocked[near[_tangent(topo, Vc, w, Vc[near]) @ t1 > 0.0]] = True
    blocked[leg1[:-1]] = True
    blocked[w] = False
    dist2, pred2 = dijkstra(_interior_graph(mesh, blocked), indices=w, return_predecessors=True)
    cand = np.unique(loop)
    cand = cand[np.isfinite(dist2[cand]) & ~blocked[cand]]
    for b2 in cand[np.argsort(dist2[cand], kind="stable")][:SPLIT_ENDS]:
        leg2 = _path_to(pred2, int(b2))[::-1]  # w ... b2
        yield np.r_[leg1, leg2[1:]]


def _split_faces(mesh: _Mesh, path: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(side (f,) bool of the cut piece's triangles, edge ids of the path) if the path
    separates the piece into exactly two parts, else None."""
    topo = mesh.topo
    n = topo.n
    keys = topo.edges[:, 0] * n + topo.edges[:, 1]
    q = _edge_keys(np.stack([path[:-1], path[1:]], 1), n)
    eid = np.searchsorted(keys, q)
    P, e = topo.face_adjacency_pairs, topo.face_adjacency_edges
    keep = ~np.isin(e, eid)
    G = sp.coo_matrix((np.ones(int(keep.sum())), (P[keep, 0], P[keep, 1])), shape=(topo.m, topo.m))
    ncomp, comp = connected_components(G, directed=False)
    if ncomp != 2:
        return None
    return comp == comp[0], eid


def _split(mesh: _Mesh, w: int):
    """The first of `_split_paths` through w that separates the piece into two parts of at
    least `MIN_SPLIT_SHARE` of its area and `MIN_PIECE_TRIANGLES` triangles each:
    (path, side (f,) bool, edge ids), or "small" if only too small parts came out, or None."""
    A = mesh.topo.areas
    small = False
    for path in _split_paths(mesh, w):
        res = _split_faces(mesh, path)
        if res is None:
            continue
        side, eid = res
        if min(A[side].sum(), A[~side].sum()) < MIN_SPLIT_SHARE * A.sum() or \
                min(side.sum(), (~side).sum()) < MIN_PIECE_TRIANGLES:
            small = True
            continue
        return path, side, eid
    return "small" if small else None


def _score(EL: float, EA: float, max_el: float) -> float:
    return max(EL / max_el, EA / (EA_PER_EL * max_el))


def _meets(u: Unfolding, max_el: float) -> bool:
    return bool(_score(u.EL, u.EA, max_el) <= 1.0 and u.flipped == 0 and u.overlaps == 0)


class _Run:
    """State of one `sheet_pieces` call."""

    def __init__(self, V, F, max_el, max_pieces, sigma_mm, method, refine_rounds, progress, groups=None):
        self.V, self.F = V, F
        self.groups = groups  # (m,) the source polygon of every triangle, or None
        self.max_el, self.max_pieces, self.sigma = max_el, max_pieces, sigma_mm
        self.method, self.refine_rounds = method, refine_rounds
        self.pr = _Progress(progress)
        self.pieces: list[_Piece] = [_Piece(np.arange(len(F), dtype=np.int64))]
        self.darts: list[_DartRec] = []
        self.splits: list[_SplitRec] = []
        self.changes = 0

    # ---------------------------------------------------------- bookkeeping
    @property
    def dart_edges(self) -> np.ndarray:
        if not self.darts:
            return np.zeros((0, 2), dtype=np.int64)
        return np.concatenate([np.stack([d.path[:-1], d.path[1:]], 1) for d in self.darts])

    def fraction(self) -> float:
        """Refinement progress estimate: changes made of the most there can be, up to 0.8."""
        budget = max(self.max_pieces - 1 + MAX_DARTS, 1)
        return 0.8 * min(self.changes / budget, 1.0)

    def prepare(self, p: _Piece, dart_edges=None, like: _Piece | None = None) -> _Piece:
        """Mesh (darts cut open) and diagnosis of a piece; like: a piece with the same triangles
        whose cut to a disk is reused."""
        if p.mesh is None:
            disk = () if like is None else like.mesh.disk_edges
            p.mesh = _piece_mesh(self.V, self.F, p.faces, self.dart_edges if dart_edges is None else dart_edges,
                                 disk, "" if like is None else like.mesh.cut)
            p.mesh.with_groups(None if self.groups is None else self.groups[p.faces])
        if p.diag is None:
            p.diag = _diagnose(p.mesh, self.sigma)
        return p

    def with_trial(self, p: _Piece) -> _Piece:
        """The cheap trial of a piece (none for a developable one: (0, 0))."""
        if p.trial is None:
            p.trial = (0.0, 0.0) if p.diag.kind == "flat" else _trial(p.mesh, self.refine_rounds > 0)
        return p

    def trial_score(self, p: _Piece) -> float:
        return _score(*p.trial, self.max_el)

    def needs_full(self, p: _Piece) -> bool:
        """Early decision (module doc): whether the full unfolding is worth running on p now.

        From the angle sums alone: EL above EL_PER_RAD max(D, X) > max_el for sure: no; EL
        at most about EL_HIGH_PER_RAD max(D, X) <= max_el: yes, no trial.  In between the
        trial decides: EL above TRIAL_SLACK max_el misses for sure (EL only: a short trial's EA
        still counts flipped triangles that the full unfolding's flip correction removes)."""
        m = max(p.diag.D, p.diag.X)
        if EL_PER_RAD * m > self.max_el:
            return False
        if p.trial is None and EL_HIGH_PER_RAD * m <= self.max_el:
            return True
        return self.with_trial(p).trial[0] <= TRIAL_SLACK * self.max_el

    def unfold(self, p: _Piece, head: str, lo: float, hi: float) -> Unfolding:
        """The one full unfolding of a piece (vert_origin into V); its progress mapped into [lo, hi].

        Also a piece the refinement gave up on (stuck) gets the whole pipeline with its overlap
        correction, the best chance of an overlap-free pattern where it misses
        max_el; the early decision before refining is what saves the time.  (A 43k-triangle face
        in one patch still ends with one stuck piece of 754 overlapping triangles, warned.)"""
        if p.full is None:
            u = unfold_patch(p.mesh.Vc, p.mesh.Fc, method=self.method, refine_rounds=self.refine_rounds,
                             progress=self.pr.sub(lo, hi, head))
            u.vert_origin = p.mesh.origin[u.vert_origin]
            u.cut = u.cut or p.mesh.cut
            p.full = u
        return p.full

    def ok(self, p: _Piece) -> bool:
        return p.full is not None and _meets(p.full, self.max_el)

    # ------------------------------------------------------------ the loop
    def run(self) -> None:
        while True:
            todo = []
            for k, p in enumerate(self.pieces):
                self.pr(self.fraction(), f"checking piece {k + 1} of {len(self.pieces)}")
                self.prepare(p)
                if p.full is None and not p.stuck and self.needs_full(p):
                    f = self.fraction()
                    self.unfold(p, f"unfolding piece {k + 1} of {len(self.pieces)}", f, f)
                if not self.ok(p) and not p.stuck:
                    todo.append(p)
            if not todo:
                return
            p = max(todo, key=lambda q: self.trial_score(self.with_trial(q)))
            self.refine(p)

    def candidates(self, p: _Piece) -> list[tuple[str, int]]:
        """(remedy, vertex) to try on p, in order: the `CANDIDATES` strongest local maxima of the
        diffused deficit (a dart each) and minima (a split each) by |defect|, strongest first
        (the sign rule of `piece_advice`, applied point by point); then splits through the
        deficit points (a dome no dart helped: smaller pieces carry less of it).  Splits go
        only through vertices at least `SPLIT_DEPTH` of the piece's largest distance from
        its boundary (nearer ones cut a sliver off)."""
        topo, Kd = p.mesh.topo, p.diag.Kd
        depth = _depth(p.mesh)
        deep = depth >= SPLIT_DEPTH * float(np.max(depth[np.isfinite(depth)], initial=0.0))
        darts = [("dart", int(v)) for v in _local_extremes(topo, Kd, 1.0, CANDIDATES)]
        splits = [("split", int(v)) for v in _local_extremes(topo, Kd, -1.0, CANDIDATES, deep)]
        first = sorted(darts + splits, key=lambda c: -abs(Kd[c[1]]))
        return first + [("split", int(v)) for v in _local_extremes(topo, Kd, 1.0, CANDIDATES, deep)]

    def refine(self, p: _Piece) -> None:
        """One dart or split on piece p (module doc): candidates in order, at most `MAX_TRIES`
        of them unfolded; the first that lowers the score by `MIN_GAIN` is kept, else p is
        marked stuck with the reason."""
        k = next(i for i, q in enumerate(self.pieces) if q is p)
        s0 = self.trial_score(self.with_trial(p))
        why, tried, small = [], 0, False
        cands = self.candidates(p)
        if not cands:
            why.append("its angle sums give no point to put a dart or a split at")
        for remedy, v in cands:
            if tried >= MAX_TRIES:
                break
            if remedy == "dart" and p.ndarts >= MAX_DARTS:
                why.append(f"it has the most darts a piece may have ({MAX_DARTS})")
                continue
            if remedy == "split" and len(self.pieces) >= self.max_pieces:
                why.append(f"the patch has the most pieces allowed ({self.max_pieces})")
                continue
            out = self.try_dart(p, k, v, s0) if remedy == "dart" else self.try_split(p, k, v, s0)
            if out == "kept":
                return
            tried += out == "worse"
            small |= out == "small"
        if small:
            why.append(f"a split through its worst points would leave a piece under {100 * MIN_SPLIT_SHARE:g} % of "
                       f"its area or {MIN_PIECE_TRIANGLES} triangles")
        if tried:
            why.append(f"none of the {tried} dart(s) / split(s) tried at its worst points lowered its error")
        p.stuck = "; ".join(dict.fromkeys(why)) or "no dart or split could be placed"

    def try_dart(self, p: _Piece, k: int, apex: int, s0: float) -> str:
        """A dart boundary -> apex on p: "kept", "worse" (unfolded, not better) or "none" (no path)."""
        mesh, Kd = p.mesh, p.diag.Kd
        self.pr(self.fraction(), f"dart {p.ndarts + 1} on piece {k + 1}", force=True)
        path = _dart_path(mesh, apex)
        if path is None or len(path) < 2:
            return "none"
        gpath = mesh.origin[path]
        q = _Piece(p.faces, ndarts=p.ndarts + 1)
        try:
            self.with_trial(self.prepare(q, np.r_[self.dart_edges, np.stack([gpath[:-1], gpath[1:]], 1)], like=p))
        except BolusError:
            return "none"
        if self.trial_score(q) >= (1.0 - MIN_GAIN) * s0:
            return "worse"
        f = int(p.faces[mesh.topo.edge_faces[self._edge_id(mesh, path[-2], path[-1]), 0]])
        self.darts.append(_DartRec(gpath, float(Kd[apex]), f))
        self.pieces[k] = q
        self.changes += 1
        return "kept"

    @staticmethod
    def _edge_id(mesh: _Mesh, a: int, b: int) -> int:
        n = mesh.topo.n
        keys = mesh.topo.edges[:, 0] * n + mesh.topo.edges[:, 1]
        return int(np.searchsorted(keys, min(a, b) * n + max(a, b)))

    def try_split(self, p: _Piece, k: int, w: int, s0: float) -> str:
        """A split through w: "kept", "worse", "small" (a side under the minimum) or "none"."""
        mesh, Kd = p.mesh, p.diag.Kd
        self.pr(self.fraction(), f"split {len(self.splits) + 1} (piece {k + 1})", force=True)
        res = _split(mesh, w)
        if res is None or isinstance(res, str):
            return res or "none"
        path, side, eid = res
        qa, qb = _Piece(p.faces[side]), _Piece(p.faces[~side])
        try:  # the larger side first: if it is not better, the other one need not be unfolded
            for q in sorted((qa, qb), key=lambda q: -len(q.faces)):
                if self.trial_score(self.with_trial(self.prepare(q))) >= (1.0 - MIN_GAIN) * s0:
                    return "worse"
        except BolusError:
            return "none"
        ef = mesh.topo.edge_faces[eid[int(np.nonzero(path == w)[0][0]) - 1]]
        self.splits.append(_SplitRec(mesh.origin[path], float(max(-Kd[w], 0.0)),
                                     (int(p.faces[ef[0]]), int(p.faces[ef[1]]))))
        for q in (qa, qb):
            q.ndarts = self._darts_in(q)
        self.pieces[k:k + 1] = [qa, qb]
        self.changes += 1
        return "kept"

    def _darts_in(self, q: _Piece) -> int:
        fs = set(q.faces.tolist())
        return sum(d.face in fs for d in self.darts)

    # ---------------------------------------------------------- the result
    def result(self, t0: float) -> SheetPieces:
        order = sorted(range(len(self.pieces)), key=lambda j: int(self.pieces[j].faces[0]))
        pieces = [self.pieces[j] for j in order]
        label = np.empty(len(self.F), dtype=np.int64)
        for j, p in enumerate(pieces):
            label[p.faces] = j
        unf = []
        for j, p in enumerate(pieces):
            lo, hi = max(self.pr.last_f, 0.8 + 0.2 * j / len(pieces)), 0.8 + 0.2 * (j + 1) / len(pieces)
            self.pr(lo, f"unfolding piece {j + 1} of {len(pieces)}", force=True)
            unf.append(self.unfold(p, f"unfolding piece {j + 1} of {len(pieces)}", lo, hi))
        darts = [Dart(int(label[d.face]), d.path, d.defect) for d in self.darts]
        splits = [Split((int(label[s.faces[0]]), int(label[s.faces[1]])), s.path, s.excess) for s in self.splits]
        bad = [j for j, u in enumerate(unf) if not _meets(u, self.max_el)]
        reason = "; ".join(self._reason(j, pieces[j], unf[j]) for j in bad)
        self.pr(1.0, "done", force=True)
        return SheetPieces(label, unf, darts, splits, not bad, reason, time.perf_counter() - t0)

    def _reason(self, j: int, p: _Piece, u: Unfolding) -> str:
        what = [f"EL {100 * u.EL:.1f} %", f"EA {100 * u.EA:.1f} %"]
        if u.flipped:
            what.append(f"{u.flipped} flipped triangles")
        if u.overlaps:
            what.append(f"{u.overlaps} overlapping triangles")
        why = p.stuck or "no further dart or split was tried"
        return (f"piece {j + 1} has {', '.join(what)} (target EL {100 * self.max_el:g} %, EA "
                f"{100 * EA_PER_EL * self.max_el:g} %): {why}")


def _check_winding(F: np.ndarray) -> None:
    """BolusError unless every interior edge is walked once in each direction (as `unfold_patch` asks)."""
    he = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    n = int(F.max()) + 1
    if len(np.unique(he[:, 0] * n + he[:, 1])) < len(he):
        raise BolusError(f"the patch's faces are not consistently oriented ({misoriented_text(F)}): "
                         "recalculate the normals first (Mesh > Normals > Recalculate Outside)")


# ------------------------------------------------------------------ public
def sheet_pieces(V, F, max_el: float = 0.02, *, max_pieces: int = MAX_PIECES, sigma_mm: float = DEFAULT_SMOOTHING_MM,
                 method: str = "lbfgs", refine_rounds: int = 3, progress=None, face_groups=None) -> SheetPieces:
    """Unfold one patch into sheet pieces with darts and splits until every piece meets ``max_el``.

    Parameters
    ----------
    V : (n,3) float mm; F : (m,3) int, one consistently oriented patch.
    max_el : the EL target as a fraction (0.02 = 2 %; EA target `EA_PER_EL` x max_el);
        0 = refinement off: one piece, exactly ``unfold_patch(V, F, method, refine_rounds)``.
    max_pieces : pieces at most (splits stop there; darts: `MAX_DARTS` per piece).
    sigma_mm : scale of the diffused angle defect (`piece_advice`) choosing dart or split.
    method, refine_rounds : passed to `unfold.unfold_patch` for each final piece.
    progress : progress(fraction in [0, 1], text) about every 0.5 s ("dart 2 on piece 1", ...).
    face_groups : (m,) int, optional - the source polygon of every triangle (the Blender layer
        triangulates quads and n-gons): no dart or split runs along an edge inside one group
        (a quad's diagonal), so every polygon stays whole in one piece.

    Returns
    -------
    `SheetPieces` (module doc for the loop): when a piece misses the target within the
    limits, met is False and reason names it with its EL / EA and why.

    Raises `BolusError` for max_el < 0, not finite or in (0, 0.001), max_pieces < 1, sigma
    < 0, and for the mesh problems `unfold_patch` refuses (NaN/inf, bad indices,
    zero-area triangles, non-manifold edges, several parts, handles; named).  Needle
    triangles (tiny angles, positive area) are unfolded like any other.
    """
    t0 = time.perf_counter()
    max_el = _check_max_el(max_el)
    if not (isinstance(max_pieces, (int, np.integer)) and max_pieces >= 1):
        raise BolusError(f"max_pieces must be a whole number of at least 1, got {max_pieces!r}")
    try:
        sigma_ok = bool(np.isfinite(float(sigma_mm)) and float(sigma_mm) >= 0)
    except (TypeError, ValueError):
        sigma_ok = False
    if not sigma_ok:
        raise BolusError(f"sigma_mm must be a number >= 0, got {sigma_mm!r}")
    V, F = check_mesh(V, F, "the patch", nondegenerate=False, min_faces=0)
    if max_el == 0:
        u = unfold_patch(V, F, method=method, refine_rounds=refine_rounds, progress=progress)
        return SheetPieces(np.zeros(len(F), dtype=np.int64), [u], [], [], True, "", time.perf_counter() - t0)
    if len(F) < 3:
        raise BolusError(f"the patch has {len(F)} triangle(s); at least 3 are needed to unfold it: segment into "
                         "fewer patches or select a larger region")
    check_mesh(V, F, "the patch", nondegenerate=True, manifold=True)
    _check_winding(F)
    groups = _check_groups(face_groups, len(F))
    run = _Run(V, F, max_el, int(max_pieces), float(sigma_mm), method, refine_rounds, progress, groups)
    run.run()
    return run.result(t0)


def _check_groups(face_groups, m: int) -> np.ndarray | None:
    """face_groups as an (m,) int array (None stays None); BolusError for a wrong shape."""
    if face_groups is None:
        return None
    g = np.asarray(face_groups)
    if g.shape != (m,) or (g.size and not np.issubdtype(g.dtype, np.integer)):
        raise BolusError(f"face_groups must give an integer group for each of the {m} triangles, got shape {g.shape}")
    return g.astype(np.int64)


def iter_sheet_pieces(V, F, labels, max_el: float = 0.02, *, max_pieces: int = MAX_PIECES,
                      sigma_mm: float = DEFAULT_SMOOTHING_MM, method: str = "lbfgs", refine_rounds: int = 3,
                      progress=None, face_groups=None):
    """`sheet_pieces` for every patch of a labelled mesh, one after the other.

    Parameters: V (n,3) mm, F (m,3), labels (m,) patch of every triangle (-1: none); the
    rest as in `sheet_pieces`; progress(fraction, "patch k/n: <step>"), each patch weighted
    by its triangle count.
    Yields (index, count, `SheetPieces`) for every label 0..p-1 present, in order, with
    SheetPieces.piece indexing np.nonzero(labels == label)[0] and every Dart / Split path
    and Unfolding.vert_origin in the caller's vertex indices; reason names the patch.  A
    patch's `BolusError` is raised again naming the patch.
    """
    _check_max_el(max_el)
    V, F = check_mesh(V, F, "the mesh", nondegenerate=False)
    labels = np.asarray(labels, dtype=np.int64)
    groups = _check_groups(face_groups, len(F))
    for k, p, count, F_local, verts, sub in labelled_patches(F, labels, progress):
        try:
            res = sheet_pieces(V[verts], F_local, max_el, max_pieces=max_pieces, sigma_mm=sigma_mm, method=method,
                               refine_rounds=refine_rounds, progress=sub,
                               face_groups=None if groups is None else groups[labels == p])
        except BolusError as exc:
            raise BolusError(f"patch {p}: {exc}") from exc
        for u in res.unfoldings:
            u.vert_origin = verts[u.vert_origin]
        for d in res.darts:
            d.path = verts[d.path]
        for s in res.splits:
            s.path = verts[s.path]
        if res.reason:
            res.reason = f"patch {p}: {res.reason}"
        yield k, count, res
