"""Unfolding a patch into a true-scale flat pattern (seed 3.5, 4.5; eqs. 3-22..3-31, 4-22..4-25).

`unfold_patch` flattens one disk-like patch, V (n,3) mm, F (m,3), into an `Unfolding` (UV (n2,2) mm,
counter-clockwise; a patch that is not a disk is cut to one first, `cut_to_disk`).  Its stages:

1. start: the least-squares conformal map or the coordinate transformation of 4.5.1 (`initial_unfolding`);
2. relaxation of the mass-spring model with crossed and disturbing springs (`springs`, 3.5, 4.5.2;
   energy eqs. 3-28, 3-29, 4-25) by L-BFGS or the explicit integrator (`relax`), flip penalty on;
3. L1 length refinement (`refine`): IRLS towards EL (eq. 3-30);
4. overlap correction (`overlap_correction`, `unfold_stages`, 4.5.3): flips, then outline crossings;
5. the measures EL, EA (`measures`, eqs. 3-30, 3-31) and the flags.

EL > `HOPELESS_EL` or EA > `HOPELESS_EA` after stage 3 skips stage 4: the patch comes back
``hopeless`` with its angle deficit / excess (eq. 4-1).  With ``target_el`` a patch that cannot
meet the target, or whose relaxed outline is tangled, comes back hopeless after stage 2, for
darts and splits (`sheet_pieces`).  `iter_unfold_patches` unfolds a labelled mesh patch by patch,
`assemble` lays the patches out; the stage modules' names are re-exported here.

Design notes: docs/design/unfold.md.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .assemble import Pattern, assemble_pattern
from ..mesh.boundary import cut_to_disk
from ..errors import BolusError
from .initial_unfolding import _conformal, _greedy, conformal_unfolding, initial_unfolding
from .measures import (  # noqa: F401 (re-exported)
    check_positions,
    _curvature_sums,
    _ratios,
    _triangle_errors,
    curvature_sums,
    length_area_errors,
    polygon_area_error,
    polygon_errors,
)
from .overlap import boundary_self_intersections, overlapping_faces, signed_areas  # noqa: F401
from .overlap_correction import (  # noqa: F401 (re-exported)
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
from .springs import (  # noqa: F401 (re-exported)
    CONTOUR_WINDOW,
    Springs,
    _build_springs,
    area_terms,
    build_springs,
    spring_energy,
    stiffness_laplacian,
)
from ..mesh.topology import MeshTopology, check_mesh, misoriented_text, submesh
from .unfold_stages import (  # noqa: F401 (re-exported)
    HOPELESS_FLIP_WEIGHT,
    LOCAL_FIRST,
    OUTLINE_BIG,
    PROGRESS,
    _ccw,
    _flip_stage,
    _outline_stage,
    _refine_stage,
    _Run,
    _Stages,
)

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
RELAX_ITERS = 300  # L-BFGS iterations of the relaxation
RELAX_TOL = 1e-7  # its stop test: relative energy decrease over 5 iterations
EXPLICIT_ITERS = 20000  # steps of the explicit integrator unless max_iter says otherwise
RELAX_FLIP_WEIGHT = 10.0 * FLIP_WEIGHT  # flip penalty during the relaxation from a flip-free start
HOPELESS_EL = 0.10  # a pattern this far off after relaxation cannot be rescued by the overlap correction
HOPELESS_EA = 0.20
HOPELESS_FAR = 2.0  # EL above HOPELESS_FAR * HOPELESS_EL after 50 iterations: stop relaxing, it is hopeless
HOPELESS_STALL = 0.02  # or above HOPELESS_EL and less than 2 % (relative) better over 25 iterations
TANGLED_CROSSINGS = 9  # with target_el: outline crossings after the relaxation beyond which the correction is skipped
TANGLED_OVERLAP = 0.10  # with target_el: or this share of the triangles overlapping after the relaxation
QUICK_ITERS = STOP_EVERY  # the cheap trial of the early decision: relaxation iterations before it (``target_el``)
QUICK_GAIN = 0.55  # the full pipeline's EL is at least this x the trial's EL (0.55 or more on 204 patches)


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


def _start(run: _Run, start: str, start_uv=None, cut=None, used=None) -> np.ndarray:
    """The starting UV (n,2): start_uv (`unfold_patch`) if it serves, else the conformal map, or
    4.5.1 with the conformal map if that folds over."""
    topo = run.topo
    if start_uv is not None and not cut.was_cut:
        UV = check_positions(start_uv, None, "start_uv", int(used.max()) + 1)[used, :2]
        if not run.flipped(UV):
            return _ccw(UV, topo.F)
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


def _check_target(target_el) -> None:
    """``target_el`` is None or a finite EL fraction above 0, else `BolusError`."""
    if target_el is not None and not (isinstance(target_el, (int, float, np.number)) and np.isfinite(target_el)
                                      and target_el > 0):
        raise BolusError(f"target_el must be None or an EL fraction above 0 (0.02 = 2 %), got {target_el!r}")


def _cut_patch(V, F, method: str, start: str, st: _Stages, crossed_springs: bool, disturbing_springs: bool):
    """The checked patch cut to a disk (`cut_to_disk`) with its mass-spring model (3.5, eq. 4-25).

    Returns (run, cut, used, deficit, excess): `_Run` on the cut patch; used (k,) the input
    vertices in a triangle (``cut.vert_origin`` indexes them); deficit / excess the angle sums
    of eq. 4-1 (rad) of the patch as given."""
    V, F, topo0 = _check_patch(V, F, method, start)
    st.stage(*PROGRESS["start"], "initial unfolding")
    deficit, excess = _curvature_sums(topo0)
    F, used = submesh(F, np.ones(len(F), dtype=bool))  # vertices in no triangle are left out
    cut = cut_to_disk(V[used], F)
    # a disk with every vertex in a triangle: the same mesh as checked, its topology reused
    same = not cut.was_cut and len(used) == len(V) and np.array_equal(cut.vert_origin, np.arange(len(V)))
    topo = topo0 if same else MeshTopology(cut.V, cut.F)
    # (the patch is checked: _check_patch; the cut keeps its triangles)
    springs = _build_springs(topo, CONTOUR_WINDOW if disturbing_springs else 0, crossed_springs)
    return _Run(topo, springs, st), cut, used, deficit, excess


def _relax_and_judge(run: _Run, UV, relax: bool, method: str, max_iter: int | None,
                     target_el: float | None) -> tuple[np.ndarray, bool, bool, str]:
    """Stage 2, the relaxation, with the early decision: (UV (n,2) mm, far, early, tangled).

    far: stopped as hopeless (`_relax_stage`); early: the trial misses ``target_el``
    (`_early_miss`; without relaxation the start is the trial); tangled: with a target,
    `_tangled`'s finding on the relaxed pattern ('' if none)."""
    far = early = False
    tangled = ""
    if relax:
        UV, far, early = _relax_stage(run, UV, method, max_iter, target_el)
        if target_el is not None and not (far or early):  # the tangled rule (with a target only)
            crossings = len(boundary_self_intersections(UV, run.topo.F))
            # no flip and no crossing: an embedding, nothing overlaps (no need to count)
            share = overlapping_faces(UV, run.topo.F).mean() if crossings or run.flipped(UV) else 0.0
            tangled = _tangled(crossings, float(share))
    elif target_el is not None:  # no relaxation: the start is the trial
        run.trial_el = run.errors(UV)[0]
        early = _early_miss(run.trial_el, target_el)
    return UV, far, early, tangled


def _correct(run: _Run, UV, far: bool, tangled: str, relax: bool, refine_rounds: int, deficit: float,
             excess: float) -> tuple[np.ndarray, int, bool, str]:
    """Stages 3-4: flips, the L1 refinement, then the outline unless hopeless (4.5.3), and the last
    folds untangled locally; returns (UV (n,2) mm, flipped, hopeless, hopeless_reason)."""
    run.st.stage(*PROGRESS["flips"], "correcting flipped triangles")
    # tangled (with a target): the pattern folds over itself (many crossings or much overlap):
    # like far, one short flip round, no outline correction; the caller splits it (unfold_patch doc)
    short = far or bool(tangled)
    UV, flipped = _flip_stage(run, UV, short)
    if relax and refine_rounds > 0 and not (short and flipped):
        run.st.stage(*PROGRESS["refine"], "length refinement")
        UV, flipped = _refine_stage(run, UV, flipped, refine_rounds, short)
    hopeless, reason = _hopeless(*run.errors(UV), deficit, excess, tangled)
    if not hopeless:
        UV, flipped = _outline_stage(run, UV, flipped, refine_rounds if relax else 0)
    if flipped:  # last resort, no relaxation after it: smooth the few folds left away locally
        UV, flipped = untangle(UV, run.topo)
    return UV, flipped, hopeless, reason


def unfold_patch(V, F, method: str = "lbfgs", refine_rounds: int = 3, max_iter: int | None = None,
                 progress=None, start: str = "auto", *, relax: bool = True, crossed_springs: bool = True,
                 disturbing_springs: bool = True, target_el: float | None = None, start_uv=None) -> Unfolding:
    """Unfold one patch into the plane at true scale (seed 4.5; the stages in the module docstring).

    Parameters
    ----------
    V : (n,3) float, mm; F : (m,3) int, consistently oriented triangles (at least 3).
    method : "lbfgs" (default) or "explicit" (the seed's integrator, eqs. 3-23..3-27).
    refine_rounds : rounds of `refine_lengths_l1` (0 = the spring energy's minimum as it is).
    max_iter : iteration budget of the relaxation (default `RELAX_ITERS` / `EXPLICIT_ITERS`).
    progress : progress(fraction in [0, 1], text), called at every stage ("initial unfolding",
        "relaxing springs", "length refinement", "overlap correction round k/n") and about
        every 0.5 s inside them.
    start : "auto" (= "conformal") starts from `conformal_unfolding`, "greedy" from the
        coordinate transformation of 4.5.1 (`initial_unfolding`; if that folds over, the
        conformal map is used and a warning says so).
    relax, crossed_springs, disturbing_springs : stage switches (for the ablation of
        bench/unfold_bench.py; defaults = the full method).  relax=False: no relaxation and no
        length refinement (``refine_rounds`` is ignored): the start as it is (for "greedy" with
        its own relaxation of the part unfolded so far, 4.5.3), mirrored to counter-clockwise;
        only if it has flipped triangles or outline crossings does the overlap correction
        (4.5.3) run on it, as in the full pipeline; a flip-free start without crossings comes
        back unchanged.  crossed_springs / disturbing_springs=False: the model is built without
        the crossed springs (3.5) / the disturbing contour springs (eq. 4-25), in every stage.
    target_el : None (default: the full pipeline) or an EL target as a fraction (0.02 = 2 %):
        the early decision.  After the cut, the start, the springs and `QUICK_ITERS` L-BFGS
        iterations of the relaxation (the whole relaxation if it ends sooner, and always for
        method="explicit", which has no stop test) the trial's EL is measured
        (``Unfolding.trial_EL``); if `QUICK_GAIN` x trial EL > target_el the patch comes back
        at once with ``hopeless=True``, ``hopeless_reason`` naming the trial EL, the target and
        the angle deficit / excess (eq. 4-1), and the trial pattern with its figures, for darts
        and splits to take over.  A relaxed outline crossing itself at more than
        `TANGLED_CROSSINGS` points, or more than `TANGLED_OVERLAP` of the triangles overlapping
        others, is handed back hopeless too (one short flip round, the refinement, no outline
        correction).  Otherwise the call goes on exactly as without target_el (EL may still end
        above the target).  Calibration and costs: docs/design/unfold.md.
    start_uv : None or (n,2) mm, a flip-free pattern of the same vertices to relax from instead
        of ``start`` (a short trial relaxation: fewer iterations); ignored if the patch had to be
        cut or it has flipped triangles.

    Returns `Unfolding`: UV (n2,2) counter-clockwise; flipped triangles are corrected (4.5.3)
    and any that remain, and any overlap of the outline, are counted and reported.  Vertices
    in no triangle are left out (vert_origin names the input vertex of every UV row).

    Raises `BolusError` naming the problem and where for bad arrays, NaN/inf, fewer than 3
    triangles, zero-area triangles (coincident or collinear vertices), non-manifold edges,
    inconsistent winding, an unknown method or start, a target_el that is not a finite
    number > 0.  Needle triangles (tiny angles, positive area) are unfolded like any other.

    Budgets: the relaxation stops at `RELAX_ITERS` iterations or a relative energy decrease
    below `RELAX_TOL` over 5 iterations, or when its EL is still above `HOPELESS_FAR` x
    `HOPELESS_EL` after 50 iterations (one short flip round follows); after the refinement a
    pattern with EL > `HOPELESS_EL` or EA > `HOPELESS_EA` skips the overlap correction (it
    only moves the outline) and comes back with ``hopeless`` and ``hopeless_reason``.
    """
    t0 = time.perf_counter()
    st = _Stages(progress)
    _check_target(target_el)
    run, cut, used, deficit, excess = _cut_patch(V, F, method, start, st, crossed_springs, disturbing_springs)
    UV = _start(run, start, start_uv, cut, used)
    st.stage(*PROGRESS["relax"], "relaxing springs")
    UV, far, early, tangled = _relax_and_judge(run, UV, relax, method, max_iter, target_el)
    if early:
        reason = _early_reason(run, float(target_el), deficit, excess)
        return _finish(run, UV, run.flipped(UV), cut, used, method, t0, True, deficit, excess, reason)
    UV, flipped, hopeless, reason = _correct(run, UV, far, tangled, relax, refine_rounds, deficit, excess)
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


def labelled_patches(F, labels, progress=None, word: str = "patch"):
    """The patches of a labelled mesh one after the other, for the per-patch iterators
    (`iter_unfold_patches`, `sheet_pieces.iter_sheet_pieces`).

    F (m,3), labels (m,) patch of every triangle (-1: none); progress(fraction, text) or None.
    Yields (k, label, count, F_local, verts, sub) for every label present in increasing
    order: F_local the patch's triangles in its own vertex numbering, verts (k,) their
    vertices in F's, sub a progress callback mapping the patch's [0, 1] into its share of
    the whole (patches weighted by triangle count, text "<word> k/n: <step>") or None.
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
            lo, hi, head = before[k], before[k + 1], f"{word} {k + 1}/{len(ids)}"

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
