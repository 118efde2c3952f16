"""Time limits: a job is refused only when it cannot fit; otherwise it runs and stops at the limit.

A step whose work can run for minutes (unfold, improve flattenability, smooth cut lines, split
into print parts, Make Bolus) estimates its time from its input's size before the long work.
The estimate of a job of pieces m_1..m_k (triangles; for Make Bolus the skin's voxel faces,
`shell_cells`), done one after another, is

    t = sum_i  T * (m_i / M) ** p        (seconds)

with (T, M, p) per step in `COSTS`, calibrated on the development machine (2 cores, see
bench/rangescan_bench.py and docs/benchmarks.md).  Easy input runs far faster than its size
says, so the job is refused (with the figures and what to do: Select Treatment Area, a Decimate
ratio or a coarser resolution, a longer limit) only when the lower bound t / `OVER_ESTIMATE` is
over the limit; otherwise it starts, and `Deadline` (the progress callback's wrapper) stops it
at the limit with `TimeLimitReached`, nothing changed.  The limit is the caller's ``limit`` (the
sidebar's *Time limit (s)*, `Scene.bolus.time_limit_s`; 0 = none), else `BUDGET_S` seconds; the
environment variable ``BOLUS_TIME_BUDGET_S`` overrides both (tests and batch runs; 0 or "off"
turns the limit off).  `OVERHEAD_S_PER_TRIANGLE` of the region is kept for reading and writing.
"""
from __future__ import annotations

import os
import time

import numpy as np

from .errors import BolusError

__all__ = ["BUDGET_S", "BUDGET_ENV", "COSTS", "OVER_ESTIMATE", "budget_s", "estimate_s", "lower_bound_s",
           "max_triangles", "decimate_ratio", "check_budget", "check_grid_budget", "grid_resolution_for_budget",
           "shell_cells", "Deadline", "TimeLimitReached"]

#: seconds an operator may take before it must have refused ("within a minute")
BUDGET_S = 60.0
BUDGET_ENV = "BOLUS_TIME_BUDGET_S"
#: step -> (T seconds, at M triangles, growth exponent p): t = T (m / M)^p per piece, fitted to
#: the core call of each step on nose-tip crops of nefertiti x4 on the 2-core development
#: machine (calibration commands: bench/rangescan_bench.py).  The machine is shared: the same
#: call took 3-4x longer at load 8 than at load 1, so T is the load-1 fit doubled (unfold,
#: improve), or measured at load 2.5 (make_shell, x1.3) or load 7-8 (smooth_cuts, print_segment):
#: unfold = `sheet_pieces` with the operator's defaults (Max EL 2 %): load 1.5: 3k 2.8 s, 6k 5.8 s,
#:   12k 28.5 s (load 8: 7.7, 20, 107 s);
#: improve = `ImproveJob` (GRADIENT, 1 mm): load 1: 3k 4.5 s, 6k 6.6 s, 12k 12.7 s (load 8: 2k 14.5 s,
#:   10k 47.6 s);
#: smooth_cuts = `cutlines.smooth_cuts` (3 patches), load 8: 50k 14.9 s, 150k 54.6 s;
#: print_segment = `print_segmentation` (3 parts), load 8: 30k 16.4 s, 120k 20.0 s;
#: make_shell: per voxel face of the skin (area / resolution^2, `shell_cells`: the narrow band's
#:   work follows the surface, not the wall's volume), `shell.make_shell` (10 mm, marching cubes),
#:   load 1 (bench/shell_bench.py regions): nose 47 cm2 1 mm (5k) 0.70 s, 0.5 mm (19k) 1.85 s; elbow
#:   sleeve 350 cm2 (35k) 2.27 s, (140k) 7.56 s; chest wall 1,243 cm2 (124k) 7.1 s, (497k) 23.0 s;
#:   Nefertiti's face 286 cm2, 17,848 triangles (29k) 2.96 s, (114k) 17.0 s: the fit at T = 7 s,
#:   raised to 9 s so that the dense curved face (the slowest per face) is within 2x of it.
COSTS = {
    "unfold": (42.0, 10_000, 1.7),
    "improve_flattenability": (22.0, 10_000, 0.75),
    "smooth_cuts": (54.6, 150_000, 1.18),
    "print_segment": (20.0, 120_000, 1.0),
    "make_shell": (9.0, 100_000, 0.8),
}
#: the most an estimate was seen over the actual time on the benchmark cases (Unfold on a smooth
#: 22,560-triangle spherical cap: about 3 min estimated, 5.8 s taken, 31x), with room: no job
#: was seen to finish in less than estimate / OVER_ESTIMATE, the lower bound a refusal needs
OVER_ESTIMATE = 40.0
#: seconds per triangle of the region an operator spends outside the step (read, check, write)
OVERHEAD_S_PER_TRIANGLE = 2.0e-5
#: the steps as the user knows them (the operators' labels)
LABELS = {"unfold": "Unfold Patches", "improve_flattenability": "Improve Flattenability",
          "smooth_cuts": "Smooth Cut Lines", "print_segment": "Split into Print Parts"}


def budget_s(limit: float | None = None) -> float | None:
    """The budget in seconds: ``BOLUS_TIME_BUDGET_S`` when set, else ``limit`` (the user's time
    limit; <= 0 = none), else `BUDGET_S`; None when turned off."""
    raw = os.environ.get(BUDGET_ENV, "").strip()
    if not raw:
        if limit is None:
            return BUDGET_S
        limit = float(limit)
        if np.isnan(limit):
            raise BolusError("the time limit is not a number of seconds")
        return limit if 0 < limit < np.inf else None
    if raw.lower() in ("off", "none", "0"):
        return None
    try:
        val = float(raw)
    except ValueError:
        raise BolusError(f"{BUDGET_ENV}={raw!r} is not a number of seconds (or 'off')") from None
    if not np.isfinite(val) or val < 0:
        raise BolusError(f"{BUDGET_ENV}={raw!r} must be a positive number of seconds (or 'off')")
    return val if val > 0 else None


def _cost(step: str):
    try:
        return COSTS[step]
    except KeyError:
        raise BolusError(f"no time estimate for the step {step!r}") from None


def estimate_s(step: str, sizes) -> float:
    """Estimated seconds of ``step`` on pieces of ``sizes`` triangles (an int or a sequence), one after another."""
    T, M, p = _cost(step)
    m = np.atleast_1d(np.asarray(sizes, dtype=np.float64))
    return float(np.sum(T * (np.maximum(m, 0.0) / M) ** p))


def max_triangles(step: str, seconds: float) -> int:
    """The largest piece (triangles) ``step`` handles within ``seconds``."""
    T, M, p = _cost(step)
    return int(M * (max(seconds, 0.0) / T) ** (1.0 / p))


def decimate_ratio(step: str, sizes, seconds: float) -> float:
    """The Decimate ratio (0..1, two digits, rounded down) that brings the estimate within ``seconds``."""
    est = estimate_s(step, sizes)
    if est <= seconds:
        return 1.0
    _, _, p = _cost(step)
    r = (seconds / est) ** (1.0 / p)
    return max(np.floor(r * 100.0) / 100.0, 0.01)


def lower_bound_s(estimate: float) -> float:
    """The least time a job estimated at ``estimate`` s was seen to take: estimate / OVER_ESTIMATE."""
    return float(estimate) / OVER_ESTIMATE


def check_budget(step: str, sizes, what: str, advice: str, limit: float | None = None) -> float:
    """Refuse (BolusError) when ``step`` on pieces of ``sizes`` triangles cannot fit the limit:
    when even the lower bound of its time (`lower_bound_s`) is over it.

    The step gets the limit less `OVERHEAD_S_PER_TRIANGLE` per triangle (reading the region,
    checking it, writing the result).  what: the input in words ("the region has 519,844
    triangles in 17 islands"); advice: what to do first ("select the treatment area first"; the
    Decimate ratio that would fit is added); limit: the user's time limit (`budget_s`).
    Returns the estimate (seconds); a job estimated over the limit but not refused runs under a
    `Deadline`."""
    sizes = np.atleast_1d(np.asarray(sizes, dtype=np.int64))
    est = estimate_s(step, sizes)
    limit = budget_s(limit)
    if limit is None:
        return est
    room = _room(limit, float(sizes.sum()))
    if lower_bound_s(est) <= room:
        return est
    name = LABELS.get(step, step)
    biggest = int(sizes.max()) if sizes.size else 0
    raise BolusError(
        f"{what} (largest piece {biggest:,} triangles): {name} would take about {_fmt_s(est)} on this computer "
        f"and at least {_fmt_s(lower_bound_s(est))}, over the {_room_text(limit, room)}, so it was not started "
        f"(one piece of up to about {max_triangles(step, room):,} triangles fits in it): {advice}, or decimate "
        f"the mesh (Decimate modifier, ratio {decimate_ratio(step, sizes, room):.2f}){_LONGER}")


def shell_cells(area_mm2: float, resolution: float) -> float:
    """The skin's voxel faces, area / resolution^2: what Make Bolus's work grows with."""
    return float(area_mm2) / float(resolution) ** 2


def grid_resolution_for_budget(area_mm2: float, wall_mm: float, resolution: float, triangles: int = 0,
                               limit: float | None = None):
    """(estimate s, limit s or None, the coarsest resolution (mm, rounded up to 0.01) whose
    estimate fits the limit, or None when this one's does) of Make Bolus on ``area_mm2``."""
    est = estimate_s("make_shell", shell_cells(area_mm2, resolution))
    limit = budget_s(limit)
    if limit is None:
        return est, None, None
    room = _room(limit, triangles)
    if est <= room:
        return est, limit, None
    _, _, p = _cost("make_shell")
    coarse = float(resolution) * (est / room) ** (1.0 / (2.0 * p))  # cells ~ resolution^-2
    return est, limit, float(np.ceil(coarse * 100.0) / 100.0)


def check_grid_budget(area_mm2: float, wall_mm: float, resolution: float, min_voxels: int, what: str,
                      triangles: int = 0, limit: float | None = None) -> float:
    """Make Bolus: refuse (BolusError) when a wall of ``wall_mm`` on ``area_mm2`` at ``resolution`` mm
    cannot fit the limit (its lower bound, `lower_bound_s`, is over it); the advice is the
    finest resolution that is not refused (while the wall keeps ``min_voxels`` across), else a
    smaller region.  Returns the estimate (s)."""
    est, limit, coarse = grid_resolution_for_budget(area_mm2, wall_mm, resolution, triangles, limit)
    if coarse is None or lower_bound_s(est) <= _room(limit, triangles):
        return est
    _, _, p = _cost("make_shell")  # the coarsest resolution whose lower bound fits: not refused there
    coarse = float(np.ceil(resolution * (lower_bound_s(est) / _room(limit, triangles)) ** (1.0 / (2.0 * p)) * 100) / 100)
    if coarse <= wall_mm / min_voxels:
        fix = f"choose a resolution of {coarse:.2f} mm or coarser, or select a smaller region (Select Treatment Area)"
    else:
        fix = (f"select a smaller region (Select Treatment Area): the resolution that would fit ({coarse:.2f} mm) "
               f"leaves fewer than {min_voxels} voxels across the {wall_mm:g} mm wall")
    room = _room(limit, triangles)
    raise BolusError(f"{what} at {resolution:g} mm: Make Bolus would take about {_fmt_s(est)} on this computer and "
                     f"at least {_fmt_s(lower_bound_s(est))}, over the {_room_text(limit, room)}, so it was not "
                     f"started: {fix}{_LONGER}")


class TimeLimitReached(BolusError):
    """A job stopped by its `Deadline`: nothing was changed."""


class Deadline:
    """A progress callback ``(fraction, text)`` that passes each call on to ``progress`` (or
    None) and raises `TimeLimitReached` once ``limit`` seconds (None: never) have passed since
    it was made.  The message names ``what`` (the step as the user knows it), how far it got
    (the last fraction and text) and what to do; the job stops at its next progress call."""

    def __init__(self, progress=None, limit: float | None = None, what: str = "the job",
                 advice: str = "select a smaller area, decimate the mesh or choose a coarser resolution",
                 clock=time.monotonic):
        self.progress, self.limit, self.what, self.advice, self.clock = progress, limit, what, advice, clock
        self.t0 = clock()
        self.fraction, self.text = 0.0, ""

    def __call__(self, fraction: float, text: str = "") -> None:
        self.fraction = float(fraction)
        self.text = str(text) if text else self.text
        if self.progress is not None:
            self.progress(fraction, text)
        if self.limit is not None and self.clock() - self.t0 > self.limit:
            where = f", at '{self.text}'" if self.text else ""
            raise TimeLimitReached(
                f"{self.what} stopped at the time limit of {_fmt_s(self.limit)} after {_fmt_s(self.clock() - self.t0)}, "
                f"{100 * self.fraction:.0f} % done{where}; nothing was changed: {self.advice}{_LONGER}")


#: the last way out of every refusal: the user may wait longer
_LONGER = "; or allow more time (Time limit (s) in the Bolus sidebar, 0 = no limit)"


def _room(limit: float, triangles: float) -> float:
    """Seconds left for the step: the budget less `OVERHEAD_S_PER_TRIANGLE` per triangle read, at least a quarter."""
    return max(limit - OVERHEAD_S_PER_TRIANGLE * float(triangles), 0.25 * limit)


def _room_text(limit: float, room: float) -> str:
    """"60 s budget", or "50 s left of the 60 s budget after reading the mesh" for a large mesh."""
    if room >= limit - 0.5:
        return f"{limit:.0f} s budget"
    return f"{room:.0f} s left of the {limit:.0f} s budget after reading the mesh"


def _fmt_s(seconds: float) -> str:
    if seconds < 10:
        return f"{seconds:.2g} s"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
