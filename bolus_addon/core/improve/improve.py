"""Improve flattenability by moving the surface outward (seed 4.3-4.4, eqs. 4-10..4-21).

`ImproveJob` / `improve_flattenability` (V (n,3) mm, F (m,3)) move the interior vertices of a region
along their outward normals by air gaps 0 <= d <= max_gap_mm so that the surface becomes easier to
flatten (J of eq. 4-21, `objective.SurfaceObjective`), and return an `Improvement` (V_out = V + N d):

* J's angle and area terms are evaluated on the analysis copy of the region (the skin smoothed at
  ``smoothing_mm``, `saliency.smooth_for_analysis`; 0 = the raw mesh), N its unit normals (eq. 3-2)
  taken once before any move; the smoothness term (4-13) on the output V + N d;
* with patch labels every patch is optimised on its own with its border fixed (seed Table 4-4);
  faces labelled -1 are left alone;
* ``GRADIENT`` (`DEFAULT_METHOD`): projected L-BFGS-B on J with |x| smoothed (`gradient_steps`),
  restarted in short chunks so a modal operator can step and cancel it; ``LPSO``: local node
  selection + particle swarm (Algorithms 4-1, 4-2; `lpso.lpso_steps`);
* before / after figures (Table 4-4: sum varpi, FLV, largest varpi, smoothness, area, gaps) on the
  analysis copies of input and output, each patch a mesh of its own (`surface_stats`); FLV never
  decreases: a patch whose sum varpi would rise is scaled back or left unchanged ("no gain").

Design notes: docs/design/improve.md.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import minimize
from threadpoolctl import threadpool_limits

from ..errors import BolusError
from .objective import MU_DEFAULT, SurfaceObjective, uniform_laplacian
from ..analysis.saliency import corner_angle_sums, flattenability, flattenability_value, smooth_for_analysis
from ..mesh.topology import MeshTopology, check_mesh, misoriented_text, submesh

__all__ = ["METHODS", "DEFAULT_METHOD", "FLAT_VARPI", "SurfaceStats", "PatchImprovement", "Improvement",
           "ImproveJob", "improve_flattenability", "gradient_steps", "surface_stats", "improve_messages"]

METHODS = ("GRADIENT", "LPSO")
DEFAULT_METHOD = "GRADIENT"
#: a patch whose largest varpi (rad, on the analysis copy) is below this is flat: nothing to do
FLAT_VARPI = 1e-5
#: air gaps above this (mm) get a warning: the clinic's tolerance is about 1 mm, 2 mm spoils the dose
GAP_WARN_MM = 2.0
#: most L-BFGS-B iterations of the gradient method per patch
GRADIENT_MAX_ITERATIONS = 1500


@dataclass
class SurfaceStats:
    """One row of the seed's Table 4-4 (mm, mm^2, rad)."""

    vertices: int
    edges: int
    faces: int
    sum_varpi: float  #: eq. 4-2 on the analysis copy
    flv: float  #: eq. 4-3
    max_varpi: float
    raw_sum_varpi: float  #: eq. 4-2 on the mesh as it is (smoothing 0)
    smoothness: float  #: sum over V_in of ||L x||^2 (eq. 4-13) on the analysis copy, mm^2
    area_mm2: float
    max_gap_mm: float
    mean_gap_mm: float

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class PatchImprovement:
    """Before / after of one patch; status "improved", "flat", "no gain", "no interior" or "cancelled"."""

    patch: int
    before: SurfaceStats
    after: SurfaceStats
    iterations: int = 0
    seconds: float = 0.0
    status: str = "no gain"
    objective_before: float = 0.0  #: J (eq. 4-21) on the analysis copy
    objective_after: float = 0.0

    def as_dict(self) -> dict:
        return {"patch": self.patch, "status": self.status, "iterations": self.iterations,
                "seconds": self.seconds, "objective_before": self.objective_before,
                "objective_after": self.objective_after, "before": self.before.as_dict(),
                "after": self.after.as_dict()}


@dataclass
class Improvement:
    """The improved region: V (n,3) mm, gap (n,) mm (0 <= gap <= max gap), directions (n,3)."""

    V: np.ndarray
    gap: np.ndarray
    directions: np.ndarray
    patches: list
    whole_before: SurfaceStats
    whole_after: SurfaceStats
    method: str
    max_gap_mm: float
    smoothing_mm: float
    cancelled: bool = False
    seconds: float = 0.0
    warnings: list = field(default_factory=list)
    infos: list = field(default_factory=list)

    @property
    def changed(self) -> bool:
        return bool(np.any(self.gap > 0))

    def table(self) -> dict:
        """JSON-ready figures: the whole region and every patch, before and after."""
        return {"method": self.method, "max_gap_mm": self.max_gap_mm, "smoothing_mm": self.smoothing_mm,
                "cancelled": self.cancelled, "seconds": self.seconds,
                "whole": {"before": self.whole_before.as_dict(), "after": self.whole_after.as_dict()},
                "patches": [p.as_dict() for p in self.patches]}


def surface_stats(V, Va, F, gap=None) -> SurfaceStats:
    """Table 4-4 figures of the mesh (V (n,3) true positions, Va (n,3) its analysis copy, F (m,3)),
    gap (n,) mm or None; only the vertices F uses count."""
    Fl, ids = submesh(F, np.ones(len(F), dtype=bool))
    topo = MeshTopology(V[ids], Fl)
    varpi = flattenability(topo, corner_angle_sums(Va[ids], topo))
    raw = flattenability(topo, topo.angle_sums)
    L = uniform_laplacian(topo)
    LX = L[np.nonzero(topo.interior_vertices)[0]] @ Va[ids]
    g = np.zeros(len(ids)) if gap is None else np.asarray(gap, dtype=np.float64)[ids]
    s = float(varpi.sum())
    return SurfaceStats(len(ids), len(topo.edges), len(Fl), s, flattenability_value(s), float(varpi.max(initial=0.0)),
                        float(raw.sum()), float(np.sum(LX * LX)), float(topo.areas.sum()),
                        float(g.max(initial=0.0)), float(g.mean()) if len(g) else 0.0)


@dataclass
class _State:
    d: np.ndarray
    value: float
    iterations: int


def gradient_steps(obj: SurfaceObjective, upper, *, max_iterations: int = GRADIENT_MAX_ITERATIONS,
                   chunk: int | None = None, window: int = 50, eps: float = 2e-3, smooth: float = 1e-3):
    """The gradient alternative: projected L-BFGS-B on the offsets of ``obj.movable_ids`` within
    [0, upper] (upper (n,) mm), on J with |x| smoothed (`SurfaceObjective.value_and_grad`).

    A generator: runs ``chunk`` iterations at a time (default: about 40,000 / movable vertices,
    10..200, i.e. ~0.2 s a slice, so a modal operator can step it and Esc answers quickly; a
    count, not a clock, so the same input gives the same result), then restarts from where it
    stopped; yields a state whose ``d`` (n,) is the best point so far by the exact J; stops at
    convergence, when the last ``window`` iterations gained less than ``eps`` (relative), or
    after ``max_iterations``."""
    ids = obj.movable_ids
    n = obj.n
    d = np.zeros(n)
    best = _State(d.copy(), obj.value(d), 0)
    if len(ids) == 0:
        yield best
        return
    if chunk is None:
        chunk = int(np.clip(40000 // len(ids), 10, 200))
    lo, hi = np.zeros(len(ids)), np.asarray(upper, dtype=np.float64)[ids]
    bounds = list(zip(lo, hi))

    def fun(x):
        d[ids] = x
        J, g = obj.value_and_grad(d, smooth)
        return J, g[ids]

    x = np.zeros(len(ids))
    total = 0
    marks = [(0, best.value)]  # (iteration, best exact J) after every chunk
    while total < max_iterations:
        # one BLAS thread: L-BFGS-B's many tiny BLAS calls ran 3-5x slower with OpenBLAS threads on a
        # busy 2-core machine (setulb 3 ms per call for 256 variables, measured)
        with threadpool_limits(1, user_api="blas"):
            res = minimize(fun, x, jac=True, method="L-BFGS-B", bounds=bounds,
                           options={"maxiter": min(chunk, max_iterations - total), "maxcor": 20})
        total += max(int(res.nit), 1)
        x = np.clip(res.x, lo, hi)
        d[ids] = x
        J = obj.value(d)
        if J < best.value:
            best = _State(d.copy(), J, total)
        best.iterations = total
        yield best
        if res.nit < chunk:  # converged before the chunk was used up
            break
        marks.append((total, best.value))
        old = [v for it, v in marks if it <= total - window]
        if old and old[-1] - best.value <= eps * max(abs(best.value), 1e-12):
            break


class ImproveJob:
    """One improvement run, steppable (see the module doc).

    V (n,3) mm, F (m,3) consistently wound, the side the faces point to is "outward";
    max_gap_mm > 0; method in METHODS; rng an int seed or Generator (LPSO); smoothing_mm the
    analysis scale; patch_labels (m,) int or None (-1: not touched); mu the weights of eq.
    4-21; particles / iterations / max_iterations the L-PSO's NP, T and budget;
    progress(fraction, text) optional; vert_ids (n,) the caller's vertex numbers for messages.
    BolusError: bad settings, an empty or degenerate mesh, inconsistent winding, no interior
    vertex.
    """

    def __init__(self, V, F, max_gap_mm: float = 1.0, *, method: str = DEFAULT_METHOD, rng=0,
                 smoothing_mm: float = 3.0, patch_labels=None, mu=MU_DEFAULT, particles: int = 30,
                 iterations: int = 200, max_iterations: int = 20000, progress=None, vert_ids=None):
        t0 = time.perf_counter()
        if not np.isfinite(max_gap_mm) or max_gap_mm <= 0:
            raise BolusError(f"the maximum air gap must be a positive number of mm (about 1 mm is what a clinic "
                             f"accepts), got {max_gap_mm:g}")
        method = str(method).upper()
        if method not in METHODS:
            raise BolusError(f"unknown method {method!r}: choose one of {', '.join(METHODS)}")
        if particles < 2 or iterations < 1 or max_iterations < 1:
            raise BolusError("the swarm needs at least 2 particles and 1 iteration")
        V, F = check_mesh(V, F, "the region", manifold=True)
        topo = MeshTopology(V, F)
        he = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
        if len(np.unique(he[:, 0] * topo.n + he[:, 1])) < len(he):
            raise BolusError(f"the region's faces are not consistently oriented ({misoriented_text(F)}), so "
                             "'outward' is not defined: recalculate the normals first (Mesh > Normals > Recalculate "
                             "Outside)")
        if not topo.boundary_edges.any():
            raise BolusError("the region is a closed surface, with no border to hold the bolus in place: select the "
                             "treatment area (an open part of the skin), not the whole closed mesh")
        if not topo.interior_vertices.any():
            raise BolusError("the region has no interior vertices: every vertex is on its border, which stays "
                             "fixed, so nothing can move (select a larger area)")
        labels = np.zeros(len(F), dtype=np.int64) if patch_labels is None else np.asarray(patch_labels, np.int64)
        if labels.shape != (len(F),):
            raise BolusError(f"patch labels must give one patch per triangle ({len(F)}), got shape {labels.shape}")
        self.V, self.F, self.topo, self.labels = V, F, topo, labels
        self.max_gap = float(max_gap_mm)
        self.method = method
        self.smoothing_mm = float(smoothing_mm)
        self.mu = mu
        self.particles, self.iterations, self.max_iterations = int(particles), int(iterations), int(max_iterations)
        self.progress_cb = progress
        self.vert_ids = np.arange(len(V)) if vert_ids is None else np.asarray(vert_ids)
        self.rng = np.random.default_rng(rng)
        self.Va = smooth_for_analysis(topo, self.smoothing_mm)
        self.N = MeshTopology(self.Va, F).vertex_normals
        self.d = np.zeros(len(V))
        self.patch_ids = [int(p) for p in np.unique(labels[labels >= 0])]
        self.patches: list[PatchImprovement] = []
        self._masks = {p: labels == p for p in self.patch_ids}
        zero = np.zeros(len(V))
        self.whole_before = surface_stats(V, self.Va, F[labels >= 0] if (labels >= 0).any() else F, zero)
        for p in self.patch_ids:
            st = surface_stats(V, self.Va, F[self._masks[p]], zero)
            self.patches.append(PatchImprovement(p, st, st))
        self._weights = np.array([max(pi.before.vertices, 1) for pi in self.patches], dtype=float)
        self._k = 0  # the patch being worked on
        self._it = None  # its optimiser
        self._obj = None
        self._ids = None
        self._state = None
        self._t_patch = 0.0
        self._finished = False
        self._result = None
        self._t0 = t0
        self.fraction, self.text = 0.0, "starting"
        self.infos: list[str] = []
        self.warnings: list[str] = []

    # ------------------------------------------------------------------ stepping
    def _report(self, fraction: float, text: str) -> None:
        self.fraction, self.text = float(min(max(fraction, 0.0), 1.0)), text
        if self.progress_cb is not None:
            self.progress_cb(self.fraction, text)

    def _start_patch(self, k: int) -> None:
        rec = self.patches[k]
        Fl, ids = submesh(self.F, self._masks[rec.patch])
        self._ids = ids
        self._t_patch = time.perf_counter()
        # angles and areas on the analysis copy, smoothness (4-13) on the skin that will be moved
        self._obj = obj = SurfaceObjective(self.Va[ids], Fl, self.N[ids], self.mu, smooth_base=self.V[ids])
        rec.objective_before = rec.objective_after = obj.value(np.zeros(obj.n))
        varpi = np.where(obj.interior, np.abs(obj.theta0 - 2 * np.pi), 0.0)
        if len(obj.movable_ids) == 0:
            rec.status = "no interior"
            self._it = None
            return
        if varpi.max(initial=0.0) < FLAT_VARPI:
            rec.status = "flat"
            self._it = None
            return
        upper = np.where(obj.movable, self.max_gap, 0.0)
        if self.method == "GRADIENT":
            self._it = gradient_steps(obj, upper)
        else:
            from .lpso import lpso_steps
            seed = int(self.rng.integers(2**63 - 1))
            # a snapshot about every 0.2 s (a swarm iteration costs ~ particles x triangles); the
            # snapshots do not change the swarm, so the result does not depend on this
            chunk = int(np.clip(500_000 // (self.particles * obj.m), 1, 50))
            self._it = lpso_steps(obj, np.zeros(obj.n), upper, rng=seed, particles=self.particles,
                                  iterations=self.iterations, max_iterations=self.max_iterations, chunk=chunk)
        self._state = None

    def _end_patch(self, k: int, cancelled: bool = False) -> None:
        rec = self.patches[k]
        st = self._state
        if st is not None and rec.status not in ("flat", "no interior"):
            rec.iterations = int(st.iterations)
            if st.value < rec.objective_before:
                self.d[self._ids] = np.maximum(st.d, 0.0)
                rec.objective_after = float(st.value)
                rec.status = "cancelled" if cancelled else "improved"
            else:
                rec.status = "cancelled" if cancelled else "no gain"
        elif cancelled and rec.status not in ("flat", "no interior"):
            rec.status = "cancelled"
        rec.seconds = time.perf_counter() - self._t_patch
        self._it = None
        self._state = None

    def step(self) -> bool:
        """Do a slice of the work (one optimiser chunk); False once everything is done."""
        if self._finished:
            return False
        if self._k >= len(self.patches):
            self._finish()
            return False
        k = self._k
        done_w = self._weights[:k].sum() / self._weights.sum()
        share = self._weights[k] / self._weights.sum()
        label = f"patch {k + 1}/{len(self.patches)}"
        if self._it is None and self._state is None:
            self._start_patch(k)
            if self._it is None:
                self._end_patch(k)
                self._k += 1
                self._report(done_w + share, f"{label}: {self.patches[k].status}")
                return True
        try:
            self._state = next(self._it)
        except StopIteration:
            self._end_patch(k)
            self._k += 1
            self._report(done_w + share, f"{label}: done")
            return True
        budget = GRADIENT_MAX_ITERATIONS if self.method == "GRADIENT" else self.max_iterations
        frac = min(self._state.iterations / max(budget, 1), 0.95)
        self._report(done_w + share * frac, f"{label}: {self._state.iterations} iterations, J = {self._state.value:.4g}")
        return True

    def _finish(self, cancelled: bool = False) -> None:
        if self._finished:
            return
        if cancelled and self._k < len(self.patches):
            if self._it is not None or self._state is not None:
                self._end_patch(self._k, cancelled=True)
                self._k += 1
            for rec in self.patches[self._k:]:
                if rec.status not in ("flat", "no interior"):
                    rec.status = "cancelled"
        self._safeguard()
        self._result = self._build(cancelled)
        self._finished = True
        self._report(1.0, "done")

    def _measure(self, d: np.ndarray):
        Vo = self.V + self.N * d[:, None]
        Va = smooth_for_analysis(MeshTopology(Vo, self.F), self.smoothing_mm)
        return Vo, Va

    def _safeguard(self) -> None:
        """FLV never decreases: scale back (halve up to 3 times, then drop) the offsets of every patch
        whose sum varpi on the analysis copy of the output exceeds the one before."""
        for attempt in range(5):
            if not self.d.any():
                return
            Vo, Va = self._measure(self.d)
            worse = []
            for rec in self.patches:
                if rec.status not in ("improved", "cancelled"):
                    continue
                after = surface_stats(Vo, Va, self.F[self._masks[rec.patch]], self.d)
                if after.sum_varpi > rec.before.sum_varpi * (1 + 1e-9) + 1e-12:
                    worse.append(rec)
            if not worse:
                return
            for rec in worse:
                Fl, ids = submesh(self.F, self._masks[rec.patch])
                inner = np.zeros(len(self.V), dtype=bool)
                inner[ids] = True
                # the patch's own vertices (shared border vertices have d = 0 anyway)
                if attempt >= 3:
                    self.d[inner] = 0.0
                    rec.status = "no gain"
                    self.infos.append(f"patch {rec.patch}: the optimiser's surface did not lower sum varpi as the "
                                      "preview measures it; left unchanged")
                else:
                    self.d[inner] *= 0.5

    def _build(self, cancelled: bool) -> Improvement:
        d = np.clip(self.d, 0.0, self.max_gap)
        Vo, Va = self._measure(d)
        labelled = self.F[self.labels >= 0] if (self.labels >= 0).any() else self.F
        after = surface_stats(Vo, Va, labelled, d)
        for rec in self.patches:
            rec.after = surface_stats(Vo, Va, self.F[self._masks[rec.patch]], d)
            if rec.status == "improved" and not np.any(d[submesh(self.F, self._masks[rec.patch])[1]] > 0):
                rec.status = "no gain"
        res = Improvement(Vo, d, self.N, self.patches, self.whole_before, after, self.method, self.max_gap,
                          self.smoothing_mm, cancelled, time.perf_counter() - self._t0,
                          list(self.warnings), list(self.infos))
        if d.max(initial=0.0) > GAP_WARN_MM:
            i = int(np.argmax(d))
            res.warnings.append(
                f"the largest air gap is {d[i]:.2f} mm (vertex {int(self.vert_ids[i])}): gaps over {GAP_WARN_MM:g} mm "
                "change the dose under the bolus and 5 mm is a failure; check it on the planning CT")
        return res

    def result(self) -> Improvement:
        """The improved region: at the end, or after a cancel the best surface so far (cancelled=True)."""
        if not self._finished:
            self._finish(cancelled=True)
        return self._result


def improve_flattenability(V, F, max_gap_mm: float = 1.0, **kw) -> Improvement:
    """Run an `ImproveJob` to the end (keywords as ImproveJob); returns the `Improvement`."""
    job = ImproveJob(V, F, max_gap_mm, **kw)
    while job.step():
        pass
    return job.result()


def _row(st: SurfaceStats) -> str:
    return (f"FLV {st.flv:.4g} (sum varpi {st.sum_varpi:.3f} rad, raw {st.raw_sum_varpi:.2f}), largest varpi "
            f"{st.max_varpi:.4f}, smoothness {st.smoothness:.4g} mm², area {st.area_mm2:.1f} mm²")


def improve_messages(res: Improvement, name: str = "the region") -> list[tuple[str, str]]:
    """(level, text) reports of an improvement, like Table 4-4: every patch before -> after."""
    out: list[tuple[str, str]] = [("WARNING", w) for w in res.warnings]
    out += [("INFO", m) for m in res.infos]
    for rec in res.patches if len(res.patches) > 1 else []:
        b, a = rec.before, rec.after
        if rec.status == "flat":
            out.append(("INFO", f"patch {rec.patch} is already flat (sum varpi {b.sum_varpi:.2e} rad): nothing to do"))
        elif rec.status == "no interior":
            out.append(("INFO", f"patch {rec.patch} has no interior vertex (its border is fixed): nothing to move"))
        else:
            out.append(("INFO", f"patch {rec.patch} ({rec.status}, {rec.iterations} iterations, {rec.seconds:.1f} s): "
                                f"FLV {b.flv:.4g} -> {a.flv:.4g}, sum varpi {b.sum_varpi:.3f} -> {a.sum_varpi:.3f} rad, "
                                f"largest varpi {b.max_varpi:.4f} -> {a.max_varpi:.4f}, smoothness {b.smoothness:.4g} -> "
                                f"{a.smoothness:.4g}, area {b.area_mm2:.1f} -> {a.area_mm2:.1f} mm², largest gap "
                                f"{a.max_gap_mm:.2f} mm"))
    b, a = res.whole_before, res.whole_after
    if all(r.status in ("flat", "no interior") for r in res.patches):
        out.append(("INFO", f"{name} is already flat (sum varpi {b.sum_varpi:.2e} rad): nothing to do, the surface "
                            "is unchanged"))
        return out
    if res.cancelled:
        out.append(("WARNING", f"cancelled after {sum(r.iterations for r in res.patches)} iterations: the best "
                               "surface so far was kept"))
    if len(res.patches) > 1 and res.changed and a.sum_varpi > b.sum_varpi:
        out.append(("INFO", f"{name} as a whole: sum varpi {b.sum_varpi:.3f} -> {a.sum_varpi:.3f} rad although no patch "
                            "got worse: the patch borders stay fixed and become shallow creases (at most the air gap "
                            "deep); a sheet is cut along them, so for the pattern only the patches' figures count"))
    if not res.changed:
        out.append(("INFO", f"{name}: no improvement found within {res.max_gap_mm:g} mm (sum varpi "
                            f"{b.sum_varpi:.3f} rad); the surface is unchanged"))
    out.append(("INFO", f"{name}: FLV {b.flv:.4g} -> {a.flv:.4g}, sum varpi {b.sum_varpi:.3f} -> {a.sum_varpi:.3f} rad "
                        f"(raw {b.raw_sum_varpi:.2f} -> {a.raw_sum_varpi:.2f}), largest varpi {b.max_varpi:.4f} -> "
                        f"{a.max_varpi:.4f}, smoothness {b.smoothness:.4g} -> {a.smoothness:.4g} mm², area "
                        f"{b.area_mm2:.1f} -> {a.area_mm2:.1f} mm² ({100 * (a.area_mm2 / b.area_mm2 - 1):+.2f} %), "
                        f"largest air gap {a.max_gap_mm:.2f} mm (mean {a.mean_gap_mm:.2f}; limit {res.max_gap_mm:g} mm), "
                        f"{res.method}, {res.seconds:.1f} s"))
    return out
