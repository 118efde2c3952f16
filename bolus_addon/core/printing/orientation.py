"""The print orientation search (seed 6.1, eqs. 6-4, 6-7, 6-10, 6-14) and the part's placement.

`orient` minimises WQ + WU (both mm^3, `measures`) over unit build directions b (3,) in four steps:

1. `_screen`: >= 2,048 directions (a Fibonacci sphere, turned by ``rng``) plus special ones
   (+-the mean normals of the largest normal clusters, +-principal axes, directions that stand
   the largest flat regions on edge, +-X, +-Y, +-Z) on a reduced float32 model;
2. `_exact_candidates`: the best 32 distinct screened and the best 8 special directions,
   evaluated exactly (the plate over the convex-hull vertices);
3. `_refine`: a derivative-free shrinking cap search around the best ``starts`` candidates
   (``cap_points`` directions on a cap of 2 x the screening spacing, shrunk 3x until under
   ``tol_deg``), evaluated exactly and cheaply (`PrintTerms.evaluate_near`);
4. `_break_ties`: among the directions within 0.5 % of the best, the lowest print.

``favour`` (optional unit vector): only directions with b . favour >= ``favour_min_cos``.
`place_on_plate` / `rotation_to_z` turn a part to its direction (every part of a model:
`parts.orient_print_parts`); the public names of `measures` and `analysis.curvature` are re-exported.

Design notes: docs/design/printing.md.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..analysis.curvature import NormalCurvature, normal_curvature
from ..errors import BolusError
from .measures import (
    CRITICAL_ANGLE_DEG,
    LAYER_MM,
    PrintObjective,
    PrintTerms,
    check_part,
    check_print_settings,
    cusp_height,
    face_support,
    fibonacci_sphere,
    overhang_faces,
    print_objective,
    surface_quality,
    unit_rows,
)
from ..rng import as_rng
from ..mesh.topology import MeshTopology, check_mesh, submesh

__all__ = [
    "LAYER_MM",
    "CRITICAL_ANGLE_DEG",
    "PrintObjective",
    "Orientation",
    "PrintPlan",
    "PartRow",
    "NormalCurvature",
    "fibonacci_sphere",
    "cusp_height",
    "surface_quality",
    "overhang_faces",
    "face_support",
    "print_objective",
    "normal_curvature",
    "rotation_to_z",
    "place_on_plate",
    "orient",
]

N_SCREEN = 2048  #: screened directions: about 4.5 deg apart, finer than the objective's basins
FACES_PER_BIN = 8  #: faces pooled per normal bin on average in the screening model
BINS_MIN, BINS_MAX = 128, 1024  #: normal bins: enough to resolve 45 deg limits, few enough to be cheap
CANDIDATES = 32  #: best distinct screened directions evaluated exactly (screening is approximate)
SPECIAL_EXACT = 8  #: best special directions always evaluated exactly (flat faces give exact optima)
DISTINCT_SCREEN = 1.5  #: candidates at least this many screening spacings apart (one per basin)
DISTINCT_STARTS = 2.0  #: refined starts at least this many spacings apart (no two starts in one basin)
STARTS = 4  #: refined starts: the best basins found by screening can trade places when evaluated exactly
CAP_RADIUS = 2.0  #: first cap radius in screening spacings: covers the gap between screened directions
CAP_POINTS = 320  #: points of the first cap: about 0.9 deg apart (160 missed a 4.7 % dip on an ICT part)
CAP_SHRINK = 3.0  #: the cap shrinks 3x per level (4x stepped over a 0.3 deg sliver 2.5 deg away: +1.8 %)
LATER_CAP_DIVISOR = 2  #: later caps use half the points (the best point is already close)
MIN_CAP_POINTS = 16  #: never fewer points per later cap
TOL_DEG = 0.1  #: last cap radius: the objective changes by well under 0.1 % over 0.1 deg
DROP_ABOVE = 0.03  #: starts more than 3 % above the best are dropped (never caught up in the tests/bench)
TIE_REL = 5e-3  #: objectives within 0.5 % of the best count as equal; the lowest print wins (SPEC allows 1 %)
TIE_SPECIAL = 4.0 * TIE_REL  #: special directions screened this close to the best are evaluated for the tie
CLUSTER_TOP = 16  #: largest normal bins offered as candidates (the seed's face-normal candidates)
CLUSTER_COHERENT = 0.5  #: a bin whose area vector is under half its area has no direction (normals cancel)
ON_EDGE = 4  #: largest flat regions also stood on edge (b perpendicular to their normal)

_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


def _random_rotation(rng) -> np.ndarray:
    """A uniformly random proper rotation (3,3) drawn from ``rng``."""
    Q, R = np.linalg.qr(as_rng(rng).standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def _tangent_basis(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,), (3,) spanning the tangent plane at the unit vector b (3,)."""
    x, y, z = b
    e1 = np.array([0.0, z, -y]) if abs(x) < 0.9 else np.array([-z, 0.0, x])  # b x X or b x Y
    e1 /= np.sqrt(e1 @ e1)
    return e1, np.array([y * e1[2] - z * e1[1], z * e1[0] - x * e1[2], x * e1[1] - y * e1[0]])


# ----------------------------------------------------------------------- placement


def rotation_to_z(b) -> np.ndarray:
    """The proper rotation R (3,3) with R @ b = +Z (shortest arc; b = -Z turns about X)."""
    b = unit_rows(b)
    flip = np.eye(3)
    if b[2] < -0.5:  # near -Z: first half a turn about X, then the short arc
        flip = np.diag([1.0, -1.0, -1.0])
        b = flip @ b
    v = np.array([b[1], -b[0], 0.0])  # b x Z
    c = b[2]
    K = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    R = np.eye(3) + K + K @ K / (1.0 + c)  # Rodrigues, c > -0.5 here
    return R @ flip


def place_on_plate(V, b) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotate V (n,3) so that b is +Z and lift it to rest on z = 0.

    Returns (V_out (n,3), R (3,3), t (3,)) with V_out = V @ R.T + t.
    """
    V = np.asarray(V, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
        raise BolusError(f"vertices must be a non-empty (n, 3) array, got shape {V.shape}")
    bad = np.nonzero(~np.isfinite(V).all(axis=1))[0]
    if len(bad):
        raise BolusError(f"{len(bad)} vertex(es) with non-finite (NaN or infinite) coordinates, e.g. vertex {bad[0]}")
    R = rotation_to_z(b)
    W = V @ R.T
    t = np.array([0.0, 0.0, -W[:, 2].min()])
    return W + t, R, t


# ----------------------------------------------------------------------- the search


@dataclass
class Orientation:
    """Result of `orient`: the build direction and its exact figures (mm^3)."""

    direction: np.ndarray  #: (3,) unit build direction, up from the plate, in the input frame
    WQ: float  #: eq. 6-7
    WU: float  #: eq. 6-14
    support_volume: float  #: projected area x height of the overhangs
    objective: float  #: WQ + WU
    evaluations: int  #: directions whose objective was evaluated exactly (cap points included)
    screened: int = 0  #: directions screened on the reduced (binned) model
    candidates: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)  #: refined starts

    @property
    def rotation(self) -> np.ndarray:
        """(3,3) rotation taking `direction` to +Z."""
        return rotation_to_z(self.direction)

    def as_dict(self) -> dict:
        return {"direction": [float(x) for x in self.direction], "WQ": self.WQ, "WU": self.WU,
                "support_volume": self.support_volume, "objective": self.objective,
                "evaluations": self.evaluations, "screened": self.screened}


class _Search:
    """The exact objective of one part under the ``favour`` constraint, counting evaluations."""

    def __init__(self, topo: MeshTopology, h: float, cos_c: float, fav, fav_min: float):
        self.exact = PrintTerms.exact(topo)
        self.h, self.cos_c, self.fav, self.fav_min = h, cos_c, fav, fav_min
        self.evaluations = 0

    def allowed(self, B: np.ndarray) -> np.ndarray:
        """(k,) bool: directions B (k,3) the favour constraint allows."""
        return np.ones(len(B), bool) if self.fav is None else B @ self.fav >= self.fav_min - 1e-12

    def objective(self, B: np.ndarray, near=None) -> np.ndarray:
        """WQ + WU (k,) of B (k,3), inf where not allowed; ``near`` = (b, radius) for cap points."""
        ok = self.allowed(B)
        out = np.full(len(B), np.inf)
        if ok.any():
            if near is None:
                WQ, WU, _ = self.exact.evaluate(B[ok], self.h, self.cos_c, support=False)
            else:
                WQ, WU, _ = self.exact.evaluate_near(near[0], B[ok], near[1], self.h, self.cos_c, support=False)
            out[ok] = WQ + WU
            self.evaluations += int(ok.sum())
        return out


def _normal_clusters(N: np.ndarray, A: np.ndarray, bin_of: np.ndarray, nbins: int,
                     top: int = CLUSTER_TOP) -> np.ndarray:
    """Area-weighted mean normals (<= top, 3) of the largest normal bins, largest first."""
    area = np.bincount(bin_of, weights=A, minlength=nbins)
    a = np.stack([np.bincount(bin_of, weights=A * N[:, k], minlength=nbins) for k in range(3)], 1)
    order = np.argsort(-area)[:top]
    order = order[area[order] > 0]
    a = a[order]
    ln = np.linalg.norm(a, axis=1)
    keep = ln > CLUSTER_COHERENT * area[order]
    return a[keep] / ln[keep, None]


def _special_directions(topo: MeshTopology, bin_of: np.ndarray, nbins: int, favour) -> np.ndarray:
    """Candidate directions (s,3) suggested by the geometry (module doc, step 1)."""
    out = [np.eye(3), -np.eye(3)]
    big = _normal_clusters(topo.face_normals, topo.areas, bin_of, nbins)
    out += [big, -big]  # the seed's candidates: the normals of the largest flat regions, both ways
    C = topo.centroids - topo.centroids.mean(axis=0)
    w = topo.areas / topo.areas.sum()
    _, axes = np.linalg.eigh((C * w[:, None]).T @ C)
    out += [axes.T, -axes.T]
    top = big[:ON_EDGE]
    for n in top:  # stand a large flat region on edge: b perpendicular to its normal
        p = axes.T - np.outer(axes.T @ n, n)
        out += [p, -p]
    for i in range(len(top)):
        for j in range(i + 1, len(top)):
            x = np.cross(top[i], top[j])
            out += [x[None], -x[None]]
    if favour is not None:
        out.append(favour[None])
    S = np.concatenate(out)
    S = S[np.linalg.norm(S, axis=1) > 1e-6]
    return S / np.linalg.norm(S, axis=1, keepdims=True)


def _distinct_best(B: np.ndarray, f: np.ndarray, count: int, min_angle: float) -> np.ndarray:
    """Indices of up to ``count`` lowest f (k,) whose directions B (k,3) are >= min_angle apart."""
    cmax = np.cos(min_angle)
    order = np.argsort(f, kind="stable")
    order = order[np.isfinite(f[order])]
    free = np.ones(len(order), dtype=bool)
    Bo = B[order]
    chosen: list[int] = []
    while len(chosen) < count and free.any():
        i = int(np.argmax(free))  # lowest f still free
        chosen.append(int(order[i]))
        free &= Bo @ Bo[i] < cmax
    return np.asarray(chosen, dtype=np.int64)


def _cap_points(b: np.ndarray, radius: float, n: int, turn: float = 0.0) -> np.ndarray:
    """n directions (n,3) evenly spread over the spherical cap of angular ``radius`` around b
    (a Fibonacci disc on the exponential map), turned by ``turn`` radians about b."""
    e1, e2 = _tangent_basis(b)
    i = np.arange(n) + 0.5
    rho = radius * np.sqrt(i / n)
    phi = _GOLDEN_ANGLE * i + turn
    T = np.cos(rho)[:, None] * b + np.sin(rho)[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    return T / np.linalg.norm(T, axis=1, keepdims=True)


@dataclass
class _Screened:
    """Step 1's result: directions B (k,3) (Fibonacci first, then special), their screened
    objective f (k,) (inf where not allowed), how many are Fibonacci, and the grid spacing (rad)."""

    B: np.ndarray
    f: np.ndarray
    n_fib: int
    spacing: float

    @property
    def special(self) -> np.ndarray:
        return self.B[self.n_fib:]


def _screening_model(exact: PrintTerms, bin_of: np.ndarray, nbins: int) -> PrintTerms:
    """Step 1's reduced model in float32: faces pooled by normal bin (bin_of (q,) in 0..nbins-1)
    when there are more than 2 nbins faces (each bin keeps its area, area vector and first
    moment), the plate over the lowest points in max(64, nbins / 2) directions only."""
    H = exact.H
    nh = max(64, nbins // 2)
    if len(H) > nh:
        H = H[np.unique(np.argmin(fibonacci_sphere(nh) @ H.T, axis=1))]
    if len(exact.A) <= 2 * nbins:
        return PrintTerms(exact.A, exact.N, exact.P, H).astype(np.float32)
    A = np.bincount(bin_of, weights=exact.A, minlength=nbins)
    a = np.stack([np.bincount(bin_of, weights=exact.A * exact.N[:, k], minlength=nbins) for k in range(3)], 1)
    P = np.stack([np.bincount(bin_of, weights=exact.P[:, k], minlength=nbins) for k in range(3)], 1)
    keep = A > 0
    A, a, P = A[keep], a[keep], P[keep]
    ln = np.linalg.norm(a, axis=1, keepdims=True)
    N = np.divide(a, ln, out=np.zeros_like(a), where=ln > 0)
    return PrintTerms(A, N, P, H).astype(np.float32)


def _screen(topo: MeshTopology, s: _Search, n_directions: int, rng) -> _Screened:
    """Step 1: the objective of many directions on the binned float32 model (module doc)."""
    from scipy.spatial import cKDTree

    nbins = int(np.clip(topo.m // FACES_PER_BIN, BINS_MIN, BINS_MAX))
    _, bin_of = cKDTree(fibonacci_sphere(nbins)).query(topo.face_normals)
    coarse = _screening_model(s.exact, bin_of, nbins)
    Bfib = fibonacci_sphere(n_directions) @ _random_rotation(rng).T
    B = np.concatenate([Bfib, _special_directions(topo, bin_of, nbins, s.fav)])
    ok = s.allowed(B)
    if s.fav is not None and not ok.any():
        B, ok = np.concatenate([B, s.fav[None]]), np.r_[ok, True]
    f = np.full(len(B), np.inf)
    WQ, WU, _ = coarse.evaluate(B[ok], s.h, s.cos_c, support=False)
    f[ok] = WQ + WU
    return _Screened(B, f, len(Bfib), float(np.sqrt(4.0 * np.pi / n_directions)))


def _exact_candidates(sc: _Screened, s: _Search, candidates: int) -> tuple[np.ndarray, np.ndarray]:
    """Step 2: the best distinct screened and special directions (c,3) and their exact objective (c,)."""
    pick = _distinct_best(sc.B, sc.f, candidates, DISTINCT_SCREEN * sc.spacing)
    sp_idx = sc.n_fib + _distinct_best(sc.special, sc.f[sc.n_fib:], SPECIAL_EXACT, 1e-3)
    Bc = sc.B[np.unique(np.r_[pick, sp_idx])]
    return Bc, s.objective(Bc)


def _refine(s: _Search, starts: list, radius: float, tol: float, cap_points: int, drop_above: float):
    """Step 3: shrinking cap search from ``starts`` [(b (3,), f)], all starts level by level.

    Returns (best b (3,), best f, the surviving starts [(b, f)])."""
    i = int(np.argmin([f for _, f in starts]))
    best_b, best_f = starts[i][0].copy(), float(starts[i][1])
    cur, level = starts, 0
    while cur and radius >= tol:
        n = cap_points if level == 0 else max(MIN_CAP_POINTS, cap_points // LATER_CAP_DIVISOR)
        nxt = []
        for b, fb in cur:
            T = _cap_points(b, radius, n, level * _GOLDEN_ANGLE)
            ft = s.objective(T, near=(b, radius))
            j = int(np.argmin(ft))
            if ft[j] < fb:
                b, fb = T[j], float(ft[j])
            if fb < best_f:
                best_f, best_b = fb, b.copy()
            nxt.append((b, fb))
        cur = [(b, fb) for b, fb in nxt if fb <= best_f * (1.0 + drop_above) + 1e-12]
        radius /= CAP_SHRINK
        level += 1
    return best_b, best_f, cur


def _break_ties(s: _Search, pool_b: np.ndarray, pool_f: np.ndarray, best_b: np.ndarray, best_f: float) -> np.ndarray:
    """Step 4: among pool_b (k,3) with pool_f (k,) within TIE_REL of best_f, the lowest print (3,)."""
    tie = np.isfinite(pool_f) & (pool_f <= best_f * (1.0 + TIE_REL) + 1e-12)
    if tie.sum() <= 1:
        return best_b
    proj = s.exact.H @ pool_b[tie].T  # hull vertices: the height is translation invariant
    height = proj.max(axis=0) - proj.min(axis=0)
    return pool_b[tie][int(np.argmin(height))].copy()


def orient(
    V,
    F,
    h: float = LAYER_MM,
    critical_angle_deg: float = CRITICAL_ANGLE_DEG,
    favour=None,
    favour_min_cos: float = 0.0,
    n_directions: int = N_SCREEN,
    starts: int = STARTS,
    cap_points: int = CAP_POINTS,
    cap_radius: float = CAP_RADIUS,
    candidates: int = CANDIDATES,
    tol_deg: float = TOL_DEG,
    drop_above: float = DROP_ABOVE,
    rng=0,
    topo: MeshTopology | None = None,
    progress=None,
) -> Orientation:
    """The build direction b minimising WQ + WU (eqs. 6-7, 6-14) of a part (module doc, steps 1-4).

    Parameters: V (n,3) mm, F (m,3) int; ``favour`` (3,) or None: directions with
    b . favour < ``favour_min_cos`` are not allowed; ``rng`` turns the Fibonacci sphere;
    ``topo`` a `MeshTopology` of (V, F) already built.  The search settings are the
    module's named constants.  Returns an `Orientation` (direction (3,), exact figures).
    """
    report = progress or (lambda f, t: None)
    topo = check_part(V, F, topo)
    h, cos_c = check_print_settings(h, critical_angle_deg)
    fav = None if favour is None else unit_rows(favour, "favoured direction")
    if fav is not None and not -1.0 <= favour_min_cos < 1.0:
        raise BolusError(f"favour_min_cos must lie in [-1, 1), got {favour_min_cos}")
    s = _Search(topo, h, cos_c, fav, favour_min_cos)
    report(0.05, "screening directions")
    sc = _screen(topo, s, max(int(n_directions), 16), rng)
    report(0.3, "evaluating candidates")
    Bc, fc = _exact_candidates(sc, s, candidates)
    report(0.5, "refining")
    sel = _distinct_best(Bc, fc, max(1, int(starts)), DISTINCT_STARTS * sc.spacing)
    if not len(sel):
        raise BolusError("no allowed build direction: the favoured side cannot be kept off the plate")
    best_b, best_f, cur = _refine(s, [(Bc[i].copy(), float(fc[i])) for i in sel], cap_radius * sc.spacing,
                                  np.radians(tol_deg), cap_points, drop_above)
    report(0.95, "figures")
    # special directions are few and may have been screened out as equals: those whose
    # screened value is near the best are evaluated exactly for the tie too
    near_sp = sc.special[sc.f[sc.n_fib:] <= best_f * (1.0 + TIE_SPECIAL) + 1e-12]
    pool_b = np.vstack([Bc, near_sp, best_b[None]] + [b[None] for b, _ in cur])
    pool_f = np.r_[fc, s.objective(near_sp), best_f, [fb for _, fb in cur]]
    best_b = _break_ties(s, pool_b, pool_f, best_b, best_f)
    WQ, WU, SV = s.exact.evaluate(best_b[None], h, cos_c)
    report(1.0, "done")
    return Orientation(best_b, float(WQ[0]), float(WU[0]), float(SV[0]), float(WQ[0] + WU[0]),
                       s.evaluations + 1, int(np.isfinite(sc.f).sum()), Bc[sel])
