"""Darts and splits: the results (SheetPieces with its Dart and Split records) and the bookkeeping of a run."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import BolusError
from .piece_geometry import (  # noqa: F401 (re-exported)
    FLAT_RAD,
    MIN_PIECE_TRIANGLES,
    MIN_SPLIT_SHARE,
    REFINE_TRIAL_ITERS,
    SPLIT_BLOCK,
    SPLIT_BLOCK_EDGES,
    SPLIT_ENDS,
    TRIAL_FLIP_WEIGHT,
    TRIAL_ITERS,
    TRIAL_REFINE_ROUNDS,
    TRIAL_TOL,
    _dart_path,
    _depth,
    _diagnose,
    _Diagnosis,
    _edge_keys,
    _interior_graph,
    _is_disk,
    _local_extremes,
    _Mesh,
    _path_to,
    _piece_mesh,
    _split,
    _split_faces,
    _split_paths,
    _tangent,
    _trial,
)
from .unfold import Unfolding

#: EA target per EL target: the benchmark's target is EL <= 2 % with EA < 3 %, the same ratio
#: for any max_el.  One-piece unfoldings have EA / EL 0.74 (60 degree cap) to 1.6 (nose
#: patches), so the EA test decides only where the areas are off more than the lengths
EA_PER_EL = 1.5


#: the smallest target (a fraction): 0.1 %; below it (but above 0) `sheet_pieces` refuses
MIN_MAX_EL = 0.001


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


@dataclass(eq=False)  # compared by identity (list.index)
class _Piece:
    faces: np.ndarray  # (f,) sorted triangle ids into F
    mesh: _Mesh | None = None
    diag: _Diagnosis | None = None
    trial: tuple | None = None  # (EL, EA)
    trial_uv: np.ndarray | None = None  # (k,2) the trial pattern on mesh.Vc: the full unfolding's start
    parent: "_Piece | None" = None  # the piece this one was cut from: its trial pattern starts this one's trial
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


def _score(EL: float, EA: float, max_el: float) -> float:
    return max(EL / max_el, EA / (EA_PER_EL * max_el))


def _meets(u: Unfolding, max_el: float) -> bool:
    return bool(_score(u.EL, u.EA, max_el) <= 1.0 and u.flipped == 0 and u.overlaps == 0)
