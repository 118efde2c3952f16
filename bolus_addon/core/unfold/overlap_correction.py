"""Overlap correction of an unfolded pattern (seed 4.5.3, Fig. 4-18; our budgets and local steps).

- flipped triangles: local untangling (`untangle`), then a growing penalty on negative
  signed area and the energy minimised again (`correct_flips`);
- outline crossings (boundary edges that cross, overlap.py): the vertex of one edge that
  lies inside the pattern is pushed back out across the other (`outline_term`, the seed's
  "spring along the intersected edge"), first locally around the crossings
  (`local_outline`: only vertices within `LOCAL_RINGS` rings move, with the tension and
  area springs IRLS-weighted as in the length refinement so that the refined pattern is
  kept), over the whole patch only if that fails (`correct_outline`).

Budgets (the seed gives none): every minimisation has an iteration budget and a
stop test, the rounds stop when the defects stop going down, the best pattern is kept.
On the scanned nose patches the whole-patch correction left 4 overlapping triangles (nose
p1, p2); with the local one none, and nose p1 went from 2.7x to 1.7x the time of SLIM-100.
"""
from __future__ import annotations

import numpy as np

from ..mesh.geometry2d import cross2d
from .overlap import boundary_edge_array, boundary_self_intersections, overlapping_faces, signed_areas
from .refine import AREA_BALANCE, area_balance_factor, irls_area_weights, irls_length_weights
from .relax import relax_lbfgs
from .springs import Springs
from ..mesh.topology import MeshTopology

__all__ = ["untangle", "correct_flips", "outline_term", "correct_outline", "local_outline", "defects"]

FLIP_WEIGHT = 10.0  # base weight of the flip penalty (springs.area_terms); rounds multiply it
PENALTY_TOL = 1e-6  # stop test of the penalty minimisations (flips, outline): relative decrease over 5 iterations
FLIP_ITERS = 150  # L-BFGS iterations per flip-correction round (was 300)
FLIP_ROUNDS = 4  # flip-correction rounds, penalty x10 each
FLIP_GROWTH = 10.0  # flip penalty factor from one round to the next
UNTANGLE_SWEEPS = 50  # Laplacian sweeps of `untangle`
OUTLINE_WEIGHT = 10.0  # outline penalty / median spring stiffness
OUTLINE_GROWTH = 2.0  # outline penalty factor per whole-patch round while crossings remain
OUTLINE_MARGIN = 0.01  # vertices are pushed this fraction of the mean edge length past the edge
OUTLINE_ROUNDS = 8  # outline correction rounds (the seed's loop; was 16)
OUTLINE_ITERS = 60  # L-BFGS iterations per outline round (was 300)
OUTLINE_PATIENCE = 2  # rounds without fewer defects before the outline correction gives up
LOCAL_RINGS = 3  # vertex rings around a crossing of the outline that `local_outline` moves
LOCAL_ROUNDS = 6  # its rounds (penalty doubled each round)
LOCAL_ITERS = 40  # L-BFGS iterations per round (a few dozen moving vertices)
LOCAL_GROWTH = 2.0  # outline penalty factor from one local round to the next
LOCAL_FLIP_WEIGHT = 1000.0  # x FLIP_WEIGHT: the local solve must not turn a triangle over
IRLS_CLIP = 10.0  # the local solve's IRLS weights stay within this factor of their median
LOCAL_CROSSED = False  # crossed springs in the local solve (with them: nose p1 EL +0.45 % instead of +0.2 %)


def _flipped(UV, F) -> int:
    return int(np.count_nonzero(signed_areas(UV, F) <= 0))


def defects(UV, F) -> tuple[int, int]:
    """(flipped triangles, overlapping triangles) of a pattern UV (n,2), F (m,3): lower is better."""
    return _flipped(UV, F), int(overlapping_faces(UV, F).sum())


def untangle(UV, topo: MeshTopology, sweeps: int = UNTANGLE_SWEEPS) -> tuple[np.ndarray, int]:
    """Local untangling (our addition to 4.5.3): the vertices of flipped triangles and their
    one-ring move to the mean of their neighbours (uniform Laplacian), a few sweeps.  A fold
    of a few triangles on a 40k-triangle patch otherwise costs whole L-BFGS rounds over
    every vertex.  UV (n,2) -> (UV, flipped); UV is unchanged if the flip count did not drop."""
    F = topo.F
    flips0 = _flipped(UV, F)
    if flips0 == 0:
        return UV, 0
    A = topo.vertex_adjacency
    deg = np.maximum(np.asarray(A.sum(axis=1)).ravel(), 1.0)
    X = UV.copy()
    for _ in range(sweeps):
        bad = signed_areas(X, F) <= 0
        if not bad.any():
            break
        sel = np.zeros(topo.n, dtype=bool)
        sel[F[bad].ravel()] = True
        sel |= np.asarray(A @ sel.astype(np.float64)).ravel() > 0
        X[sel] = (A @ X)[sel] / deg[sel, None]
    flips = _flipped(X, F)
    return (X, flips) if flips < flips0 else (UV, flips0)


def correct_flips(UV, springs: Springs, topo: MeshTopology, rounds: int = FLIP_ROUNDS, max_iter: int = FLIP_ITERS,
                  progress=None, weight: float = FLIP_WEIGHT):
    """Overlap correction of flipped triangles (4.5.3): untangle, then push them back with a
    penalty growing `FLIP_GROWTH`-fold per round.  UV (n,2) -> (UV, iterations, still flipped).
    Stops when a stronger penalty did not help (our budget); the best pattern is kept."""
    F, A0 = topo.F, topo.areas
    flipped = _flipped(UV, F)
    its = 0
    best = (flipped, UV)
    for k in range(rounds):
        if flipped == 0:
            break
        UV, flipped = untangle(UV, topo)
        if flipped == 0:  # the lengths around the fold were smoothed: relax them back, folds kept out
            UV, it, _ = relax_lbfgs(UV, springs, max_iter=OUTLINE_ITERS, tol=PENALTY_TOL, F=F, A0=A0,
                                    flip_weight=max(weight, FLIP_WEIGHT * 100.0))
            its += it
            flipped = _flipped(UV, F)
            if flipped == 0:
                best = (0, UV)
                break
        sub = None if progress is None else (lambda f, k=k: progress((k + f) / rounds))
        UV, it, _ = relax_lbfgs(UV, springs, max_iter=max_iter, tol=PENALTY_TOL, F=F, A0=A0, flip_weight=weight,
                                progress=sub)
        its += it
        flipped = _flipped(UV, F)
        weight *= FLIP_GROWTH
        if flipped >= best[0] and k >= 1:
            break  # a stronger penalty did not help twice: the fold is not going away (our budget)
        if flipped < best[0]:
            best = (flipped, UV)
    if flipped > best[0]:
        flipped, UV = best
    return UV, its, flipped


def outline_term(verts: np.ndarray, edges: np.ndarray, lengths: np.ndarray, n: int, weight: float, margin: float):
    """Penalty pushing outline vertices out of the pattern across outline edges (4.5.3).

    verts (k,), edges (k,2), lengths (k,): for every (vertex v, boundary edge c->d with the
    pattern on its left) pair, s = (d - c) x (v - c) / L is v's distance to the left of the
    edge's line; energy 1/2 w max(0, s + margin)^2: the seed's "spring along the
    intersected edge" that moves a wrongly placed vertex back out.
    Returns f(x (2n,)) -> (energy, grad (2n,)).
    """
    idx = np.concatenate([verts, edges[:, 1], edges[:, 0]])

    def f(x):
        Q = x.reshape(n, 2)
        v, c, d = Q[verts], Q[edges[:, 0]], Q[edges[:, 1]]
        e, r = d - c, v - c
        s = cross2d(e, r) / lengths
        viol = np.maximum(s + margin, 0.0)
        coef = weight * viol / lengths  # dE/d(cross product)
        gv = np.stack([-e[:, 1], e[:, 0]], 1) * coef[:, None]
        gd = np.stack([r[:, 1], -r[:, 0]], 1) * coef[:, None]
        gg = np.concatenate([gv, gd, -gv - gd])
        grad = np.empty((n, 2))
        grad[:, 0] = np.bincount(idx, gg[:, 0], minlength=n)
        grad[:, 1] = np.bincount(idx, gg[:, 1], minlength=n)
        return 0.5 * weight * float(np.dot(viol, viol)), grad.ravel()

    return f


def _add_constraints(cons: set, pairs: np.ndarray, E: np.ndarray) -> None:
    """For every crossing pair of boundary edges (a, b): (v, b) for each end v of a not on b, and vice versa."""
    for i, j in pairs.tolist():
        for a, b in ((i, j), (j, i)):
            for v in E[a]:
                if v not in E[b]:
                    cons.add((int(v), int(b)))


def _constraint_arrays(cons: set, E: np.ndarray, UV, mean_len: float):
    """(vertices (k,), edges (k,2), edge lengths (k,)) of the outline constraints."""
    cv = np.array([c[0] for c in cons], dtype=np.int64)
    ce = E[np.array([c[1] for c in cons], dtype=np.int64)]
    L = np.maximum(np.linalg.norm(UV[ce[:, 1]] - UV[ce[:, 0]], axis=1), 1e-9 * mean_len)
    return cv, ce, L


def correct_outline(UV, springs: Springs, topo: MeshTopology, rounds: int = OUTLINE_ROUNDS,
                    max_iter: int = OUTLINE_ITERS, progress=None):
    """Whole-patch overlap correction of the outline (4.5.3, first method): where boundary
    edges cross, the vertex of one that lies inside the pattern is pushed back out across
    the other, with the flip penalty raised so that no triangle turns over on the way.
    Constraints found in earlier rounds are kept.

    UV (n,2).  Budget (our change): at most ``rounds`` rounds of ``max_iter``
    L-BFGS iterations, stopping once the defects (flipped, crossing) have not improved for
    `OUTLINE_PATIENCE` rounds; the best pattern seen is returned.  progress(fraction, text)
    names the round.  Returns (UV, iterations, crossings left, the last penalty term, to
    keep the outline apart in later steps)."""
    F = topo.F
    E = boundary_edge_array(F)
    mean_len = float(topo.edge_lengths.mean())
    cons: set[tuple[int, int]] = set()
    its, term, stale = 0, None, 0
    pairs = boundary_self_intersections(UV, F)
    weight = float(np.median(springs.stiffness)) * OUTLINE_WEIGHT
    flip_w = FLIP_WEIGHT * 100.0
    flips = _flipped(UV, F)
    best = ((flips, len(pairs)), UV, term)
    for k in range(rounds):
        if len(pairs) == 0 and flips == 0:
            break
        if flips:
            flip_w *= FLIP_GROWTH
        _add_constraints(cons, pairs, E)
        if not cons:
            break
        text = f"overlap correction round {k + 1}/{rounds}"
        if progress is not None:
            progress(k / rounds, text)
        sub = None if progress is None else (lambda f, k=k, text=text: progress((k + f) / rounds, text))
        cv, ce, L = _constraint_arrays(cons, E, UV, mean_len)
        term = outline_term(cv, ce, L, topo.n, weight=weight, margin=OUTLINE_MARGIN * mean_len)
        UV, it, _ = relax_lbfgs(UV, springs, max_iter=max_iter, tol=PENALTY_TOL, F=F, A0=topo.areas,
                                flip_weight=flip_w, extra=term, progress=sub)
        its += it
        pairs = boundary_self_intersections(UV, F)
        flips = _flipped(UV, F)
        if len(pairs):
            weight *= OUTLINE_GROWTH
        if (flips, len(pairs)) < best[0]:
            best, stale = ((flips, len(pairs)), UV, term), 0
        else:
            stale += 1
            if stale >= OUTLINE_PATIENCE:
                break
    (_, crossings), UV, term = best
    return UV, its, crossings, term


def _moving_vertices(topo: MeshTopology, X, cv, ce, rings: int) -> np.ndarray:
    """(n,) bool: the constrained vertices and edges, the overlapping triangles, and ``rings`` rings around."""
    free = np.zeros(topo.n, dtype=bool)
    free[cv] = True
    free[ce.ravel()] = True
    free[topo.F[overlapping_faces(X, topo.F)].ravel()] = True
    A = topo.vertex_adjacency
    for _ in range(rings):
        free |= np.asarray(A @ free.astype(np.float64)).ravel() > 0
    return free


class _LocalProblem:
    """The springs and triangles touching the moving vertices, re-indexed to the touched
    vertices ``gid`` (l,), with IRLS weights towards EL / EA clipped to `IRLS_CLIP` x their median."""

    def __init__(self, topo: MeshTopology, springs: Springs, X, free: np.ndarray):
        F, nt = topo.F, springs.n_tension
        ssel = free[springs.ends].any(axis=1)
        ssel[nt:] &= LOCAL_CROSSED
        fsel = free[F].any(axis=1)
        touched = free.copy()
        touched[springs.ends[ssel].ravel()] = True
        touched[F[fsel].ravel()] = True
        self.gid = np.nonzero(touched)[0]
        self.loc = np.full(topo.n, -1, dtype=np.int64)
        self.loc[self.gid] = np.arange(len(self.gid))
        self.mov = self.loc[np.nonzero(free)[0]]
        self.X = X[self.gid]
        self.F, self.A0 = self.loc[F[fsel]], topo.areas[fsel]
        self._weights(topo, springs, ssel)

    def _weights(self, topo: MeshTopology, springs: Springs, ssel) -> None:
        nt = springs.n_tension
        face_count = topo.edge_face_count.astype(np.float64)
        stiff_med = float(np.median(springs.stiffness[:nt]))
        lam = area_balance_factor(springs.rest[:nt], face_count, topo.areas, AREA_BALANCE)
        ends, rest = self.loc[springs.ends[ssel]], springs.rest[ssel]
        stiff = springs.stiffness[ssel].copy()
        tsel = np.nonzero(ssel[:nt])[0]
        ntl = len(tsel)
        Xl = self.X
        w = irls_length_weights(np.linalg.norm(Xl[ends[:ntl, 0]] - Xl[ends[:ntl, 1]], axis=1), rest[:ntl],
                                face_count[tsel])
        w_med = float(np.median(w))
        stiff[:ntl] = np.clip(w / w_med, 1.0 / IRLS_CLIP, IRLS_CLIP) * stiff_med
        self.springs = Springs(ends, rest, stiff, ntl, np.zeros((0, 1), dtype=np.int64), np.zeros(0), np.zeros(0))
        aw = irls_area_weights(signed_areas(Xl, self.F), self.A0)
        aw_med = float(np.median(aw))
        self.area_weights = np.clip(aw / aw_med, 1.0 / IRLS_CLIP, IRLS_CLIP) * aw_med * lam * stiff_med / w_med

    def solve(self, X, cv, ce, L, weight: float, margin: float, max_iter: int):
        """Minimise over the moving vertices; returns (X (n,2) with them moved, iterations)."""
        term = outline_term(self.loc[cv], self.loc[ce], L, len(self.gid), weight=weight, margin=margin)
        moving = np.zeros(len(self.gid), dtype=bool)
        moving[self.mov] = True
        Xl, it, _ = relax_lbfgs(self.X, self.springs, max_iter=max_iter, tol=PENALTY_TOL, F=self.F, A0=self.A0,
                                flip_weight=FLIP_WEIGHT * LOCAL_FLIP_WEIGHT, area_weights=self.area_weights,
                                extra=term, moving=moving)
        X = X.copy()
        X[self.gid[self.mov]] = Xl[self.mov]
        return X, it


def local_outline(UV, springs: Springs, topo: MeshTopology, rings: int = LOCAL_RINGS, rounds: int = LOCAL_ROUNDS,
                  max_iter: int = LOCAL_ITERS) -> tuple[np.ndarray, int, int]:
    """Local overlap correction of the outline (our addition to 4.5.3).

    Only the vertices within ``rings`` edge rings of the crossing outline edges (and of the
    overlapping triangles) move; everything else stays where it is.  The energy is the one
    of `correct_outline` restricted to them (the springs and triangles touching a moving
    vertex, the flip penalty, the outline penalty of the crossing pairs), with the tension
    and area springs IRLS-weighted as in the length refinement (towards EL, eq. 3-30) so
    that it does not undo that refinement; L-BFGS over the moving vertices only.  Rounds
    double the outline penalty and add the new crossing pairs.
    UV (n,2) -> (UV, iterations, crossings left); UV is returned unchanged unless the
    defects (flipped, crossings) went down."""
    F = topo.F
    E = boundary_edge_array(F)
    pairs = boundary_self_intersections(UV, F)
    if not len(pairs):
        return UV, 0, 0
    mean_len = float(topo.edge_lengths.mean())
    weight = float(np.median(springs.stiffness)) * OUTLINE_WEIGHT
    X = UV.copy()
    cons: set[tuple[int, int]] = set()
    its = 0
    best = ((_flipped(UV, F), len(pairs)), UV)
    for _ in range(rounds):
        _add_constraints(cons, pairs, E)
        cv, ce, L = _constraint_arrays(cons, E, X, mean_len)
        problem = _LocalProblem(topo, springs, X, _moving_vertices(topo, X, cv, ce, rings))
        X, it = problem.solve(X, cv, ce, L, weight, OUTLINE_MARGIN * mean_len, max_iter)
        its += it
        pairs = boundary_self_intersections(X, F)
        flips = _flipped(X, F)
        if (flips, len(pairs)) < best[0]:
            best = ((flips, len(pairs)), X)
        if not len(pairs) and not flips:
            break
        weight *= LOCAL_GROWTH
    (_, crossings), X = best
    return X, its, crossings
