"""The correction stages of `unfold.unfold_patch` (4.5.3) and the state of one call.

`_Run` holds the cut patch (topology, springs), the progress and the counters; the stages
take and return UV (n,2) mm with the number of flipped triangles left:

* `_flip_stage`: flipped triangles (`overlap_correction.correct_flips`), one short strong
  round for a patch already known to be hopeless;
* `_refine_stage`: the L1 length refinement (`refine.refine_lengths_l1`, towards EL of
  eq. 3-30) with the flip penalty, then flips again;
* `_outline_stage`: outline crossings, locally first (`local_outline`), over the whole patch
  if that fails (`_whole_outline`: `correct_outline`, refined again with the outline kept
  apart), locally again if crossings are left.

`PROGRESS` gives every stage its range of the progress fraction.

Design notes: docs/design/unfold.md.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..mesh.topology import MeshTopology
from .measures import _ratios, _triangle_errors
from .overlap import boundary_self_intersections, signed_areas
from .overlap_correction import (
    FLIP_ROUNDS,
    FLIP_WEIGHT,
    OUTLINE_ITERS,
    OUTLINE_ROUNDS,
    correct_flips,
    correct_outline,
    defects,
    local_outline,
)
from .refine import refine_lengths_l1
from .springs import Springs

HOPELESS_FLIP_WEIGHT = 100.0 * FLIP_WEIGHT  # the one short flip round of a hopeless patch
OUTLINE_BIG = 10000  # triangles: larger patches get proportionally fewer outline rounds
LOCAL_FIRST = True  # try `local_outline` before the whole-patch `correct_outline`
# progress fraction range of every stage (by their typical share of the time)
PROGRESS = {"start": (0.0, 0.1), "relax": (0.1, 0.35), "flips": (0.35, 0.45), "refine": (0.45, 0.6),
            "local": (0.6, 0.7), "outline": (0.6, 0.95), "outline refine": (None, 0.98)}


class _Stages:
    """Progress of `unfold_patch`: stage ranges of the fraction, never decreasing, and a
    call at least every ~0.5 s inside the long loops (relax_lbfgs reports itself)."""

    def __init__(self, progress):
        self.progress = progress
        self.last = 0.0
        self.lo, self.hi, self.text = 0.0, 0.0, ""

    def stage(self, lo: float, hi: float, text: str) -> None:
        self.lo, self.hi, self.text = lo, hi, text
        self(0.0)

    def __call__(self, f: float, text: str | None = None) -> None:
        if self.progress is None:
            return
        frac = max(self.last, min(self.hi, self.lo + (self.hi - self.lo) * min(max(float(f), 0.0), 1.0)))
        self.last = frac
        self.progress(frac, text or self.text)


@dataclass
class _Run:
    """State of one `unfold_patch` call: the cut patch, its springs, progress, counters."""

    topo: MeshTopology
    springs: Springs
    st: _Stages
    it: int = 0
    trial_el: float = float("nan")
    trial_it: int = 0
    warnings: list[str] = field(default_factory=list)

    def flipped(self, UV) -> int:
        return int(np.count_nonzero(signed_areas(UV, self.topo.F) <= 0))

    def errors(self, UV) -> tuple[float, float]:
        return _ratios(*_triangle_errors(self.topo.V, self.topo.F, UV))


def _ccw(UV, F) -> np.ndarray:
    """Mirror UV (n,2) in place if its total signed area is negative (counter-clockwise like the 3D corners)."""
    if np.sum(signed_areas(UV, F)) < 0:
        UV[:, 0] = -UV[:, 0]
    return UV


def _flip_stage(run: _Run, UV, far: bool) -> tuple[np.ndarray, int]:
    """Flipped triangles corrected (4.5.3); a hopeless patch gets one short strong round."""
    if far:  # only to take out the folds
        UV, it, flipped = correct_flips(UV, run.springs, run.topo, rounds=1, max_iter=OUTLINE_ITERS, progress=run.st,
                                        weight=HOPELESS_FLIP_WEIGHT)
    else:
        UV, it, flipped = correct_flips(UV, run.springs, run.topo, progress=run.st)
    run.it += it
    return UV, flipped


def _refine_stage(run: _Run, UV, flipped: int, rounds: int, far: bool) -> tuple[np.ndarray, int]:
    """L1 length refinement (flip penalty on if nothing is flipped), then flips corrected again."""
    topo = run.topo
    UV, it = refine_lengths_l1(UV, run.springs, topo.edge_face_count.astype(np.float64), rounds=rounds,
                               F=topo.F if flipped == 0 else None, A0=topo.areas, progress=run.st)
    run.it += it
    flipped = run.flipped(UV)
    if flipped:
        UV, it, flipped = correct_flips(UV, run.springs, topo, rounds=1 if far else FLIP_ROUNDS)
        run.it += it
    return UV, flipped


def _whole_outline(run: _Run, UV, flipped: int, refine_rounds: int) -> tuple[np.ndarray, int]:
    """Whole-patch outline correction, refined again with the outline kept apart; kept if not worse."""
    topo, st = run.topo, run.st
    st.stage(*PROGRESS["outline"], "overlap correction")
    # big patches: fewer rounds (each costs ~m), at least 2 (OUTLINE_BIG triangles: all rounds)
    rounds = max(2, min(OUTLINE_ROUNDS, OUTLINE_ROUNDS * OUTLINE_BIG // topo.m))
    UV2, it, _, term = correct_outline(UV, run.springs, topo, rounds=rounds, progress=st)
    run.it += it
    if refine_rounds > 0 and term is not None:
        # the correction relaxed the plain spring energy: refine again, outline kept apart
        st.stage(st.last, PROGRESS["outline refine"][1], "length refinement (outline kept apart)")
        UV3, it = refine_lengths_l1(UV2, run.springs, topo.edge_face_count.astype(np.float64),
                                    rounds=refine_rounds, F=topo.F, A0=topo.areas, extra=term, progress=st)
        run.it += it
        if defects(UV3, topo.F) <= defects(UV2, topo.F):
            UV2 = UV3
    if defects(UV2, topo.F) <= defects(UV, topo.F):
        return UV2, run.flipped(UV2)
    return UV, flipped


def _outline_stage(run: _Run, UV, flipped: int, refine_rounds: int) -> tuple[np.ndarray, int]:
    """Outline crossings (4.5.3): locally first, the whole patch if that fails, locally again;
    the last flips left are untangled locally."""
    topo = run.topo
    if not len(boundary_self_intersections(UV, topo.F)):  # nothing crosses: nothing to correct
        return UV, flipped
    if LOCAL_FIRST:
        run.st.stage(*PROGRESS["local"], "overlap correction (local)")
        UV2, it, crossings2 = local_outline(UV, run.springs, topo)
        run.it += it
        if crossings2 == 0 and not run.flipped(UV2):
            UV, flipped = UV2, 0
    if len(boundary_self_intersections(UV, topo.F)):
        UV, flipped = _whole_outline(run, UV, flipped, refine_rounds)
    if len(boundary_self_intersections(UV, topo.F)):
        # crossings left: a local correction around them only (the rest of the pattern stays)
        UV, it, _ = local_outline(UV, run.springs, topo)
        run.it += it
        flipped = run.flipped(UV)
    return UV, flipped
