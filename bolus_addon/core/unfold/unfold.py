"""Unfolding a patch into a true-scale flat pattern (seed 3.5, 4.5; eqs. 3-22..3-31, 4-22..4-25).

The pipeline of `unfold_patch` for one disk-like patch, V (n,3) mm, F (m,3); each stage
lives in its own module:

1. start (`initial_unfolding`): the least-squares conformal map (``start="auto"``, one
   sparse solve) or the seed's coordinate transformation of 4.5.1 (``start="greedy"``),
   which reaches the same minimum where it does not fold, but folded over on 6 of 8
   scanned nose patches and costs seconds of Python on 20k-triangle patches;
2. relaxation of the mass-spring model with crossed and disturbing springs (`springs`,
   3.5, 4.5.2; total energy eqs. 3-28, 3-29, 4-25) by L-BFGS or the seed's explicit
   integrator (`relax`), with the flip penalty on from the first step (the start has no
   flipped triangle; a nostril pocket otherwise folds flat);
3. L1 length refinement (`refine`, our addition): IRLS towards EL (eq. 3-30) itself;
4. overlap correction (`overlap_correction`, 4.5.3): flipped triangles, then outline
   crossings locally around them and over the whole patch only if that fails;
5. the measures EL, EA (`measures`, eqs. 3-30, 3-31) and the flags.

Hopeless patches (EL > `HOPELESS_EL` or EA > `HOPELESS_EA` after relaxation and
refinement) skip the overlap correction and come back at once with
``Unfolding.hopeless`` and the figures (angle deficit / excess, eq. 4-1).

Early decision (``unfold_patch(target_el=...)``): after the cut, the
start and a short trial relaxation, a patch that cannot meet an EL target in one piece
comes back hopeless before the refinement and the overlap correction, so that darts
and splits (`sheet_pieces`) take over; with a target, an outline that crosses itself at
more than `TANGLED_CROSSINGS` points after the relaxation is also handed back (split it)
instead of corrected.  Rules and calibration in `unfold_patch`.

A patch that is not a topological disk is cut to one first (`cutting.cut_to_disk`).  `assemble` lays the
patches out.  The names imported from here before the split are re-exported.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .assemble import Pattern, assemble_pattern
from ..mesh.boundary import cut_to_disk
from ..errors import BolusError
from .initial_unfolding import _conformal, _greedy, conformal_unfolding, initial_unfolding
from .measures import (
    _curvature_sums,
    _ratios,
    _triangle_errors,
    curvature_sums,
    length_area_errors,
    polygon_area_error,
    polygon_errors,
)
from .overlap import boundary_self_intersections, overlapping_faces, signed_areas
from .overlap_correction import (
    FLIP_ROUNDS,
    FLIP_WEIGHT,
    OUTLINE_ITERS,
    OUTLINE_ROUNDS,
    correct_flips,
    correct_outline,
    defects,
    local_outline,
    outline_term,
    untangle,
)
from .refine import refine_lengths_l1
from .relax import STOP_EVERY, relax_explicit, relax_lbfgs
from ..analysis.saliency import lumped_mass
from .springs import (
    CONTOUR_WINDOW,
    Springs,
    _build_springs,
    area_terms,
    build_springs,
    spring_energy,
    stiffness_laplacian,
)
from ..mesh.topology import MeshTopology, check_mesh, misoriented_text, submesh

__all__ = [
    "Springs",
    "Unfolding",
    "build_springs",
    "spring_energy",
    "area_terms",
    "initial_unfolding",
    "conformal_unfolding",
    "relax_lbfgs",
    "stiffness_laplacian",
    "relax_explicit",
    "unfold_patch",
    "refine_lengths_l1",
    "iter_unfold_patches",
    "assemble_pattern",
    "Pattern",
    "length_area_errors",
    "polygon_errors",
    "polygon_area_error",
    "curvature_sums",
    "outline_term",
]

METHODS = ("lbfgs", "explicit")
STARTS = ("auto", "conformal", "greedy")
MIN_TRIANGLES = 3  # fewer triangles are no patch to unfold
RELAX_ITERS = 300  # L-BFGS iterations of the relaxation (was 2000)
RELAX_TOL = 1e-7  # its stop test: relative energy decrease over 5 iterations (was 1e-9)
EXPLICIT_ITERS = 20000  # steps of the explicit integrator unless max_iter says otherwise
RELAX_FLIP_WEIGHT = 10.0 * FLIP_WEIGHT  # flip penalty during the relaxation from a flip-free start
HOPELESS_FLIP_WEIGHT = 100.0 * FLIP_WEIGHT  # the one short flip round of a hopeless patch
HOPELESS_EL = 0.10  # a pattern this far off after relaxation cannot be rescued by the overlap correction
HOPELESS_EA = 0.20
HOPELESS_FAR = 2.0  # EL above HOPELESS_FAR * HOPELESS_EL after 50 iterations: stop relaxing, it is hopeless
HOPELESS_STALL = 0.02  # or above HOPELESS_EL and less than 2 % (relative) better over 25 iterations
TANGLED_CROSSINGS = 9  # with target_el: outline crossings after the relaxation beyond which the correction is skipped
TANGLED_OVERLAP = 0.10  # with target_el: or this share of the triangles overlapping after the relaxation
QUICK_ITERS = STOP_EVERY  # the cheap trial of the early decision: relaxation iterations before it (``target_el``)
QUICK_GAIN = 0.55  # the full pipeline's EL is at least this x the trial's EL (0.55 or more on 204 patches)
OUTLINE_BIG = 10000  # triangles: larger patches get proportionally fewer outline rounds
LOCAL_FIRST = True  # try `local_outline` before the whole-patch `correct_outline`
# progress fraction range of every stage (by their typical share of the time)
PROGRESS = {"start": (0.0, 0.1), "relax": (0.1, 0.35), "flips": (0.35, 0.45), "refine": (0.45, 0.6),
            "local": (0.6, 0.7), "outline": (0.6, 0.95), "outline refine": (None, 0.98)}


@dataclass
class Unfolding:
    """A flattened patch.

    UV (n2,2) mm positions of the unfolded vertices, F (m,3) the patch's triangles in
    the same order as given, indexing UV; vert_origin (n2,) the input vertex of each
    unfolded vertex (vertices on a cut appear twice).

    hopeless: the patch cannot lie flat in one piece within `HOPELESS_EL` / `HOPELESS_EA`,
    its outline is tangled (`TANGLED_CROSSINGS`), or with ``target_el`` it cannot meet
    that target (decided before the overlap correction, which is then skipped: see
    `unfold_patch`);
    angle_deficit / angle_excess: sum over interior vertices of max(0, 2 pi - theta) and
    max(0, theta - 2 pi) in radians (theta the angle sum, eq. 4-1: deficit = cap-like,
    excess = saddle-like material that would overlap); hopeless_reason: the figures
    that decided it.  trial_EL: EL of the relaxation after `QUICK_ITERS` iterations (or
    at its end if it stopped sooner), the cheap trial of ``unfold_patch(target_el=...)``
    (NaN without relaxation).
    """

    UV: np.ndarray
    F: np.ndarray
    vert_origin: np.ndarray
    EL: float
    EA: float
    flipped: int
    overlaps: int
    iterations: int
    energy: float
    seconds: float
    method: str
    cut: str = ""
    warnings: list[str] = field(default_factory=list)
    hopeless: bool = False
    angle_deficit: float = 0.0
    angle_excess: float = 0.0
    hopeless_reason: str = ""
    trial_EL: float = float("nan")


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


def _check_patch(V, F, method: str, start: str) -> tuple[np.ndarray, np.ndarray, MeshTopology]:
    """The input checks of `unfold_patch` (messages in the caller's indices); returns (V, F, topology)."""
    V, F = check_mesh(V, F, "the patch", nondegenerate=False, min_faces=0)
    if len(F) < MIN_TRIANGLES:
        raise BolusError(f"a patch of {len(F)} triangles is too small to unfold (at least {MIN_TRIANGLES} "
                         "are needed)")
    if method not in METHODS:
        raise BolusError(f"unknown unfolding method {method!r}; use one of {', '.join(METHODS)}")
    if start not in STARTS:
        raise BolusError(f"unknown start {start!r}; use auto, greedy or conformal")
    topo = MeshTopology(V, F)
    if float(topo.areas.sum()) <= 0 or topo.degenerate_faces().all():
        raise BolusError("the patch has no area to unfold")
    topo.require_valid("the patch", manifold=True)  # zero-area triangles, non-manifold edges: named
    # consistent winding: every interior edge is walked once in each direction
    he = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    if len(np.unique(he[:, 0] * topo.n + he[:, 1])) < len(he):
        raise BolusError(
            f"the patch's faces are not consistently oriented ({misoriented_text(F)}): "
            "recalculate the normals first (Mesh > Normals > Recalculate Outside)"
        )
    return V, F, topo


def _ccw(UV, F) -> np.ndarray:
    """Mirror UV (n,2) in place if its total signed area is negative (counter-clockwise like the 3D corners)."""
    if np.sum(signed_areas(UV, F)) < 0:
        UV[:, 0] = -UV[:, 0]
    return UV


def _start(run: _Run, start: str) -> np.ndarray:
    """The starting UV (n,2): conformal map, or 4.5.1 with the conformal map if that folds over."""
    topo = run.topo
    if start != "greedy":
        return _ccw(_conformal(topo), topo.F)
    UV = _greedy(topo, springs=run.springs)
    if run.flipped(UV):
        # the coordinate transformation of 4.5.1 folded over (a strongly curved patch):
        # start from the least-squares conformal map, which does not fold on a disk
        UV = _conformal(topo)
        run.warnings.append("started from a conformal map: the coordinate transformation of 4.5.1 folded over")
    return _ccw(UV, topo.F)


def _relax_stage(run: _Run, UV, method: str, max_iter: int | None,
                 target_el: float | None = None) -> tuple[np.ndarray, bool, bool]:
    """Spring relaxation (3.5); returns (UV, far, early): far = stopped early as hopeless,
    early = stopped after the trial because it cannot meet ``target_el`` (`_early_miss`)."""
    topo = run.topo
    far: list[int] = []
    early: list[int] = []
    el_seen: list[float] = []

    def far_off(X, it):
        """Early hopeless test, every STOP_EVERY iterations: lengths still HOPELESS_FAR x the EL
        limit off after 50 iterations (a nostril pocket: EL 40-75 %), or above the limit and
        less than `HOPELESS_STALL` better than STOP_EVERY iterations before, will not come
        under the limit (and a long penalised relaxation starts to push triangles over)."""
        el = run.errors(X)[0]
        if not el_seen:  # the first test, at QUICK_ITERS = STOP_EVERY iterations: the trial
            run.trial_el, run.trial_it = el, it
            if _early_miss(el, target_el):
                early.append(it)
                return True
        stalled = bool(el_seen) and el > HOPELESS_EL and el > (1.0 - HOPELESS_STALL) * el_seen[-1]
        if it >= 2 * STOP_EVERY and (el > HOPELESS_FAR * HOPELESS_EL or stalled):
            far.append(it)
        el_seen.append(el)
        return bool(far)

    if method == "lbfgs":
        # from a flip-free start the flip penalty (4.5.3) is on from the first step, so the
        # relaxation does not fold the pattern (a nostril pocket folds flat otherwise, and
        # unfolding the fold afterwards took minutes of penalty rounds)
        flip_free = not run.flipped(UV)
        UV, it, _ = relax_lbfgs(UV, run.springs, max_iter=max_iter or RELAX_ITERS, tol=RELAX_TOL, progress=run.st,
                                F=topo.F if flip_free else None, A0=topo.areas,
                                flip_weight=RELAX_FLIP_WEIGHT if flip_free else 0.0, stop=far_off)
    else:
        UV, it, _ = relax_explicit(UV, run.springs, lumped_mass(topo.V, topo.F), max_iter=max_iter or EXPLICIT_ITERS,
                                   progress=run.st)
    run.it += it
    if not el_seen:  # the relaxation ended before the first test (or explicit): its end is the trial
        run.trial_el, run.trial_it = run.errors(UV)[0], it
        early = early or ([it] if _early_miss(run.trial_el, target_el) else [])
    return _ccw(UV, topo.F), bool(far), bool(early)


def _early_miss(trial_el: float, target_el: float | None) -> bool:
    """The early decision: the full pipeline cannot bring a trial EL this high under ``target_el``."""
    return target_el is not None and QUICK_GAIN * trial_el > target_el


def _early_reason(run: _Run, target_el: float, deficit: float, excess: float) -> str:
    return (f"the trial relaxation ({run.trial_it} iterations) has EL {100 * run.trial_el:.1f} %: the full unfolding "
            f"would still be above {100 * QUICK_GAIN * run.trial_el:.1f} % ({QUICK_GAIN:g} x the trial), more than the "
            f"target {100 * target_el:g} %; angle deficit {deficit:.2f} rad, angle excess {excess:.2f} rad: "
            "cut darts or split the patch (the later stages were skipped)")


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


def _tangled(crossings: int, overlap_share: float) -> str:
    """'' or what makes a relaxed pattern tangled (`TANGLED_CROSSINGS`, `TANGLED_OVERLAP`)."""
    if crossings > TANGLED_CROSSINGS:
        return f"the outline crosses itself at {crossings} points (more than {TANGLED_CROSSINGS})"
    if overlap_share > TANGLED_OVERLAP:
        return (f"{100 * overlap_share:.0f} % of its triangles overlap others (more than "
                f"{100 * TANGLED_OVERLAP:g} %)")
    return ""


def _hopeless(EL: float, EA: float, deficit: float, excess: float, tangled: str = "") -> tuple[bool, str]:
    """(hopeless, reason): no warning here, the operator warns on EL / EA with the user's threshold.
    tangled: `_tangled`'s finding after the relaxation (with a target only)."""
    if tangled and not (EL > HOPELESS_EL or EA > HOPELESS_EA):
        return True, (f"after relaxation {tangled}; EL {100 * EL:.1f} % / EA {100 * EA:.1f} %, angle deficit "
                      f"{deficit:.2f} rad, angle excess {excess:.2f} rad: the pattern folds over itself, the overlap "
                      "correction cannot lay it flat in one piece and was skipped (split the patch)")
    if not (EL > HOPELESS_EL or EA > HOPELESS_EA):
        return False, ""
    return True, (f"after relaxation EL {100 * EL:.1f} % / EA {100 * EA:.1f} % (more than {100 * HOPELESS_EL:g} % / "
                  f"{100 * HOPELESS_EA:g} %); angle deficit {deficit:.2f} rad, angle excess {excess:.2f} rad: "
                  "the patch cannot lie flat in one piece, the overlap correction was skipped")


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
    if LOCAL_FIRST and len(boundary_self_intersections(UV, topo.F)):
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


def unfold_patch(V, F, method: str = "lbfgs", refine_rounds: int = 3, max_iter: int | None = None,
                 progress=None, start: str = "auto", *, relax: bool = True, crossed_springs: bool = True,
                 disturbing_springs: bool = True, target_el: float | None = None) -> Unfolding:
    """Unfold one patch into the plane at true scale (seed 4.5; see the module docstring).

    Parameters
    ----------
    V : (n,3) float, mm; F : (m,3) int, consistently oriented triangles (at least 3).
    method : "lbfgs" (default) or "explicit" (the seed's integrator, eqs. 3-23..3-27).
    refine_rounds : rounds of `refine_lengths_l1` (0 = the spring energy's minimum as it is).
    max_iter : iteration budget of the relaxation (default `RELAX_ITERS` / `EXPLICIT_ITERS`).
    progress : progress(fraction in [0, 1], text), called at every stage ("initial
        unfolding", "relaxing springs", "length refinement", "overlap correction round
        k/n") and about every 0.5 s inside them.
    start : "auto" (= "conformal") starts from `conformal_unfolding`, "greedy" from the
        coordinate transformation of 4.5.1 (`initial_unfolding`; if that folds over, the
        conformal map is used and a warning says so).
    relax, crossed_springs, disturbing_springs : stage switches (for the ablation of
        bench/unfold_bench.py; defaults = the full method).  relax=False: no spring
        relaxation and no length refinement (``refine_rounds`` is ignored): the start as
        it is (for "greedy" with its own relaxation of the part unfolded so far, 4.5.3),
        mirrored to counter-clockwise; only if it has flipped triangles or outline
        crossings does the overlap correction (4.5.3) run on it, as in the full pipeline
        (flip rounds, local then whole-patch outline correction, `untangle`); a flip-free
        start without crossings comes back unchanged.  crossed_springs=False /
        disturbing_springs=False: the model is built without the crossed springs (3.5) /
        the disturbing contour springs (eq. 4-25) (`build_springs`), in every stage.
    target_el : None (default: the full pipeline) or an EL target as a fraction (0.02 =
        2 %): the early decision.  After the cheap stages (cut, conformal start, springs,
        `QUICK_ITERS` L-BFGS iterations of the relaxation, or the whole relaxation if it
        ends sooner) the trial's EL is measured (``Unfolding.trial_EL``); if
        `QUICK_GAIN` x trial EL > target_el the patch cannot meet the target in one piece
        and comes back at once with ``hopeless=True``, ``hopeless_reason`` naming the
        trial EL, the target and the angle deficit / excess (eq. 4-1), and the trial
        pattern with its figures (EL, EA, flips, overlaps); refinement (darts, splits)
        should take over.  Otherwise the call goes on exactly as without target_el (the
        same pattern; EL may still end above the target).  Calibration of QUICK_GAIN
        (full-pipeline EL / trial EL) on 204 patches: caps, saddle, the bench's nose,
        chest, knee and nostril patches, the hard patches, and nose regions of
        nefertiti, demosthenes (145 mm/unit), ICT and MakeHuman of 30-50 mm, native and
        subdivided, cut into 2-4 patches (21-17,000 triangles).  On the 170 the full
        pipeline does not flag hopeless (EL >= 0.1 %) the ratio is 0.55-0.95 (below 0.6
        only on coarse demosthenes pieces of 21-234 triangles; above 1 on two pieces whose
        overlap correction raised EL, 1.1 and 1.8), on the 32 it flags 0.75-1.56.  With 0.55 no patch was flagged that the full pipeline brought under
        the target, for any target from 0.1 to 10 %; at 2 % it flagged 87, all above 2 %
        in the end, and let 30 more that end above 2 % through (they get the full call).
        (0.6 flagged 5 small pieces wrongly.)  The angle sums alone do not
        decide: the full EL per radian of (diffused) deficit + excess spans 0.2-2.6 %/rad
        over the same patches (a long strip carries much total curvature at little
        stretch), so they are reported, not used.  Cost: the cut, start and 25 iterations
        (~1/4-1/2 of a full call on small patches, 1/10-1/5 on large ones; measured on the
        hard patches 0.03-0.18 s CPU up to 2.2k triangles, 0.4-0.9 s at 4.7-6.4k,
        1.1-1.5 s at 11-12k, against 0.07-0.4, 1.1-5.6 and 5-14 s for the full call).
        method="explicit" has no stop test: its whole relaxation is the trial there.
        With a target, an outline that crosses itself at more than `TANGLED_CROSSINGS`
        points after the relaxation, or a pattern with more than `TANGLED_OVERLAP` of its
        triangles overlapping others then, is handed back hopeless too (one short flip
        round, the refinement, no outline correction), for the caller to split.
        Crossings: of 10 patches with 10-47, the correction laid one flat (an ICT nose
        piece of 1607 triangles, 28 crossings, 0.7 s) and left 9 overlapping: two ICT
        nostril pieces of 10-12k triangles (133 and 442 triangles after 17-30 s; 3-7 s
        without it), four ruffled disks z = a r^2 sin(k phi) (~1000 of 1152 after
        2.4-3.3 s; 0.4 s without), three ICT / MakeHuman nose pieces of 700-3000
        triangles (4-10 after 1.3-1.7 s; 4-40 without it, at a lower EL); every bench
        patch it lays flat has 0-8.  Overlap share: at most 3.6 % on the 11 patches with
        flips or crossings after the relaxation that the correction laid flat (bench,
        hard and sweep patches); 15.5 % on a MakeHuman nose piece of 3964 triangles
        with one crossing, which it left with 760 overlapping after 11-14 s (patches
        hopeless by EL: 18-24 %).  Neither predicts failure for certain, so the default
        (no target) keeps the correction.

    Returns
    -------
    `Unfolding`: UV (n2,2) counter-clockwise; flipped triangles are corrected (4.5.3) and
    any that remain, and any overlap of the outline, are counted and reported.  Vertices
    in no triangle are left out (vert_origin names the input vertex of every UV row).

    Raises `BolusError` naming the problem and where for bad arrays, NaN/inf, fewer than
    3 triangles, zero-area triangles (coincident or collinear vertices), non-manifold
    edges, inconsistent winding, an unknown method or start, a target_el that is not a
    finite number > 0.  Needle triangles (tiny
    angles, positive area) are unfolded like any other.

    Budgets (the stages of the seed are kept, their budgets are ours): the
    relaxation stops at `RELAX_ITERS` iterations or a relative energy decrease below
    `RELAX_TOL` over 5 iterations; a relaxation whose EL is still above `HOPELESS_FAR` x
    `HOPELESS_EL` after 50 iterations is stopped (a nostril pocket) and gets one short
    flip round; after the refinement, a pattern with EL > `HOPELESS_EL` or EA >
    `HOPELESS_EA` cannot be rescued by the overlap correction (it only moves the
    outline), so that is skipped and the pattern returned with ``hopeless`` and
    ``hopeless_reason``.
    """
    t0 = time.perf_counter()
    st = _Stages(progress)
    if target_el is not None and not (isinstance(target_el, (int, float, np.number)) and np.isfinite(target_el)
                                      and target_el > 0):
        raise BolusError(f"target_el must be None or an EL fraction above 0 (0.02 = 2 %), got {target_el!r}")
    V, F, topo0 = _check_patch(V, F, method, start)
    st.stage(*PROGRESS["start"], "initial unfolding")
    deficit, excess = _curvature_sums(topo0)
    F, used = submesh(F, np.ones(len(F), dtype=bool))  # vertices in no triangle are left out
    cut = cut_to_disk(V[used], F)
    topo = MeshTopology(cut.V, cut.F)
    # (the patch is checked: _check_patch; the cut keeps its triangles)
    springs = _build_springs(topo, CONTOUR_WINDOW if disturbing_springs else 0, crossed_springs)
    run = _Run(topo, springs, st)
    UV = _start(run, start)
    st.stage(*PROGRESS["relax"], "relaxing springs")
    far = early = False
    tangled = ""
    if relax:
        UV, far, early = _relax_stage(run, UV, method, max_iter, target_el)
        if target_el is not None and not (far or early):  # the tangled rule (with a target only)
            crossings = len(boundary_self_intersections(UV, topo.F))
            # no flip and no crossing: an embedding, nothing overlaps (no need to count)
            share = overlapping_faces(UV, topo.F).mean() if crossings or run.flipped(UV) else 0.0
            tangled = _tangled(crossings, float(share))
    elif target_el is not None:  # no relaxation: the start is the trial
        run.trial_el = run.errors(UV)[0]
        early = _early_miss(run.trial_el, target_el)
    if early:
        reason = _early_reason(run, float(target_el), deficit, excess)
        return _finish(run, UV, run.flipped(UV), cut, used, method, t0, True, deficit, excess, reason)
    st.stage(*PROGRESS["flips"], "correcting flipped triangles")
    # tangled (with a target): the pattern folds over itself (many crossings or much overlap):
    # like far, one short flip round, no outline correction; the caller splits it (unfold_patch doc)
    short = far or bool(tangled)
    UV, flipped = _flip_stage(run, UV, short)
    if relax and refine_rounds > 0 and not (short and flipped):
        st.stage(*PROGRESS["refine"], "length refinement")
        UV, flipped = _refine_stage(run, UV, flipped, refine_rounds, short)
    hopeless, reason = _hopeless(*run.errors(UV), deficit, excess, tangled)
    if not hopeless:
        UV, flipped = _outline_stage(run, UV, flipped, refine_rounds if relax else 0)
    if flipped:  # last resort, no relaxation after it: smooth the few folds left away locally
        UV, flipped = untangle(UV, topo)
    return _finish(run, UV, flipped, cut, used, method, t0, hopeless, deficit, excess, reason)


def _finish(run: _Run, UV, flipped, cut, used, method, t0, hopeless, deficit, excess, reason) -> Unfolding:
    """The `Unfolding` with its measures and warnings."""
    topo = run.topo
    e, _ = spring_energy(UV.ravel(), run.springs, topo.n)
    if flipped:
        run.warnings.append(f"{flipped} triangles remain flipped after the overlap correction")
    crossings = len(boundary_self_intersections(UV, topo.F))
    overlaps = int(overlapping_faces(UV, topo.F).sum()) if crossings or flipped else 0
    if crossings or overlaps:
        run.warnings.append(f"the pattern overlaps itself ({overlaps} triangles)")
    EL, EA = run.errors(UV)
    run.st.stage(1.0, 1.0, "done")
    return Unfolding(UV, topo.F, used[cut.vert_origin], EL, EA, flipped, overlaps, run.it, float(e),
                     time.perf_counter() - t0, method, cut.description if cut.was_cut else "", run.warnings,
                     hopeless, deficit, excess, reason, run.trial_el)


def labelled_patches(F, labels, progress=None):
    """The patches of a labelled mesh one after the other, for the per-patch iterators
    (`iter_unfold_patches`, `sheet_pieces.iter_sheet_pieces`).

    F (m,3), labels (m,) patch of every triangle (-1: none); progress(fraction, text) or None.
    Yields (k, label, count, F_local, verts, sub) for every label present in increasing
    order: F_local the patch's triangles in its own vertex numbering, verts (k,) their
    vertices in F's, sub a progress callback mapping the patch's [0, 1] into its share of
    the whole (patches weighted by triangle count, text "patch k/n: <step>") or None.
    """
    labels = np.asarray(labels, dtype=np.int64)
    if labels.shape != (len(F),):
        raise BolusError(f"{labels.size} patch labels for {len(F)} triangles")
    ids = np.unique(labels[labels >= 0])
    sizes = np.array([np.count_nonzero(labels == p) for p in ids], dtype=np.float64)
    before = np.concatenate([[0.0], np.cumsum(sizes)]) / max(sizes.sum(), 1.0)
    for k, p in enumerate(ids):
        F_local, verts = submesh(F, labels == p)
        sub = None
        if progress is not None:
            lo, hi, head = before[k], before[k + 1], f"patch {k + 1}/{len(ids)}"

            def sub(f, text, lo=lo, hi=hi, head=head):
                progress(float(lo + (hi - lo) * min(max(f, 0.0), 1.0)), f"{head}: {text}")
        yield k, int(p), len(ids), F_local, verts, sub


def iter_unfold_patches(V, F, labels, method: str = "lbfgs", refine_rounds: int = 3, progress=None):
    """Unfold every patch of a labelled mesh, one after the other.

    Parameters: V (n,3) mm, F (m,3), labels (m,) patch label of every triangle (-1: none);
    method, refine_rounds as in `unfold_patch`; progress(fraction, text): the overall
    fraction in [0, 1], each patch weighted by its triangle count, text "patch k/n: <step>".
    Yields (index, count, `Unfolding`) for every label 0..p-1 present, vert_origin in the
    caller's vertex indices.  A patch's `BolusError` is raised again naming the patch.
    """
    V, F = check_mesh(V, F, "the mesh", nondegenerate=False)
    for k, p, count, F_local, verts, sub in labelled_patches(F, labels, progress):
        try:
            u = unfold_patch(V[verts], F_local, method=method, refine_rounds=refine_rounds, progress=sub)
        except BolusError as exc:
            raise BolusError(f"patch {p}: {exc}") from exc
        u.vert_origin = verts[u.vert_origin]  # back to the caller's vertex indices
        yield k, count, u
