"""Minimisers of the spring energy (seed 3.5: eqs. 3-23..3-29).

Two minimisers of the same energy (`springs.spring_energy` plus optional area and extra
terms): `relax_explicit`, the seed's explicit Euler integration with lumped masses
(eqs. 3-23..3-27), and `relax_lbfgs`, a quasi-Newton minimiser with the exact gradient
and a Sobolev preconditioner.  L-BFGS is the default of `unfold.unfold_patch`: it reaches
a lower energy in a fraction of the time (bench/unfold_bench.py).
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..errors import BolusError
from .measures import check_positions
from .springs import Springs, area_terms, laplacian_with_shift, spring_energy, stiffness_laplacian

__all__ = ["relax_lbfgs", "relax_explicit", "STOP_EVERY"]

STOP_EVERY = 25  # iterations between calls of relax_lbfgs' stop(UV, it) test
PROGRESS_EVERY = 0.5  # seconds between progress calls inside a minimisation
FACTOR_EPS = 1e-8  # K + eps I with eps this fraction of K's mean diagonal: K is singular (translations)
ARMIJO = 1e-4  # sufficient-decrease constant of the line search
LINE_SEARCH_STEPS = 40  # backtracking steps before the line search gives up
STALL_WINDOW = 5  # relax_lbfgs stops when the energy fell by less than tol * E over this many iterations
ENERGY_FLOOR = 1e-28  # an energy this small is the exact minimum (a developable patch)
CURVATURE_TOL = 1e-16  # an (s, y) pair is kept only if s.y > this * |s|^2 (positive curvature)
EXPLICIT_CHECK = 100  # relax_explicit tests its stop criterion every this many steps
EXPLICIT_ENERGY_FLOOR = 1e-24  # relax_explicit stops at this energy (the step size limits it sooner than L-BFGS)
STEP_BRACKET = (0.1, 0.5)  # a backtracking step shrinks to within this fraction of the last one


def _start_positions(UV0, springs: Springs) -> np.ndarray:
    """UV0 (n,2) float64, n covering every spring end; `BolusError` on a bad shape or NaN/inf (named)."""
    n_min = int(springs.ends.max()) + 1 if len(springs.ends) else 0
    return check_positions(UV0, None, "the start", n_min)[:, :2]


def _factor_cache(springs: Springs, n: int):
    """Factorisation of K + eps I (`stiffness_laplacian`), cached on ``springs`` for its current stiffness."""
    key = (n, hash(springs.stiffness.tobytes()), hash(springs.ends.tobytes()))
    cache = springs.__dict__.setdefault("_factor", {})
    if key not in cache:
        # K + eps I (`springs.laplacian_with_shift`: the arrays of (K + eps * identity).tocsc())
        Keps, _ = laplacian_with_shift(springs, n, lambda diag: FACTOR_EPS * float(np.abs(diag).mean()))
        # symmetric positive definite: symmetric ordering, no pivoting (15x faster than default)
        lu = splu(Keps, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        cache.clear()  # one stiffness at a time (refinement changes it every round)
        cache[key] = (lu, Keps.tocsr())
    return cache[key]


def _preconditioner(springs: Springs, n: int, precondition: bool, moving):
    """(apply_h0, apply_k): v -> K^-1 v and v -> K v for the two-loop recursion; K of the
    moving vertices alone (the others held: Dirichlet) when ``moving`` is given; identity
    without preconditioning."""
    if not precondition:
        def ident(v):
            return v
        return ident, ident
    if moving is None:
        lu, Kcsr = _factor_cache(springs, n)
        return lu.solve, (lambda v: Kcsr @ v)
    mi = np.nonzero(moving)[0]
    K = stiffness_laplacian(springs, n)
    Kmm = K[mi][:, mi].tocsc()
    Kmm = Kmm + FACTOR_EPS * float(np.abs(Kmm.diagonal()).mean()) * sp.identity(len(mi), format="csc")
    lu_m = splu(Kmm.tocsc())
    Kcsr = K.tocsr()

    def apply_h0(v):
        out = np.zeros_like(v)
        out[mi] = lu_m.solve(v[mi])
        return out

    return apply_h0, (lambda v: Kcsr @ v)


def _objective(springs: Springs, n: int, F, A0, flip_weight: float, area_weights, extra, moving):
    """x (n,2) -> (energy, gradient (n,2)): springs + area terms + extra, frozen vertices' gradient zeroed."""
    mean_A0 = float(np.mean(A0)) if A0 is not None and len(A0) else None

    def fun(x):
        e, g = spring_energy(x.ravel(), springs, n)
        if flip_weight > 0 or area_weights is not None:
            e2, g2 = area_terms(x.ravel(), F, A0, n, flip_weight, area_weights, mean_A0=mean_A0)
            e, g = e + e2, g + g2
        if extra is not None:
            e3, g3 = extra(x.ravel())
            e, g = e + e3, g + g3
        g = g.reshape(n, 2)
        if moving is not None:
            g[~moving] = 0.0
        return e, g

    return fun


def _two_loop(g, S, Y, apply_h0, gamma: float, SY):
    """L-BFGS direction -H g (n,2) by the two-loop recursion with H0 = gamma K^-1.

    SY: the products y.s of the pairs and gamma = s.K s / s.y of the newest pair, both computed
    once when a pair is stored.  The pairs are (n,2) C-ordered arrays; the dot products and
    updates run on their flat views with Python floats (the per-step numpy overhead, not
    the arithmetic, is the cost on patches of a few hundred vertices), each rounded as in the
    plain loop over (n,2) arrays: the same numbers, bit for bit."""
    q = g.copy()
    qf = q.ravel()
    k = len(S)
    alphas = [0.0] * k
    for i in range(k - 1, -1, -1):
        a_ = (1.0 / SY[i]) * float(np.dot(S[i].ravel(), qf))  # rho s.q, rounded as rho times
        alphas[i] = a_
        qf -= a_ * Y[i].ravel()
    r = np.ascontiguousarray(apply_h0(q))  # (the solver may hand back a Fortran-ordered array)
    if k:  # scale H0: y ~ (1/gamma) K s  =>  gamma = s.K s / s.y (a matvec per pair, no solve)
        r *= gamma
    rf = r.ravel()
    for i in range(k):
        b_ = (1.0 / SY[i]) * float(np.dot(Y[i].ravel(), rf))
        rf += (alphas[i] - b_) * S[i].ravel()
    return -r


def _line_search(fun, x, e, d, slope):
    """Armijo backtracking from t = 1 with a quadratic step estimate (penalty terms make
    plain halving take ~7 evaluations per iteration).  Returns (x, e, g) or None."""
    t = 1.0
    for _ in range(LINE_SEARCH_STEPS):
        xn = x + t * d
        en, gn = fun(xn)
        if en <= e + ARMIJO * t * slope:
            return xn, en, gn
        # minimiser of the quadratic through e, slope and en, kept within STEP_BRACKET x t
        lo, hi = STEP_BRACKET
        denom = 2.0 * (en - e - slope * t)
        t_q = -slope * t * t / denom if denom > 0 and np.isfinite(en) else lo * t
        t = min(max(t_q, lo * t), hi * t)
    return None


def relax_lbfgs(UV0, springs: Springs, max_iter: int = 2000, tol: float = 1e-9, F=None, A0=None,
                flip_weight: float = 0.0, callback=None, memory: int = 8,
                precondition: bool = True, area_weights=None, extra=None, progress=None,
                stop=None, moving=None) -> tuple[np.ndarray, int, float]:
    """Minimise the spring energy (eqs. 3-28, 3-29, 4-25) with L-BFGS from UV0 (n,2).

    Parameters: springs (`springs.Springs`); F (m,3), A0 (m,) with flip_weight > 0 or
    area_weights (m,): the area terms of `springs.area_terms`; extra: x (2n,) -> (energy,
    gradient (2n,)) added to the energy; moving (n,) bool: only these vertices move;
    stop(UV, it): asked every `STOP_EVERY` iterations, True stops; progress(fraction of
    max_iter) about every 0.5 s; callback(UV) after every iteration.
    Returns (UV (n,2), iterations, energy).  `BolusError` if UV0 is not (n,2) covering
    every spring end or has NaN/inf positions (named).

    The initial inverse Hessian of the two-loop recursion is gamma K^-1, K the springs'
    Hessian at rest (`stiffness_laplacian`, factorised once per stiffness and cached on
    the springs): a Sobolev preconditioner that makes the iteration count almost
    independent of the mesh resolution (plain L-BFGS needs thousands of iterations on a
    20k-triangle cap).  Stops when the energy decreased by less than tol * E over
    `STALL_WINDOW` iterations, after max_iter iterations, or when stop says so.
    """
    x = _start_positions(UV0, springs).copy()
    n = len(x)
    fun = _objective(springs, n, F, A0, flip_weight, area_weights, extra, moving)
    apply_h0, apply_k = _preconditioner(springs, n, precondition, moving)
    e, g = fun(x)
    S: list[np.ndarray] = []
    Y: list[np.ndarray] = []
    SY: list[float] = []  # y.s of every stored pair
    gamma = 1.0  # s.K s / s.y of the newest pair (`_two_loop`)
    history = [e]
    it = 0
    t_report = time.perf_counter() + PROGRESS_EVERY
    for it in range(1, max_iter + 1):
        d = _two_loop(g, S, Y, apply_h0, gamma, SY)
        slope = float(np.vdot(g, d))
        if not slope < 0:  # not a descent direction: forget the history
            S.clear()
            Y.clear()
            SY.clear()
            d = -apply_h0(g)
            slope = float(np.vdot(g, d))
            if not slope < 0:
                break
        step = _line_search(fun, x, e, d, slope)
        if step is None:
            break
        xn, en, gn = step
        s_, y_ = xn - x, gn - g
        sy = float(np.vdot(s_, y_))
        if sy > CURVATURE_TOL * max(float(np.vdot(s_, s_)), 1e-300):
            S.append(s_)
            Y.append(y_)
            SY.append(sy)
            gamma = float(np.vdot(s_, apply_k(s_))) / max(sy, 1e-300)
            if len(S) > memory:
                S.pop(0)
                Y.pop(0)
                SY.pop(0)
        x, e, g = xn, en, gn
        history.append(e)
        if callback is not None:
            callback(x)
        if len(history) > STALL_WINDOW and history[-STALL_WINDOW - 1] - e <= tol * max(e, 1e-300):
            break
        if e <= ENERGY_FLOOR:
            break
        if stop is not None and it % STOP_EVERY == 0 and stop(x, it):
            break
        if progress is not None:
            now = time.perf_counter()
            if now >= t_report:
                progress(it / max_iter)
                t_report = now + PROGRESS_EVERY
    return x, it, float(e)


def relax_explicit(UV0, springs: Springs, masses: np.ndarray, max_iter: int = 20000, damping: float = 0.05,
                   tol: float = 1e-10, callback=None, progress=None) -> tuple[np.ndarray, int, float]:
    """The seed's explicit integration (eqs. 3-23..3-27) from UV0 (n,2) with masses (n,) (eq. 3-24).

    v(t+dt) = v + dt a,  x(t+dt) = x + dt v + dt^2/2 a,  a = f / m (eq. 3-25).
    The seed gives no damping; without it the springs oscillate for ever, so the
    velocity is multiplied by (1 - damping) each step.  The step is the largest stable
    one for the stiffest spring (dt = 0.5 sqrt(m_min / (c_max * degree))).
    Stops when the relative energy change over 100 steps falls below tol.
    progress(fraction of max_iter) is called about every 0.5 s.
    Returns (UV (n,2), steps, energy).  `BolusError` on a bad UV0 (as `relax_lbfgs`) or
    masses that are not (n,) positive.
    """
    x = _start_positions(UV0, springs).ravel().copy()
    n = len(UV0)
    masses = np.asarray(masses, dtype=np.float64)
    if masses.shape != (n,) or not (masses > 0).all():
        raise BolusError(f"the masses must be {n} positive numbers (one per vertex, eq. 3-24)")
    v = np.zeros_like(x)
    m2 = np.repeat(np.maximum(masses, 1e-300), 2)
    deg = np.bincount(springs.ends.ravel(), minlength=n).max()
    dt = 0.5 * np.sqrt(masses.min() / (springs.stiffness.max() * max(deg, 1)))
    e_prev, _ = spring_energy(x, springs, n)
    it = 0
    t_report = time.perf_counter() + PROGRESS_EVERY
    for it in range(1, max_iter + 1):
        e, grad = spring_energy(x, springs, n)
        a = -grad / m2
        x += dt * v + 0.5 * dt * dt * a
        v = (1.0 - damping) * (v + dt * a)
        if it % EXPLICIT_CHECK == 0:
            if callback is not None:
                callback(x)
            if progress is not None and time.perf_counter() >= t_report:
                progress(it / max_iter)
                t_report = time.perf_counter() + PROGRESS_EVERY
            if abs(e_prev - e) <= tol * max(e, 1e-300) or e < EXPLICIT_ENERGY_FLOOR:
                break
            e_prev = e
    e, _ = spring_energy(x, springs, n)
    return x.reshape(n, 2), it, float(e)
