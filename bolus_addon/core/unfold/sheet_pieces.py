"""Darts and splits: a patch made into sheet pieces that meet a length-error target.

A patch (V (n,3) mm, F (m,3)) whose pattern stretches more than ``max_el`` (EL, eq. 3-30) is
refined by the sign of the angle defect 2 pi - theta (eq. 4-1) diffused at the analysis scale
(`piece_advice.diffused_defect`, seed 4.1.1), point by point:

* at a deficit (theta < 2 pi) a DART: the shortest interior edge path from the piece's boundary
  to the vertex, cut open (`boundary.split_along_edges`) into a V in the pattern;
* at an excess (theta > 2 pi) a SPLIT: boundary -> vertex -> boundary (`_split_paths`), the two
  sides separate pieces (`SPLIT_DEPTH`, `MIN_SPLIT_SHARE`, `MIN_PIECE_TRIANGLES`);
* a dome that no dart helped is split through its deficit points.

A patch of `part_split.PART_MIN_TRIANGLES` or more is first cut into spectral parts by its angle
defect (`part_split`: a whole face left in one patch), each part then refined as above (so
``max_pieces`` and `MAX_DARTS` count per part) and cut again where it still misses.

`sheet_pieces` judges every piece from its angle sums (`EL_PER_RAD`, `EL_HIGH_PER_RAD`) or a cheap
trial (`TRIAL_ITERS`, `TRIAL_SLACK`); a piece misses when EL > max_el, EA > `EA_PER_EL` max_el or
a triangle is flipped or overlapping.  The worst piece is refined first, with the first candidate
that lowers its score by `MIN_GAIN` (`CANDIDATES`, `MAX_TRIES`), up to `MAX_PIECES` pieces and
`MAX_DARTS` darts per piece; every final piece gets one full `unfold.unfold_patch`.

Design notes: docs/design/unfold.md.
"""
from __future__ import annotations

import dataclasses
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
from . import part_split
from .piece_advice import EXCESS_SHARE, diffused_defect
from .refine import refine_lengths_l1
from .relax import relax_lbfgs
from ..analysis.saliency import DEFAULT_SMOOTHING_MM
from .springs import build_springs
from ..mesh.topology import MeshTopology, check_mesh, misoriented_text, submesh
from .unfold import Unfolding, labelled_patches, unfold_patch
from .piece_geometry import (  # noqa: F401 (re-exported)
    TRIAL_ITERS,
    TRIAL_REFINE_ROUNDS,
    REFINE_TRIAL_ITERS,
    TRIAL_TOL,
    TRIAL_FLIP_WEIGHT,
    FLAT_RAD,
    MIN_SPLIT_SHARE,
    MIN_PIECE_TRIANGLES,
    SPLIT_BLOCK,
    SPLIT_BLOCK_EDGES,
    SPLIT_ENDS,
    _Mesh,
    _Diagnosis,
    _edge_keys,
    _is_disk,
    _piece_mesh,
    _diagnose,
    _trial,
    _inherit_uv,
    _local_extremes,
    _depth,
    _interior_graph,
    _path_to,
    _dart_path,
    _tangent,
    _split_paths,
    _split_faces,
    _split,
)
from .sheet_records import (  # noqa: F401 (re-exported)
    EA_PER_EL,
    MIN_MAX_EL,
    PROGRESS_EVERY,
    Dart,
    Split,
    SheetPieces,
    _Piece,
    _DartRec,
    _SplitRec,
    _Progress,
    _check_max_el,
    _score,
    _meets,
)

__all__ = ["Dart", "Split", "SheetPieces", "sheet_pieces", "iter_sheet_pieces", "MAX_PIECES", "MAX_DARTS",
           "EA_PER_EL", "MIN_MAX_EL"]

#: pieces per patch at most (splits stop there)
MAX_PIECES = 8
#: darts per piece at most (on the 17 hard patches no piece kept more than 3)
MAX_DARTS = 3
#: a trial EL above TRIAL_SLACK x max_el misses the target for sure: the full unfolding is
#: skipped and the piece refined at once (trial / full EL on the 13 hard nose patches that are
#: not hopeless: 1.04-1.21, mean 1.15, with 40-iteration trials; 1.10-1.27 with today's
#: shorter and warm-started ones, `piece_geometry.TRIAL_ITERS`).  1.1 rather than 1.25: a full unfolding that then
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
#: a change is kept when it lowers the piece's score by at least this share
MIN_GAIN = 0.02
#: candidate vertices per sign (local extremes of the diffused defect)
CANDIDATES = 3
#: changes unfolded (trial) per refinement step at most
MAX_TRIES = 4
#: splits go through vertices at least this share of the piece's largest boundary distance deep
SPLIT_DEPTH = 0.3


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
        self.seen: dict[bytes, _Piece] = {}  # split sides prepared and tried, by `_key`

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
        if p.trial is None and p.diag.kind == "flat":
            p.trial = (0.0, 0.0)
        elif p.trial is None:
            q, start = p.parent, None
            if q is not None and q.trial_uv is not None:
                start = _inherit_uv(q.mesh, q.faces, q.trial_uv, p.mesh, p.faces)
            el, ea, p.trial_uv = _trial(p.mesh, self.refine_rounds > 0, with_uv=True, start=start)
            p.trial, p.parent = (el, ea), None
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
                             progress=self.pr.sub(lo, hi, head), start_uv=p.trial_uv)
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
        q = _Piece(p.faces, ndarts=p.ndarts + 1, parent=p)
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
        qa, qb = self._side(p.faces[side], p), self._side(p.faces[~side], p)
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

    def _side(self, faces: np.ndarray, parent: _Piece) -> _Piece:
        """A new piece of these faces cut from parent, with the mesh, diagnosis and trial of an
        earlier piece of the same faces and the same darts inside if there was one (a split
        tried, found worse, then tried again after a dart elsewhere)."""
        key = self._key(faces)
        old = self.seen.get(key)
        if old is not None and old.trial is not None:
            return _Piece(faces, old.mesh, old.diag, old.trial, old.trial_uv)
        q = _Piece(faces, parent=parent)
        self.seen[key] = q
        return q

    def _key(self, faces: np.ndarray) -> bytes:
        """The faces and the dart edges with both ends among their vertices: what `_piece_mesh` cuts."""
        de = self.dart_edges
        inside = np.isin(de, self.F[faces]).all(axis=1) if len(de) else np.zeros(0, dtype=bool)
        e = np.sort(de[inside], axis=1)
        e = e[np.lexsort((e[:, 1], e[:, 0]))] if len(e) else e
        return faces.tobytes() + b"|" + e.astype(np.int64).tobytes()

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
    max_pieces : pieces at most (splits stop there; darts: `MAX_DARTS` per piece); per spectral
        part on a patch that is cut into parts first (module doc).
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

    def solve(Vp, Fp, gp, pr):
        t_part = time.perf_counter()
        run = _Run(Vp, Fp, max_el, int(max_pieces), float(sigma_mm), method, refine_rounds, pr, gp)
        run.run()
        return run.result(t_part)

    parts = part_split.part_labels(V, F, None, float(sigma_mm), face_groups=groups)
    if parts is None:
        return dataclasses.replace(solve(V, F, groups, progress), seconds=time.perf_counter() - t0)
    found = part_split.solve_in_parts(V, F, parts, solve, float(sigma_mm), groups, progress)
    return part_split.merge_parts(V, F, found, time.perf_counter() - t0)


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
