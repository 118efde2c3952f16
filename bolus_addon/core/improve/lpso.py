"""Local node selection (Algorithm 4-1) and L-PSO (Algorithm 4-2) on the objective of eq. 4-21.

The surface X(d) = X0 + N d moves every vertex along its own unit direction by an
offset d >= 0 (mm); `improve_objective.SurfaceObjective` evaluates J (eq. 4-21) and the
angle sums theta (eq. 4-1).  This module only searches offsets:

* `select_nodes` (Algorithm 4-1): which vertices a round of the swarm may move;
* `lpso_steps` / `lpso` (Algorithm 4-2): a particle swarm over the ABSOLUTE offsets
  of the selected vertices, inside the box 0 <= d <= upper, with the seed's T-doubling
  and eps stopping rule, the selection refreshed on the new surface between rounds.

Everything random comes from one ``rng`` (int seed or ``np.random.Generator``): the
same seed gives the same offsets bit for bit.

Measured (1 mm gap, defaults: 30 particles, T = 200, eps = 1e-4): ICT nose regions of
499 / 993 vertices (3 mm analysis copy) J 234.2 -> 219.2 (-6.4 %) in 1,200 iterations and
439.2 -> 438.5 (-0.2 %) in 800 iterations, 10-16 s on a loaded 2-core machine; about 94 %
of the time is ``obj.batch_values``.  Two limits, both measured on these noses: a round's
swarm (121 / 249 dimensions) finds 36 / 43 % of the gain that L-BFGS-B finds on the same
nodes (first round: 234.2 -> 225.3 against 209.6; 439.18 -> 438.82 against 438.36), and
Algorithm 4-1's selection itself is narrow: the best offsets of the 993-vertex nose's
first 249 nodes give J 438.4, while L-BFGS-B on all movable vertices reaches 401.8 (and
184 on the 499-vertex nose, against 219 for L-PSO).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from ..errors import BolusError

__all__ = [
    "PSO_W",
    "PSO_C1",
    "PSO_C2",
    "LPSOState",
    "select_nodes",
    "lpso_steps",
    "lpso",
]

TWO_PI = 2.0 * np.pi

#: Clerc's constriction values (Clerc & Kennedy 2002): inertia w and the two
#: acceleration coefficients c1 (own best), c2 (swarm best) of Algorithm 4-2 line 9
PSO_W, PSO_C1, PSO_C2 = 0.7298, 1.49618, 1.49618

#: varpi (rad) at or below this counts as flat: never a reference node
FLAT_VARPI = 1e-9

#: the swarm starts within +- INIT_SPREAD * box width around the current offsets
INIT_SPREAD = 0.25

#: initial velocities are uniform in +- VELOCITY0 * box width
VELOCITY0 = 0.05

#: velocities are clamped to +- VMAX * box width
VMAX = 1.0

#: the swarm has collapsed when every particle is within this * box width of gbest
#: and no velocity is larger: more iterations cannot find anything new
STALL = 1e-9


@dataclass
class LPSOState:
    """Progress of Algorithm 4-2 (a snapshot; the generator yields copies).

    d (n,) float: the best offsets so far (mm), 0 <= d <= upper; value: J(d) (eq. 4-21);
    iterations: swarm iterations t summed over the rounds (the seed's "number of
    iterations"); rounds: accepted rounds k (Gbest^k); evaluations: J evaluations
    (particles x iterations + the exact checks); done: the run has ended; history: J of
    Gbest^0 = J(d0), Gbest^1, ... (one entry per accepted round).
    doublings: how often T was doubled (T = T + T, Algorithm 4-2 line 20);
    selected: size of the current round's node set; stop: why the run ended
    ("converged" -- the eps rule, "stalled" -- the swarm collapsed without a gain,
    "nothing to move" -- Algorithm 4-1 selected no vertex, "max_iterations"), "" while running.
    """

    d: np.ndarray
    value: float
    iterations: int = 0
    rounds: int = 0
    evaluations: int = 0
    done: bool = False
    history: list = field(default_factory=list)
    doublings: int = 0
    selected: int = 0
    stop: str = ""

    def snapshot(self) -> "LPSOState":
        return replace(self, d=self.d.copy(), history=list(self.history))


def _adjacency(F: np.ndarray, n: int) -> sp.csr_matrix:
    """(n,n) bool CSR: one-ring neighbours N^p of every vertex, from the triangles F (m,3)."""
    F = np.asarray(F, dtype=np.int64)
    i = np.concatenate([F[:, 0], F[:, 1], F[:, 2], F[:, 1], F[:, 2], F[:, 0]])
    j = np.concatenate([F[:, 1], F[:, 2], F[:, 0], F[:, 0], F[:, 1], F[:, 2]])
    A = sp.csr_matrix((np.ones(len(i), dtype=bool), (i, j)), shape=(n, n))
    A.sum_duplicates()
    return A


def _movable_mask(obj) -> np.ndarray:
    mask = np.zeros(obj.n, dtype=bool)
    mask[np.asarray(obj.movable_ids, dtype=np.int64)] = True
    return mask


def _select(theta, d, interior, movable, adj, top_fraction) -> np.ndarray:
    """Algorithm 4-1 on given angle sums theta (n,) and offsets d (n,): sorted movable ids."""
    varpi = np.where(interior, np.abs(theta - TWO_PI), 0.0)
    cand = np.nonzero(interior & (varpi > FLAT_VARPI))[0]
    k = int(math.ceil(top_fraction * int(interior.sum()) - 1e-12))
    if k <= 0 or len(cand) == 0:
        return np.zeros(0, dtype=np.int64)
    # lines 1-5: the top 30 % of varpi (ties broken by vertex index, so the choice is reproducible)
    ref = cand[np.lexsort((cand, -varpi[cand]))][:k]
    is_ref = np.zeros(len(theta), dtype=bool)
    is_ref[ref] = True
    excess = ref[theta[ref] > TWO_PI]          # lines 8-9: theta > 2 pi -> pre-optimised
    deficit = ref[theta[ref] < TWO_PI]         # lines 10-12: stay reference ...
    pre = np.zeros(len(theta), dtype=bool)
    pre[excess] = True
    if len(deficit):
        ring = np.asarray(adj[deficit].sum(axis=0)).ravel() > 0   # ... their one-rings are candidates
        pre |= ring & ~is_ref                                     # lines 15-18
        pre[deficit[d[deficit] > 0]] = True   # step 4: moved out earlier -> may move back (never below 0)
    return np.nonzero(pre & movable)[0].astype(np.int64)


def select_nodes(obj, d, top_fraction: float = 0.3) -> np.ndarray:
    """Algorithm 4-1 (local node selection) on the surface X(d); returns (k,) sorted unique vertex ids.

    obj: `SurfaceObjective`; d (n,) offsets (mm).  With varpi = |theta(X(d)) - 2 pi| over
    the interior vertices V_in (eq. 4-1): the reference nodes are the ceil(top_fraction x
    |V_in|) interior vertices with the largest varpi (vertices with varpi <= 1e-9 rad are
    flat and never reference nodes).  Reference nodes with an excess (theta > 2 pi) are
    pre-optimised; those with a deficit (theta < 2 pi) stay reference nodes and their
    one-ring neighbours that are not reference nodes are pre-optimised; a deficit
    reference node that already has d > 0 is pre-optimised too (step 4: it may move back
    towards, never below, 0).  Only ``obj.movable_ids`` are returned.
    """
    if not (0.0 < float(top_fraction) <= 1.0):
        raise BolusError(f"top_fraction must be in (0, 1], got {top_fraction}")
    d = _offsets(d, obj.n, "d")
    return _select(np.asarray(obj.theta(d), dtype=float), d, np.asarray(obj.interior, dtype=bool),
                   _movable_mask(obj), _adjacency(obj.F, obj.n), float(top_fraction))


def _offsets(a, n: int, name: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.shape != (n,):
        raise BolusError(f"{name} must be an array of {n} offsets (one per vertex), got shape {a.shape}")
    bad = np.nonzero(~np.isfinite(a))[0]
    if len(bad):
        raise BolusError(f"{name} has {len(bad)} non-finite (NaN or infinite) value(s), e.g. at vertex {int(bad[0])}")
    return a


def _integer_arg(name: str, v, lo: int) -> int:
    """v as an int >= lo, or `BolusError` naming the argument."""
    try:
        ok = int(v) == v and v >= lo
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise BolusError(f"{name} must be an integer >= {lo}, got {v!r}")
    return int(v)


def _check_arguments(obj, d0, upper, particles, iterations, eps, max_iterations, top_fraction, chunk):
    """The input checks of `lpso_steps`; returns (d0 (n,), upper (n,), eps, P, T, max_iterations, chunk)."""
    n = int(obj.n)
    d0 = _offsets(d0, n, "d0")
    upper = _offsets(upper, n, "upper")
    if (upper < 0).any():
        i = int(np.nonzero(upper < 0)[0][0])
        raise BolusError(f"upper must be >= 0 (the largest offset, mm), got {upper[i]} at vertex {i}")
    counts = [_integer_arg(name, v, lo) for name, v, lo in (
        ("particles", particles, 2), ("iterations", iterations, 1), ("max_iterations", max_iterations, 1),
        ("chunk", chunk, 1))]
    try:
        eps = float(eps)
    except (TypeError, ValueError):
        eps = np.nan
    if not (np.isfinite(eps) and eps >= 0):
        raise BolusError(f"eps must be a finite number >= 0, got {eps}")
    if not (0.0 < float(top_fraction) <= 1.0):
        raise BolusError(f"top_fraction must be in (0, 1], got {top_fraction}")
    return (d0, upper, eps, *counts)


class _Search:
    """The state of one L-PSO run across its rounds: the accepted offsets d (n,) mm with J(d)
    (Gbest^k, eq. 4-21), the box 0 <= d <= upper (n,) mm, the selection's inputs and the
    `LPSOState` that is yielded."""

    def __init__(self, obj, d0, upper, rng, P: int, max_iterations: int, top_fraction: float, chunk: int):
        self.obj, self.P, self.max_iterations, self.chunk = obj, P, max_iterations, chunk
        self.top_fraction = float(top_fraction)
        self.g = np.random.default_rng(rng)
        self.movable = _movable_mask(obj)
        self.interior = np.asarray(obj.interior, dtype=bool)
        self.upper = np.where(self.movable, upper, 0.0)   # non-movable vertices stay put
        self.d = np.clip(d0, 0.0, self.upper)              # d0 projected onto the box
        self.adj = _adjacency(obj.F, int(obj.n))
        self.J = float(obj.value(self.d))
        self.st = LPSOState(d=self.d.copy(), value=self.J, evaluations=1, history=[self.J])

    def select(self) -> np.ndarray:
        """Algorithm 4-1 on the current surface, less the vertices whose box is empty: (k,) ids."""
        nodes = _select(np.asarray(self.obj.theta(self.d), dtype=float), self.d, self.interior, self.movable,
                        self.adj, self.top_fraction)
        return nodes[self.upper[nodes] > 0]

    def best_so_far(self, swarm: "_Swarm") -> None:
        """st.d / st.value := the better of Gbest^{k-1} and the running gbest of the swarm."""
        st = self.st
        st.d = self.d.copy()
        st.value = self.J
        if swarm.gf < self.J:
            st.d[swarm.nodes] = swarm.gX
            st.value = float(swarm.gf)

    def accept(self, swarm: "_Swarm") -> float | None:
        """Lines 17-18 after T iterations: Gbest^k = gbest if it is better, checked with one exact
        ``obj.value``; returns the gain J(Gbest^{k-1}) - J(Gbest^k), or None (no real gain)."""
        if not swarm.gf < self.J:
            return None
        dn = self.d.copy()
        dn[swarm.nodes] = swarm.gX
        Jn = float(self.obj.value(dn))
        self.st.evaluations += 1
        if not Jn < self.J:
            swarm.gf = self.J  # batch_values rounding: not a real gain
            return None
        gain = self.J - Jn
        self.d, self.J = dn, Jn
        self.st.rounds += 1
        self.st.history.append(Jn)
        return gain


class _Swarm:
    """One round's particles over the ABSOLUTE offsets of the k selected nodes (Algorithm 4-2):
    X, Vel, pbest (P,k) mm, pf (P,) J of the own bests, gX (k,) / gf the swarm's best; the box
    of every node is [0, hi]."""

    def __init__(self, search: _Search, nodes: np.ndarray):
        P, k, g = search.P, len(nodes), search.g
        self.nodes = nodes
        self.hi = search.upper[nodes]                   # (k,) box widths (lower bound 0)
        self.vmax = VMAX * self.hi
        x0 = search.d[nodes]
        # particle 0 at the current offsets (a round never makes J worse), the others around them
        self.X = np.clip(x0 + g.uniform(-INIT_SPREAD, INIT_SPREAD, (P, k)) * self.hi, 0.0, self.hi)
        self.X[0] = x0
        self.Vel = g.uniform(-VELOCITY0, VELOCITY0, (P, k)) * self.hi
        f = np.asarray(search.obj.batch_values(search.d, nodes, self.X), dtype=float)
        search.st.evaluations += P
        self.pbest, self.pf = self.X.copy(), f.copy()
        ib = int(np.argmin(self.pf))
        self.gX, self.gf = self.pbest[ib].copy(), float(self.pf[ib])

    def step(self, search: _Search) -> None:
        """One swarm iteration, lines 9-14: velocities (constriction values, clamped to +- VMAX x
        the box width), positions clipped to the box, all P candidates evaluated at once."""
        P, k = self.X.shape
        r1 = search.g.random((P, k))
        r2 = search.g.random((P, k))
        self.Vel *= PSO_W
        self.Vel += PSO_C1 * r1 * (self.pbest - self.X) + PSO_C2 * r2 * (self.gX - self.X)   # line 9
        np.clip(self.Vel, -self.vmax, self.vmax, out=self.Vel)
        self.X += self.Vel                                                                   # line 10
        np.clip(self.X, 0.0, self.hi, out=self.X)
        f = np.asarray(search.obj.batch_values(search.d, self.nodes, self.X), dtype=float)
        better = f < self.pf                                                                 # line 13
        self.pbest[better] = self.X[better]
        self.pf[better] = f[better]
        ib = int(np.argmin(self.pf))                                                         # line 14
        if self.pf[ib] < self.gf:
            self.gX, self.gf = self.pbest[ib].copy(), float(self.pf[ib])

    def collapsed(self) -> bool:
        """Every particle within STALL x the box width of gbest and no faster: nothing new to find."""
        width = self.hi.max()
        return np.abs(self.X - self.gX).max() <= STALL * width and np.abs(self.Vel).max() <= STALL * width


def _round(search: _Search, nodes: np.ndarray, T: int):
    """One round k of Algorithm 4-2 on the selected nodes (k,): swarm iterations until a gain
    is accepted after T of them (else T = T + T, line 20), the swarm collapses or the
    iteration cap is reached.  Yields a snapshot every ``chunk`` iterations; returns the
    accepted gain, or None."""
    st = search.st
    swarm = _Swarm(search, nodes)
    t, gain = 0, None
    while True:
        swarm.step(search)
        t += 1
        st.iterations += 1
        st.evaluations += search.P
        end_swarm = st.iterations >= search.max_iterations
        if t >= T:
            gain = search.accept(swarm)
            end_swarm = end_swarm or gain is not None
            if not end_swarm:
                if swarm.collapsed():
                    end_swarm = True
                else:
                    T += T                                                       # line 20
                    st.doublings += 1
        if st.iterations % search.chunk == 0:
            search.best_so_far(swarm)
            yield st.snapshot()
        if end_swarm:
            break
    search.best_so_far(swarm)
    return gain


def lpso_steps(obj, d0, upper, *, rng=0, particles: int = 30, iterations: int = 200, eps: float = 1e-4,
               max_iterations: int = 20000, top_fraction: float = 0.3, chunk: int = 50):
    """Algorithm 4-2 (L-PSO) as a generator of `LPSOState` snapshots.

    obj: `SurfaceObjective` (J of eq. 4-21 on X(d) = X0 + N d).  d0 (n,) start offsets
    (mm) and upper (n,) the largest offset of every vertex (the user's max air gap);
    non-movable vertices (boundary, ``obj.movable_ids`` excluded) get upper 0, and d0 is
    projected onto the box 0 <= d <= upper first.  Those bounds hold for every state.

    A round k: Algorithm 4-1 selects the nodes (k ids) on the current surface; a swarm
    of ``particles`` positions (P, k) over their ABSOLUTE offsets, bounds [0, upper];
    particle 0 starts at the current offsets (so a round never makes J worse), the
    others uniformly within +- 25 % of the box width around them, clipped to the box (a
    local search: a point drawn uniformly in the whole box is a rough, strongly penalised
    surface -- on a 500-vertex nose with 121 selected nodes and a 1 mm gap the median J of
    such particles is 2.1 x J(d0), of particles around d0 1.015 x -- and the swarm would
    spend its iterations coming back); velocities start uniform in +- 5 % of the box width.  Each iteration
    updates velocities with Clerc's constriction values (w, c1, c2) = (0.7298, 1.49618,
    1.49618) (line 9), clamps them to +- the box width, clips positions to the box
    (line 10) and evaluates all P candidates at once with ``obj.batch_values``.  After T
    (``iterations``) swarm iterations: if J(gbest) < J(Gbest^{k-1}) the round is accepted
    (Gbest^k = gbest, checked with one exact ``obj.value``), else T = T + T and the same
    swarm continues (line 20).  A swarm that has collapsed onto gbest without a gain
    ends the run ("stalled": more iterations cannot find anything).  After an accepted
    round the run stops when J(Gbest^{k-1}) - J(Gbest^k) < eps * |J(Gbest^{k-1})|
    (eps is RELATIVE to |J|; line 24), else the nodes are selected again on the new
    surface and a new round starts with T reset.  ``max_iterations`` caps the swarm
    iterations t summed over the rounds (the seed's count).

    Yields a snapshot every ``chunk`` swarm iterations and a last one with done=True;
    ``state.d`` is always the best offsets found so far (an interrupted run keeps it).
    """
    d0, upper, eps, P, T0, max_iterations, chunk = _check_arguments(
        obj, d0, upper, particles, iterations, eps, max_iterations, top_fraction, chunk)
    search = _Search(obj, d0, upper, rng, P, max_iterations, top_fraction, chunk)
    st = search.st
    while True:
        if st.iterations >= max_iterations:
            st.stop = "max_iterations"
            break
        nodes = search.select()
        st.selected = len(nodes)
        if len(nodes) == 0:
            st.stop = "nothing to move"
            break
        gain = yield from _round(search, nodes, T0)
        if gain is None:
            st.stop = "max_iterations" if st.iterations >= max_iterations else "stalled"
            break
        if gain < eps * max(abs(st.history[-2]), 1e-300):                # line 24
            st.stop = "converged"
            break
    st.d = search.d.copy()
    st.value = search.J
    st.done = True
    yield st.snapshot()


def lpso(obj, d0, upper, **kw) -> LPSOState:
    """Algorithm 4-2 run to the end: the last `LPSOState` of `lpso_steps` (same arguments)."""
    state = None
    for state in lpso_steps(obj, d0, upper, **kw):
        pass
    return state
