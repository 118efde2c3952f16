"""Unfolding a patch into a true-scale flat pattern (seed 3.5, 4.5; eqs. 3-22..3-31, 4-22..4-25).

Pipeline of `unfold_patch` for one disk-like patch, V (n,3) mm, F (m,3):

1. start: `conformal_unfolding` (default, see below) or `initial_unfolding` (4.5.1): vertex labels by breadth-first layers from the
   boundary; the central triangle has the largest label sum; it is laid flat without
   deformation, then the *central triangle crossing*: the main stripe (of several
   directions through the central triangle's centroid, the one crossing most triangles)
   and its perpendicular are unfolded edge to edge without deformation; then the
   adjacent crossings layer by layer: every triangle with an unfolded edge gets its
   third vertex from two angles and that edge, the angles rescaled at interior vertices
   so that they sum to 2 pi (eq. 4-24), on the side away from the unfolded neighbour.
2. relaxation of the mass-spring model with crossed springs (3.5): tension springs on
   the edges (rest length: the 3D edge, eq. 3-22), crossed springs between the two
   vertices opposite every interior edge, and disturbing springs on the boundary
   (4.5.2, eq. 4-25).  Total energy E = sum 1/2 c (|Q_i Q_j| - D_ij)^2 (eqs. 3-28, 3-29).
   Two minimisers of the same energy: `relax_explicit`, the seed's explicit Euler
   integration with masses of eq. 3-24 (eqs. 3-23, 3-25..3-27), and `relax_lbfgs`, a
   quasi-Newton minimiser (scipy L-BFGS) with the exact gradient.  L-BFGS is the
   default: it reaches a lower energy in a fraction of the time (bench/unfold_bench.py).
3. length refinement (our addition): EL (eq. 3-30) sums *absolute* length errors
   while the spring energy sums squares; a few rounds of iteratively reweighted least
   squares on the tension springs (`refine_lengths_l1`) minimise EL itself.  On a 60
   degree cap (20k triangles) EL goes from 3.99 % to 3.56 %, EA from 4.62 % to 2.44 %
   (Blender's SLIM at 100 iterations: 4.05 % / 6.86 %).  ``refine_rounds=0`` switches it off.
4. overlap correction (4.5.3): flipped triangles are pushed back by a penalty on
   negative signed area and the energy minimised again; remaining flips and outline
   crossings (overlap.py) are counted and reported.

Speed on big and hard patches (issue 9; what changed and why, measured in
bench/unfold_bench.py against Blender's SLIM):
- the default start (``start="auto"``) is the least-squares conformal map (one sparse
  solve).  The seed's coordinate transformation of 4.5.1 (``start="greedy"``) reaches
  the same minimum where it does not fold, but folded over on 6 of 8 scanned nose
  patches (then the conformal map was needed anyway) and costs seconds of Python on
  20k-triangle patches;
- the relaxation runs with the flip penalty on from its first step (the start has no
  flipped triangle): a nostril pocket otherwise folds flat, and unfolding the fold took
  minutes of penalty rounds;
- every minimisation has an iteration budget and a stop test (`RELAX_ITERS`,
  `FLIP_ITERS`, `OUTLINE_ROUNDS` x `OUTLINE_ITERS`, `PENALTY_TOL`); the outline
  correction stops when the defects stop going down, and keeps the best pattern;
- hopeless patches (EL > `HOPELESS_EL` or EA > `HOPELESS_EA` after relaxation and
  refinement) skip the outline correction and come back at once with
  ``Unfolding.hopeless`` and the figures (angle deficit / excess, eq. 4-1);
- outline crossings are first corrected locally (`_local_outline`): only the vertices
  within `LOCAL_RINGS` rings of the crossing outline edges move, with the tension and
  area springs weighted as in the length refinement, so the refined pattern elsewhere is
  kept as it is; the whole-patch `_correct_outline` runs only when that fails, and the
  local correction once more after it.  On the scanned nose patches the whole-patch
  correction left 4 overlapping triangles (nose p1, p2), 2 on the nostril middle and 12
  on the 43k face region; with the local one none, and nose p1 went from 2.7x to 1.7x the
  time of SLIM-100 (EL 3.75 -> 3.90 %, EA 5.89 -> 6.19 %: the outline opened up);
- progress(fraction, text) is called at every stage and about every 0.5 s inside.

A patch that is not a topological disk is cut to one first (cutting.py).

Choices where the seed is vague (stated here and in the code):
- spring stiffness c = 1 / D (Hooke's law for a uniform sheet: stiffness inversely
  proportional to rest length), so the energy does not favour long edges; crossed
  springs are CROSSED_WEIGHT = 3 times stiffer (on a 60 degree cap this lowers the
  area error EA from 5.7 % to 3.6 % for +0.2 % of length error EL; the seed gives no
  ratio);
- crossed spring rest length = the distance between the two opposite vertices when
  the two triangles are rotated into one plane about their common edge (the length
  the pair has in a perfect flattening; the 3D chord would pull folds shut);
- disturbing springs (blue "contour" springs of Fig. 4-17): over every window of
  `CONTOUR_WINDOW` consecutive boundary edges, 1/2 c (sum |Q| - sum D)^2 with
  c = 1 / sum D (eq. 4-25), which keeps the outline's length right piece by piece.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize
from scipy.sparse.csgraph import dijkstra

from .cutting import cut_to_disk
from .errors import BolusError
from .geometry2d import cross2d
from .layout import pack_islands
from .overlap import boundary_edge_array, boundary_self_intersections, overlapping_faces, signed_areas
from .topology import MeshTopology

__all__ = [
    "Springs",
    "Unfolding",
    "build_springs",
    "spring_energy",
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
]

CONTOUR_WINDOW = 8
CROSSED_WEIGHT = 3.0
RELAX_LAYER_ITERS = 10
AREA_BALANCE = 0.25
OUTLINE_WEIGHT = 10.0
METHODS = ("lbfgs", "explicit")
STRIPE_DIRECTIONS = 12
STRIPE_TIES = 3


# --------------------------------------------------------------------------- measures
def length_area_errors(V: np.ndarray, F: np.ndarray, UV: np.ndarray) -> tuple[float, float]:
    """EL and EA of eqs. 3-30, 3-31 as SPEC measures them (no scale fitted).

    EL = sum |L - L0| / sum L0 over the three edges of every triangle;
    EA = sum |A - A0| / sum A0 with A the *signed* 2D area (a flipped face counts fully).
    """
    L0 = np.concatenate([np.linalg.norm(V[F[:, k]] - V[F[:, (k + 1) % 3]], axis=1) for k in range(3)])
    L = np.concatenate([np.linalg.norm(UV[F[:, k]] - UV[F[:, (k + 1) % 3]], axis=1) for k in range(3)])
    A0 = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    A = signed_areas(UV, F)
    return float(np.abs(L - L0).sum() / L0.sum()), float(np.abs(A - A0).sum() / A0.sum())


def _fanned(V_src, corners_src, V_pat, corners_pat, sizes):
    """Matching polygons fanned from their first corner: (tri_poly (t,), L0 (t,3), L (t,3), A0 (t,), A (t,))."""
    from .topology import triangulate_polygons

    Fs, tri_poly = triangulate_polygons(corners_src, sizes)
    Fp, _ = triangulate_polygons(corners_pat, sizes)
    V_src = np.asarray(V_src, dtype=np.float64)
    P = np.asarray(V_pat, dtype=np.float64)[:, :2]
    L0 = np.stack([np.linalg.norm(V_src[Fs[:, k]] - V_src[Fs[:, (k + 1) % 3]], axis=1) for k in range(3)], 1)
    L = np.stack([np.linalg.norm(P[Fp[:, k]] - P[Fp[:, (k + 1) % 3]], axis=1) for k in range(3)], 1)
    A0 = 0.5 * np.linalg.norm(np.cross(V_src[Fs[:, 1]] - V_src[Fs[:, 0]], V_src[Fs[:, 2]] - V_src[Fs[:, 0]]), axis=1)
    return tri_poly, L0, L, A0, signed_areas(P, Fp)


def polygon_errors(V_src: np.ndarray, corners_src: np.ndarray, V_pat: np.ndarray, corners_pat: np.ndarray,
                   sizes: np.ndarray, groups: np.ndarray | None = None) -> dict:
    """EL and EA exactly as SPEC measures a pattern against its source, per group.

    V_src (n,3) and V_pat (k,2 or 3) in the same unit; corners_* (c,) the corner
    vertices of matching polygons (same order, same sizes (p,)); every polygon is fanned
    from its first corner; groups (p,) optional labels (e.g. patches).
    Returns {group: (EL, EA, flipped)} and the key None for all polygons together.
    """
    tri_poly, L0, L, A0, A = _fanned(V_src, corners_src, V_pat, corners_pat, sizes)
    out = {}
    g = np.zeros(len(sizes), dtype=np.int64) if groups is None else np.asarray(groups)
    tg = g[tri_poly]
    for key in [None, *np.unique(tg).tolist()]:
        sel = np.ones(len(tg), dtype=bool) if key is None else tg == key
        el = float(np.abs(L[sel] - L0[sel]).sum() / L0[sel].sum())
        ea = float(np.abs(A[sel] - A0[sel]).sum() / A0[sel].sum())
        out[key] = (el, ea, int(np.count_nonzero(A[sel] <= 0)))
    return out


def polygon_area_error(V_src, corners_src, V_pat, corners_pat, sizes) -> np.ndarray:
    """A / A0 - 1 (p,) of every pattern polygon against its source polygon (signed area)."""
    tri_poly, _, _, A0, A = _fanned(V_src, corners_src, V_pat, corners_pat, sizes)
    a0 = np.bincount(tri_poly, A0, minlength=len(sizes))
    return np.bincount(tri_poly, A, minlength=len(sizes)) / np.maximum(a0, 1e-300) - 1.0


# --------------------------------------------------------------------------- springs
@dataclass
class Springs:
    """All springs of the model: endpoints (s,2), rest lengths (s,), stiffness (s,).

    The first `n_tension` springs are the edges, then the crossed springs.  Contour
    (disturbing) springs act on paths and are kept apart: `contour_edges` (w,W) holds
    the spring indices of the W boundary edges of each window, `contour_rest` (w,).
    """

    ends: np.ndarray
    rest: np.ndarray
    stiffness: np.ndarray
    n_tension: int
    contour_edges: np.ndarray
    contour_rest: np.ndarray
    contour_stiffness: np.ndarray

    def incidence(self, n: int):
        """Sparse (s,n) matrix B with B @ Q = Q[p] - Q[q] (cached per n)."""
        return self._incidence_pair(n)[0]

    def _incidence_pair(self, n: int):
        """(B, B^T) as CSR matrices, cached per n (B^T @ g scatters spring forces to vertices)."""
        cache = self.__dict__.setdefault("_incidence", {})
        if n not in cache:
            import scipy.sparse as sp

            s = len(self.ends)
            rows = np.r_[np.arange(s), np.arange(s)]
            B = sp.csr_matrix((np.r_[np.ones(s), -np.ones(s)], (rows, self.ends.T.ravel())), shape=(s, n))
            cache[n] = (B, B.T.tocsr())
        return cache[n]


def _hinge_distance(V: np.ndarray, i, j, a, b) -> np.ndarray:
    """Distance a-b after unfolding triangles (i,j,a) and (j,i,b) into one plane."""
    L = np.linalg.norm(V[j] - V[i], axis=1)
    da_i = np.sum((V[a] - V[i]) ** 2, axis=1)
    da_j = np.sum((V[a] - V[j]) ** 2, axis=1)
    db_i = np.sum((V[b] - V[i]) ** 2, axis=1)
    db_j = np.sum((V[b] - V[j]) ** 2, axis=1)
    xa = (da_i - da_j + L**2) / (2 * L)
    xb = (db_i - db_j + L**2) / (2 * L)
    ha = np.sqrt(np.maximum(da_i - xa**2, 0.0))
    hb = np.sqrt(np.maximum(db_i - xb**2, 0.0))
    return np.sqrt((xa - xb) ** 2 + (ha + hb) ** 2)


def build_springs(topo: MeshTopology, contour_window: int = CONTOUR_WINDOW, crossed: bool = True) -> Springs:
    """Tension, crossed and disturbing springs of a patch (3.5, 4.5.2)."""
    V, F = topo.V, topo.F
    E = topo.edges
    rest_t = topo.edge_lengths
    ends = [E]
    rest = [rest_t]
    if crossed:
        inner = np.nonzero(topo.edge_face_count == 2)[0]
        f0, f1 = topo.edge_faces[inner, 0], topo.edge_faces[inner, 1]
        i, j = E[inner, 0], E[inner, 1]
        # opposite vertex of each face: the corner that is neither i nor j
        def opposite(f):
            tri = F[f]
            mask = (tri != i[:, None]) & (tri != j[:, None])
            return tri[np.arange(len(f)), np.argmax(mask, axis=1)]

        a, b = opposite(f0), opposite(f1)
        ends.append(np.stack([a, b], axis=1))
        rest.append(_hinge_distance(V, i, j, a, b))
    ends = np.concatenate(ends).astype(np.int64)
    rest = np.concatenate(rest)
    stiffness = 1.0 / np.maximum(rest, 1e-12 * max(rest.max(), 1.0))
    stiffness[len(E):] *= CROSSED_WEIGHT
    # disturbing (contour) springs over windows of boundary edges
    bidx = np.nonzero(topo.boundary_edges)[0]
    windows = []
    if contour_window >= 2 and len(bidx) > contour_window:
        loops = _boundary_edge_loops(topo)
        for loop in loops:
            if len(loop) <= contour_window:
                continue
            k = np.arange(len(loop))
            win = loop[(k[:, None] + np.arange(contour_window)[None, :]) % len(loop)]
            windows.append(win)
    if windows:
        cw = np.concatenate(windows)
        crest = rest_t[cw].sum(axis=1)
    else:
        cw = np.zeros((0, max(contour_window, 1)), dtype=np.int64)
        crest = np.zeros(0)
    return Springs(ends, rest, stiffness, len(E), cw, crest, 1.0 / np.maximum(crest, 1e-300))


def _boundary_edge_loops(topo: MeshTopology) -> list[np.ndarray]:
    """Boundary edges (indices into topo.edges) grouped into loops, in walking order."""
    E = topo.edges
    bidx = np.nonzero(topo.boundary_edges)[0]
    if len(bidx) == 0:
        return []
    # next edge: boundary edges sharing a vertex; walk with a vertex -> edges map
    from collections import defaultdict

    at = defaultdict(list)
    for e in bidx.tolist():
        at[int(E[e, 0])].append(e)
        at[int(E[e, 1])].append(e)
    seen = set()
    loops = []
    for start in bidx.tolist():
        if start in seen:
            continue
        loop = [start]
        seen.add(start)
        v = int(E[start, 1])
        cur = start
        while True:
            nxt = [e for e in at[v] if e != cur and e not in seen]
            if not nxt:
                break
            cur = nxt[0]
            seen.add(cur)
            loop.append(cur)
            v = int(E[cur, 0]) if int(E[cur, 1]) == v else int(E[cur, 1])
        loops.append(np.asarray(loop, dtype=np.int64))
    return loops


def spring_energy(x: np.ndarray, springs: Springs, n: int) -> tuple[float, np.ndarray]:
    """Total energy (eqs. 3-28, 3-29, plus eq. 4-25) and its gradient (2n,) at x = UV.ravel()."""
    Q = x.reshape(n, 2)
    B, BT = springs._incidence_pair(n)
    d = B @ Q  # Q[p] - Q[q] for every spring, as one sparse product
    ell = np.sqrt(np.einsum("ij,ij->i", d, d))
    ell_safe = np.maximum(ell, 1e-300)
    stretch = ell - springs.rest
    energy = 0.5 * float(np.dot(springs.stiffness, stretch * stretch))
    g = (springs.stiffness * stretch / ell_safe)[:, None] * d  # force on p is -g (eq. 3-22)
    if len(springs.contour_rest):
        W = springs.contour_edges
        ell_t = ell[: springs.n_tension]
        s = ell_t[W].sum(axis=1) - springs.contour_rest
        energy += 0.5 * float(np.dot(springs.contour_stiffness, s * s))
        # each contour window adds c*s*d(ell_e)/dx to the edges it spans
        coef = np.bincount(W.ravel(), np.repeat(springs.contour_stiffness * s, W.shape[1]), minlength=springs.n_tension)
        g[: springs.n_tension] += (coef / ell_safe[: springs.n_tension])[:, None] * d[: springs.n_tension]
    return energy, np.asarray(BT @ g).ravel()


def _area_gradient(Q: np.ndarray, F: np.ndarray, coef: np.ndarray, n: int, abc=None) -> np.ndarray:
    """sum_t coef_t dA_t/dQ (2n,) for signed areas A_t of triangles F (m,3)."""
    a, b, c = (Q[F[:, 0]], Q[F[:, 1]], Q[F[:, 2]]) if abc is None else abc
    # dA/dv for the corner v of a counter-clockwise triangle (v, p, q) = 0.5 (p_y - q_y, q_x - p_x)
    h = 0.5 * coef
    corners = F.T.ravel()
    grad = np.empty((n, 2))
    grad[:, 0] = np.bincount(corners, np.concatenate([h * (b[:, 1] - c[:, 1]), h * (c[:, 1] - a[:, 1]),
                                                      h * (a[:, 1] - b[:, 1])]), minlength=n)
    grad[:, 1] = np.bincount(corners, np.concatenate([h * (c[:, 0] - b[:, 0]), h * (a[:, 0] - c[:, 0]),
                                                      h * (b[:, 0] - a[:, 0])]), minlength=n)
    return grad.ravel()


def area_terms(x: np.ndarray, F: np.ndarray, A0: np.ndarray, n: int, flip_weight: float = 0.0,
               area_weights: np.ndarray | None = None, frac: float = 0.05,
               mean_A0: float | None = None) -> tuple[float, np.ndarray]:
    """Energy terms on the signed areas A_t of the triangles, and their gradient (2n,).

    flip penalty (overlap correction, 4.5.3): 1/2 w sum max(0, frac A0 - A)^2 / mean(A0),
    zero until a triangle is about to turn over;
    area springs (length refinement): 1/2 sum a_t (A_t - A0_t)^2.
    """
    Q = x.reshape(n, 2)
    a, b, c = Q[F[:, 0]], Q[F[:, 1]], Q[F[:, 2]]
    A = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    e = 0.0
    coef = np.zeros(len(F))
    if flip_weight > 0:
        short = np.maximum(frac * A0 - A, 0.0)
        mA = float(np.mean(A0)) if mean_A0 is None else mean_A0
        e += 0.5 * flip_weight * float(np.dot(short, short)) / mA
        coef -= flip_weight * short / mA
    if area_weights is not None:
        r = A - A0
        e += 0.5 * float(np.dot(area_weights, r * r))
        coef += area_weights * r
    if not coef.any():
        return e, np.zeros(2 * n)
    return e, _area_gradient(Q, F, coef, n, (a, b, c))


# --------------------------------------------------------------------------- minimisers
def stiffness_laplacian(springs: Springs, n: int):
    """K (n,n) = sum_s c_s (e_p - e_q)(e_p - e_q)^T: the springs' Hessian at rest, per coordinate."""
    import scipy.sparse as sp

    p, q = springs.ends[:, 0], springs.ends[:, 1]
    c = springs.stiffness
    K = sp.coo_matrix((np.r_[-c, -c], (np.r_[p, q], np.r_[q, p])), shape=(n, n)).tocsr()
    K = K - sp.diags(np.asarray(K.sum(axis=1)).ravel())
    return K.tocsc()


STOP_EVERY = 25


def _factor_cache(springs: Springs, n: int):
    """Factorisation of K + eps I (`stiffness_laplacian`), cached on ``springs`` for its current stiffness."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    key = (n, hash(springs.stiffness.tobytes()), hash(springs.ends.tobytes()))
    cache = springs.__dict__.setdefault("_factor", {})
    if key not in cache:
        K = stiffness_laplacian(springs, n)
        eps = 1e-8 * float(np.abs(K.diagonal()).mean())
        Keps = (K + eps * sp.identity(n, format="csc")).tocsc()
        # symmetric positive definite: symmetric ordering, no pivoting (15x faster than default)
        lu = splu(Keps, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        cache.clear()  # one stiffness at a time (refinement changes it every round)
        cache[key] = (lu, Keps.tocsr())
    return cache[key]


def relax_lbfgs(UV0, springs: Springs, max_iter: int = 2000, tol: float = 1e-9, F=None, A0=None,
                flip_weight: float = 0.0, callback=None, memory: int = 8,
                precondition: bool = True, area_weights=None, extra=None, progress=None,
                stop=None, moving=None) -> tuple[np.ndarray, int, float]:
    """Minimise the spring energy with L-BFGS (two-loop recursion) from UV0 (n,2).

    The initial inverse Hessian of the recursion is gamma K^-1, K the springs' Hessian
    at rest (`stiffness_laplacian`, factorised once per stiffness and cached on the
    springs): a Sobolev preconditioner that makes the iteration count almost independent
    of the mesh resolution (plain L-BFGS needs thousands of iterations on a 20k-triangle
    cap).  Armijo backtracking line search with a quadratic step estimate (penalty
    terms make the plain halving take ~7 evaluations per iteration).  Stops when the
    energy decreased by less than tol * E over 5 iterations, after max_iter
    iterations, or when stop(UV, it) is true (asked every `STOP_EVERY` iterations).
    progress(fraction of max_iter) is called about every 0.5 s.  moving (n,) bool: only
    these vertices move (the gradient of the others is zeroed; needs precondition=False).
    Returns (UV, iterations, energy).
    """
    n = len(UV0)
    x = np.asarray(UV0, dtype=np.float64).copy()
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

    if precondition and moving is not None:
        # the preconditioner of the moving vertices alone (the others are held: Dirichlet)
        import scipy.sparse as sp
        from scipy.sparse.linalg import splu

        mi = np.nonzero(moving)[0]
        Kmm = stiffness_laplacian(springs, n)[mi][:, mi].tocsc()
        Kmm = Kmm + 1e-8 * float(np.abs(Kmm.diagonal()).mean()) * sp.identity(len(mi), format="csc")
        lu_m = splu(Kmm.tocsc())
        Kcsr = stiffness_laplacian(springs, n).tocsr()

        def apply_h0(v):
            out = np.zeros_like(v)
            out[mi] = lu_m.solve(v[mi])
            return out

        def apply_k(v):
            return Kcsr @ v
    elif precondition:
        lu, Kcsr = _factor_cache(springs, n)
        apply_h0 = lu.solve

        def apply_k(v):
            return Kcsr @ v
    else:
        def apply_h0(v):
            return v

        apply_k = apply_h0

    e, g = fun(x)
    S: list[np.ndarray] = []
    Y: list[np.ndarray] = []
    history = [e]
    it = 0
    t_report = time.perf_counter() + 0.5
    for it in range(1, max_iter + 1):
        # two-loop recursion with H0 = gamma K^-1
        q = g.copy()
        alphas = []
        for s_, y_ in zip(reversed(S), reversed(Y)):
            rho = 1.0 / np.vdot(y_, s_)
            a_ = rho * np.vdot(s_, q)
            alphas.append((a_, rho))
            q -= a_ * y_
        r = apply_h0(q)
        if S:  # scale H0: y ~ (1/gamma) K s  =>  gamma = s.K s / s.y (a matvec, no solve)
            r *= np.vdot(S[-1], apply_k(S[-1])) / max(np.vdot(S[-1], Y[-1]), 1e-300)
        for (a_, rho), s_, y_ in zip(reversed(alphas), S, Y):
            b_ = rho * np.vdot(y_, r)
            r += (a_ - b_) * s_
        d = -r
        slope = float(np.vdot(g, d))
        if not slope < 0:
            S.clear()
            Y.clear()
            d = -apply_h0(g)
            slope = float(np.vdot(g, d))
            if not slope < 0:
                break
        t = 1.0
        for _ in range(40):
            xn = x + t * d
            en, gn = fun(xn)
            if en <= e + 1e-4 * t * slope:
                break
            # minimiser of the quadratic through e, slope and en, kept within [0.1 t, 0.5 t]
            denom = 2.0 * (en - e - slope * t)
            t_q = -slope * t * t / denom if denom > 0 and np.isfinite(en) else 0.1 * t
            t = min(max(t_q, 0.1 * t), 0.5 * t)
        else:
            break
        s_, y_ = xn - x, gn - g
        if np.vdot(s_, y_) > 1e-16 * max(np.vdot(s_, s_), 1e-300):
            S.append(s_)
            Y.append(y_)
            if len(S) > memory:
                S.pop(0)
                Y.pop(0)
        x, e, g = xn, en, gn
        history.append(e)
        if callback is not None:
            callback(x)
        if len(history) > 5 and history[-6] - e <= tol * max(e, 1e-300):
            break
        if e <= 1e-28:
            break
        if stop is not None and it % STOP_EVERY == 0 and stop(x, it):
            break
        if progress is not None:
            now = time.perf_counter()
            if now >= t_report:
                progress(it / max_iter)
                t_report = now + 0.5
    return x, it, float(e)


def relax_explicit(UV0, springs: Springs, masses: np.ndarray, max_iter: int = 20000, damping: float = 0.05,
                   tol: float = 1e-10, callback=None, progress=None) -> tuple[np.ndarray, int, float]:
    """The seed's explicit integration (eqs. 3-23..3-27) with masses m_i (eq. 3-24).

    v(t+dt) = v + dt a,  x(t+dt) = x + dt v + dt^2/2 a,  a = f / m (eq. 3-25).
    The seed gives no damping; without it the springs oscillate for ever, so the
    velocity is multiplied by (1 - damping) each step.  The step is the largest stable
    one for the stiffest spring (dt = 0.5 sqrt(m_min / (c_max * degree))).
    Stops when the relative energy change over 100 steps falls below tol.
    progress(fraction of max_iter) is called about every 0.5 s.
    """
    n = len(UV0)
    x = np.asarray(UV0, dtype=np.float64).ravel().copy()
    v = np.zeros_like(x)
    m2 = np.repeat(np.maximum(masses, 1e-300), 2)
    deg = np.bincount(springs.ends.ravel(), minlength=n).max()
    dt = 0.5 * np.sqrt(masses.min() / (springs.stiffness.max() * max(deg, 1)))
    e_prev, _ = spring_energy(x, springs, n)
    it = 0
    t_report = time.perf_counter() + 0.5
    for it in range(1, max_iter + 1):
        e, grad = spring_energy(x, springs, n)
        a = -grad / m2
        x += dt * v + 0.5 * dt * dt * a
        v = (1.0 - damping) * (v + dt * a)
        if it % 100 == 0:
            if callback is not None:
                callback(x)
            if progress is not None and time.perf_counter() >= t_report:
                progress(it / max_iter)
                t_report = time.perf_counter() + 0.5
            if abs(e_prev - e) <= tol * max(e, 1e-300) or e < 1e-24:
                break
            e_prev = e
    e, _ = spring_energy(x, springs, n)
    return x.reshape(n, 2), it, float(e)


# --------------------------------------------------------------------------- initial unfolding
def _rot(u: np.ndarray, ang: np.ndarray) -> np.ndarray:
    c, s = np.cos(ang), np.sin(ang)
    return np.stack([c * u[:, 0] - s * u[:, 1], s * u[:, 0] + c * u[:, 1]], axis=1)


def _place_third(Pi, Pj, beta_i, beta_j, away_from):
    """Third vertex of triangles on edges Pi->Pj (k,2) with angles beta at i and j (law of sines),
    on the side of the edge opposite to the points ``away_from`` (k,2)."""
    e = Pj - Pi
    l1 = np.linalg.norm(e, axis=1)
    u = e / np.maximum(l1, 1e-300)[:, None]
    s = np.sin(np.clip(beta_i + beta_j, 1e-9, np.pi - 1e-9))
    r = l1 * np.sin(beta_j) / s
    side_ref = np.sign(cross2d(u, away_from - Pi))
    side_ref[side_ref == 0] = -1.0
    ang = -side_ref * beta_i  # rotate u towards the side away from the reference
    return Pi + r[:, None] * _rot(u, ang)


def _place_at(Pi, Pj, beta_i, length, away_from):
    """Point at ``length`` from Pi, at angle beta_i from the direction Pi->Pj, on the side
    of the line away from ``away_from`` (all (k,2) / (k,))."""
    e = Pj - Pi
    u = e / np.maximum(np.linalg.norm(e, axis=1), 1e-300)[:, None]
    side_ref = np.sign(cross2d(u, away_from - Pi))
    side_ref[side_ref == 0] = -1.0
    return Pi + length[:, None] * _rot(u, -side_ref * beta_i)


def _sub_springs(springs: Springs, keep_vertex: np.ndarray) -> tuple[Springs, np.ndarray]:
    """The springs between kept vertices, re-indexed; returns (springs, kept vertex ids)."""
    ids = np.nonzero(keep_vertex)[0]
    local = np.full(len(keep_vertex), -1, dtype=np.int64)
    local[ids] = np.arange(len(ids))
    sel = keep_vertex[springs.ends].all(axis=1)
    ntension = int(sel[: springs.n_tension].sum())
    empty = np.zeros((0, springs.contour_edges.shape[1]), dtype=np.int64)
    sub = Springs(local[springs.ends[sel]], springs.rest[sel], springs.stiffness[sel], ntension, empty,
                  np.zeros(0), np.zeros(0))
    return sub, ids


def initial_unfolding(topo: MeshTopology, directions: int = STRIPE_DIRECTIONS,
                      springs: Springs | None = None) -> np.ndarray:
    """Initial 2D positions UV (n,2) of a disk-like patch by the coordinate transformation of 4.5.1.

    With ``springs``, the part unfolded so far is relaxed by the mass-spring model each
    time it has doubled (the seed's second overlap-prevention method, 4.5.3:
    "optimize unfolded triangles after unfolding each adjacent triangle crossing"), so
    that errors do not pile up into folds on large patches.
    """
    V, F, n, m = topo.V, topo.F, topo.n, topo.m
    alpha = topo.angles  # (m,3) 3D inner angles
    # labels: breadth-first layers from the boundary (0 on the boundary)
    bverts = np.nonzero(topo.boundary_vertices)[0]
    if len(bverts):
        lab = dijkstra(topo.vertex_adjacency, directed=False, indices=bverts, unweighted=True, min_only=True)
        lab[~np.isfinite(lab)] = 0
    else:
        lab = np.zeros(n)
    fsum = lab[F].sum(axis=1)
    best = np.nonzero(fsum == fsum.max())[0]
    UV = np.full((n, 2), np.nan)
    placed_face = np.zeros(m, dtype=bool)

    def place_central(f):
        i, j, k = F[f]
        Lij = np.linalg.norm(V[j] - V[i])
        out = {i: np.array([0.0, 0.0]), j: np.array([Lij, 0.0])}
        out[k] = _place_third(np.array([[0.0, 0.0]]), np.array([[Lij, 0.0]]), np.array([alpha[f, 0]]),
                              np.array([alpha[f, 1]]), np.array([[0.0, -1.0]]))[0]
        return out

    # central triangle crossing: stripes through the central triangle's centroid
    import math

    Fl = F.tolist()
    face_edges = topo.face_edges.tolist()
    edge_faces = topo.edge_faces.tolist()
    edge_count = topo.edge_face_count.tolist()
    edges = topo.edges.tolist()
    alpha_l = alpha.tolist()

    def stripe(f0, pos, direction):
        """Walk both ways along a line through face f0's centroid, unfolding faces edge to edge
        (plain Python floats: this loop runs a few thousand steps)."""
        faces, newpos = [f0], {}
        allpos = {k: (float(v[0]), float(v[1])) for k, v in pos.items()}
        cx = sum(allpos[v][0] for v in Fl[f0]) / 3.0
        cy = sum(allpos[v][1] for v in Fl[f0]) / 3.0
        seen = {f0}
        for sgn in (1.0, -1.0):
            dx, dy = sgn * float(direction[0]), sgn * float(direction[1])
            f, came_from = f0, -1
            while True:
                tri = Fl[f]
                best_t, exit_edge = -math.inf, -1
                for k in range(3):
                    ax, ay = allpos[tri[k]]
                    bx, by = allpos[tri[(k + 1) % 3]]
                    # c + t d = a + s (b - a)  ->  solve for t, s (Cramer)
                    ex, ey = bx - ax, by - ay
                    det = dx * (-ey) - dy * (-ex)
                    if abs(det) < 1e-14:
                        continue
                    rx, ry = ax - cx, ay - cy
                    t = (rx * (-ey) - ry * (-ex)) / det
                    sv = (dx * ry - dy * rx) / det
                    if 0.0 <= sv <= 1.0 and t > best_t:
                        eid = face_edges[f][k]
                        if eid == came_from:
                            continue
                        best_t, exit_edge = t, eid
                if exit_edge < 0 or edge_count[exit_edge] != 2:
                    break
                f0e, f1e = edge_faces[exit_edge]
                nf = f1e if f0e == f else f0e
                if nf in seen:
                    break
                vi, vj = edges[exit_edge]
                tri_n = Fl[nf]
                other = [v for v in tri_n if v != vi and v != vj][0]
                if other in allpos:
                    break
                bi, bj = alpha_l[nf][tri_n.index(vi)], alpha_l[nf][tri_n.index(vj)]
                awx = sum(allpos[v][0] for v in tri) / 3.0
                awy = sum(allpos[v][1] for v in tri) / 3.0
                pix, piy = allpos[vi]
                pjx, pjy = allpos[vj]
                ux, uy = pjx - pix, pjy - piy
                l1 = math.hypot(ux, uy)
                ux, uy = ux / l1, uy / l1
                r = l1 * math.sin(bj) / max(math.sin(bi + bj), 1e-12)
                side = ux * (awy - piy) - uy * (awx - pix)
                ang = -bi if side > 0 else bi
                c_, s_ = math.cos(ang), math.sin(ang)
                p = (pix + r * (c_ * ux - s_ * uy), piy + r * (s_ * ux + c_ * uy))
                allpos[other] = p
                newpos[other] = np.array(p)
                faces.append(nf)
                seen.add(nf)
                f, came_from = nf, exit_edge
        return faces, newpos

    dirs = [np.array([np.cos(t), np.sin(t)]) for t in np.linspace(0, np.pi, directions, endpoint=False)]
    best_choice = None
    if len(best) > STRIPE_TIES:  # many ties: keep those nearest the patch's centre
        c = topo.centroids
        centre = (c * topo.areas[:, None]).sum(axis=0) / topo.areas.sum()
        best = best[np.argsort(np.linalg.norm(c[best] - centre, axis=1))[:STRIPE_TIES]]
    for f in best:  # ties on the label: the one with the longest main stripe wins
        pos = place_central(f)
        counts = [len(stripe(f, pos, d)[0]) for d in dirs]
        kbest = int(np.argmax(counts))
        if best_choice is None or counts[kbest] > best_choice[0]:
            best_choice = (counts[kbest], f, pos, dirs[kbest])
    _, f0, pos, dmain = best_choice
    faces_main, pos_main = stripe(f0, pos, dmain)
    pos.update(pos_main)
    faces_perp, pos_perp = stripe(f0, pos, np.array([-dmain[1], dmain[0]]))
    pos.update(pos_perp)
    for v, p in pos.items():
        UV[v] = p
    placed_v = ~np.isnan(UV[:, 0])
    placed_face = placed_v[F].all(axis=1)

    # adjacent triangle crossings, layer by layer (vectorised per layer)
    interior = topo.interior_vertices
    next_relax = max(int(placed_v.sum() * 2.0), 64)
    for _layer in range(4 * m):
        if placed_face.all():
            break
        # 2D angle sums of placed faces and 3D angle sums of the others, at every vertex
        P = UV[F]
        placed_ang = np.zeros((m, 3))
        if placed_face.any():
            Pp = P[placed_face]
            a_ = np.roll(Pp, -1, axis=1) - Pp
            b_ = np.roll(Pp, -2, axis=1) - Pp
            cr = cross2d(a_, b_)
            placed_ang[placed_face] = np.arctan2(np.abs(cr), np.einsum("mkc,mkc->mk", a_, b_))
        beta_sum = np.bincount(F.ravel(), weights=placed_ang.ravel(), minlength=n)
        alpha_free = np.bincount(F[~placed_face].ravel(), weights=alpha[~placed_face].ravel(), minlength=n)
        # targets: unplaced faces with exactly two placed vertices
        npl = placed_v[F].sum(axis=1)
        tgt = np.nonzero((~placed_face) & (npl == 2))[0]
        if len(tgt) == 0:
            # a face with one placed vertex only and no neighbour to hinge on cannot
            # happen in a connected disk once the stripes are placed; stop safely
            break
        T = F[tgt]
        k_free = np.argmin(placed_v[T], axis=1)  # the unplaced corner
        ki = (k_free + 1) % 3
        kj = (k_free + 2) % 3
        rows = np.arange(len(tgt))
        vi, vj, vp = T[rows, ki], T[rows, kj], T[rows, k_free]
        ai, aj = alpha[tgt, ki], alpha[tgt, kj]

        def rescale(v, a):  # eq. 4-24 at interior vertices
            remaining = 2 * np.pi - beta_sum[v]
            fac = np.where(interior[v] & (alpha_free[v] > 0), remaining / np.maximum(alpha_free[v], 1e-300), 1.0)
            fac = np.clip(fac, 0.5, 2.0)
            return a * fac

        bi, bj = rescale(vi, ai), rescale(vj, aj)
        # the unfolded neighbour across edge (vi, vj): the side to move away from
        eid = topo.face_edges[tgt, ki]
        ef = topo.edge_faces[eid]
        nbr = np.where(ef[:, 0] == tgt, ef[:, 1], ef[:, 0])
        has_nbr = (nbr >= 0) & placed_face[np.maximum(nbr, 0)]
        away = np.where(has_nbr[:, None], np.nan_to_num(UV[F[np.maximum(nbr, 0)]].mean(axis=1)), 0.0)
        # no placed neighbour on that edge: keep the 3D orientation relative to another placed face at vi
        if (~has_nbr).any():
            # use the mirror of the triangle's own orientation: place on the side that keeps
            # the corner order counter-clockwise like the central triangle
            e = UV[vj] - UV[vi]
            away_alt = UV[vi] + np.stack([e[:, 1], -e[:, 0]], axis=1)  # right-hand side of i->j
            away = np.where(has_nbr[:, None], away, away_alt)
        # The seed fixes P by the two angles and the unfolded edge (law of sines); where
        # the rescaled angles add up to nearly pi that puts P far away and the error
        # grows layer after layer.  We keep the rescaled angle *directions* at both ends
        # but the true 3D lengths |vi P| and |vj P|, and average the two positions.
        Lip = np.linalg.norm(V[vp] - V[vi], axis=1)
        Ljp = np.linalg.norm(V[vp] - V[vj], axis=1)
        Pnew = 0.5 * (_place_at(UV[vi], UV[vj], bi, Lip, away) + _place_at(UV[vj], UV[vi], bj, Ljp, away))
        # several triangles may target the same vertex in one layer: average them
        cnt = np.bincount(vp, minlength=n)
        sx = np.bincount(vp, Pnew[:, 0], minlength=n)
        sy = np.bincount(vp, Pnew[:, 1], minlength=n)
        newv = np.nonzero(cnt > 0)[0]
        UV[newv, 0] = sx[newv] / cnt[newv]
        UV[newv, 1] = sy[newv] / cnt[newv]
        placed_v[newv] = True
        placed_face = placed_v[F].all(axis=1)
        count = int(placed_v.sum())
        if springs is not None and count >= next_relax and count < n:
            sub, ids = _sub_springs(springs, placed_v)
            if len(sub.rest):
                UV[ids], _, _ = relax_lbfgs(UV[ids], sub, max_iter=RELAX_LAYER_ITERS)
            next_relax = int(count * 2.0) + 1
    if not placed_v.all():
        raise BolusError("the patch could not be unfolded: some of its faces are not connected to the rest")
    return UV


def conformal_unfolding(topo: MeshTopology) -> np.ndarray:
    """Least-squares conformal map (Levy et al. 2002) scaled to true area: UV (n,2).

    Our fallback start for patches where the greedy unfolding of 4.5.1 folds over
    (strongly curved patches): LSCM is the minimiser of a convex quadratic, so it has no
    accumulated error; two far-apart boundary vertices are pinned.
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    V, F, n, m = topo.V, topo.F, topo.n, topo.m
    # each triangle in its own plane: p0 at 0, p1 on the x axis
    e1 = V[F[:, 1]] - V[F[:, 0]]
    e2 = V[F[:, 2]] - V[F[:, 0]]
    l1 = np.linalg.norm(e1, axis=1)
    x1 = l1
    x2 = np.einsum("ij,ij->i", e1, e2) / l1
    y2 = np.linalg.norm(np.cross(e1, e2), axis=1) / l1
    xs = np.stack([np.zeros(m), x1, x2], 1)
    ys = np.stack([np.zeros(m), np.zeros(m), y2], 1)
    d = np.sqrt(np.maximum(xs[:, 1] * ys[:, 2], 1e-300))  # sqrt(2 A)
    # W_j = (x_{j+2} - x_{j+1}) + i (y_{j+2} - y_{j+1})
    Wr = (np.roll(xs, -2, axis=1) - np.roll(xs, -1, axis=1)) / d[:, None]
    Wi = (np.roll(ys, -2, axis=1) - np.roll(ys, -1, axis=1)) / d[:, None]
    rows = np.repeat(np.arange(m), 3)
    cols = F.ravel()
    # unknowns [u (n), v (n)]; real rows: Wr u - Wi v; imaginary rows: Wi u + Wr v
    R = sp.coo_matrix((np.r_[Wr.ravel(), -Wi.ravel()], (np.r_[rows, rows], np.r_[cols, cols + n])), shape=(m, 2 * n))
    I_ = sp.coo_matrix((np.r_[Wi.ravel(), Wr.ravel()], (np.r_[rows, rows], np.r_[cols, cols + n])), shape=(m, 2 * n))
    A = sp.vstack([R, I_]).tocsr()
    b = np.nonzero(topo.boundary_vertices)[0]
    if len(b) < 2:
        b = np.arange(n)
    p0 = b[np.argmax(np.linalg.norm(V[b] - V[b].mean(axis=0), axis=1))]
    p1 = b[np.argmax(np.linalg.norm(V[b] - V[p0], axis=1))]
    dist = float(np.linalg.norm(V[p1] - V[p0]))
    fixed = np.array([p0, p1, p0 + n, p1 + n])
    vals = np.array([0.0, dist, 0.0, 0.0])
    free = np.setdiff1d(np.arange(2 * n), fixed)
    Af, Ax = A[:, free], A[:, fixed]
    rhs = -(Ax @ vals)
    sol = spsolve((Af.T @ Af).tocsc(), Af.T @ rhs)
    x = np.empty(2 * n)
    x[free] = sol
    x[fixed] = vals
    UV = np.stack([x[:n], x[n:]], axis=1)
    A2 = signed_areas(UV, F)
    if A2.sum() < 0:
        UV[:, 1] = -UV[:, 1]
    UV *= np.sqrt(topo.areas.sum() / max(abs(A2.sum()), 1e-300))
    return UV


# --------------------------------------------------------------------------- L1 refinement
def refine_lengths_l1(UV, springs: Springs, face_count: np.ndarray, rounds: int = 3,
                      crossed_weight: float = 0.0, max_iter: int = 20, F=None, A0=None,
                      area_balance: float = AREA_BALANCE, extra=None, progress=None) -> tuple[np.ndarray, int]:
    """Iteratively reweighted least squares towards min sum kappa_e |l_e - D_e| (the numerator of EL).

    Our addition after the spring relaxation: the spring energy is a sum of squares,
    while EL (eq. 3-30) sums absolute errors; reweighting the tension springs by
    kappa / |l - D| (kappa = faces on the edge, as EL counts every face's edges) for a
    few rounds minimises EL itself.  Crossed springs keep ``crossed_weight`` times their
    stiffness.  With F and A0 (m,) the flip penalty stays on, so that no triangle is
    turned over on the way.  Returns (UV, iterations).
    """
    nt = springs.n_tension
    no_windows = np.zeros((0, springs.contour_edges.shape[1]), dtype=np.int64)
    sp_ = Springs(springs.ends, springs.rest, springs.stiffness.copy(), nt, no_windows, np.zeros(0), np.zeros(0))
    X = UV
    its = 0
    for k in range(rounds):
        if progress is not None:
            progress(k / rounds)
        d = X[springs.ends[:nt, 0]] - X[springs.ends[:nt, 1]]
        res = np.abs(np.linalg.norm(d, axis=1) - springs.rest[:nt])
        w = face_count / np.maximum(res, 1e-3 * springs.rest[:nt])
        w *= np.median(springs.stiffness[:nt]) / np.median(w)
        sp_.stiffness[:nt] = w
        sp_.stiffness[nt:] = springs.stiffness[nt:] * crossed_weight
        aw = None
        if area_balance > 0 and F is not None:
            # IRLS weights for sum |A - A0| too, scaled so that EL and EA count alike
            ra = np.abs(signed_areas(X, F) - A0)
            aw = 1.0 / np.maximum(ra, 1e-3 * A0)
            lam = area_balance * springs.rest[:nt].dot(face_count) / A0.sum()
            aw *= lam * np.median(w) / np.median(face_count / np.maximum(res, 1e-3 * springs.rest[:nt]))
        X, it, _ = relax_lbfgs(X, sp_, max_iter=max_iter, tol=1e-6, F=F, A0=A0,
                               flip_weight=FLIP_WEIGHT * 10.0 if F is not None else 0.0, area_weights=aw, extra=extra,
                               progress=None if progress is None else (lambda f, k=k: progress((k + f) / rounds)))
        its += it
    return X, its


FLIP_WEIGHT = 10.0
RELAX_ITERS = 300  # L-BFGS iterations of the relaxation (was 2000)
RELAX_TOL = 1e-7  # its stop test: relative energy decrease over 5 iterations (was 1e-9)
HOPELESS_EL = 0.10  # a pattern this far off after relaxation cannot be rescued by the overlap correction
HOPELESS_EA = 0.20
HOPELESS_FAR = 2.0  # EL above HOPELESS_FAR * HOPELESS_EL after 50 iterations: stop relaxing, it is hopeless
HOPELESS_STALL = 0.02  # or above HOPELESS_EL and less than 2 % (relative) better over 25 iterations
UNTANGLE_SWEEPS = 50  # Laplacian sweeps of `_untangle`
PENALTY_TOL = 1e-6  # stop test of the penalty minimisations (flips, outline): relative decrease over 5 iterations
FLIP_ITERS = 150  # L-BFGS iterations per flip-correction round (was 300)
OUTLINE_ROUNDS = 8  # outline correction rounds (the seed's loop; was 16)
OUTLINE_ITERS = 60  # L-BFGS iterations per outline round (was 300)
OUTLINE_BIG = 10000  # triangles: larger patches get proportionally fewer outline rounds
OUTLINE_PATIENCE = 2  # rounds without fewer defects before the outline correction gives up


def _untangle(UV, topo: MeshTopology, sweeps: int = UNTANGLE_SWEEPS) -> tuple[np.ndarray, int]:
    """Local untangling before the penalty rounds (our addition to 4.5.3): the vertices of
    flipped triangles and their one-ring are moved to the mean of their neighbours
    (uniform Laplacian), a few sweeps.  A fold of a few triangles on a 40k-triangle patch
    otherwise costs whole L-BFGS rounds over every vertex.  Returns (UV, flipped); UV is
    unchanged if the sweeps did not lower the flip count."""
    F = topo.F
    flips0 = int(np.count_nonzero(signed_areas(UV, F) <= 0))
    if flips0 == 0:
        return UV, 0
    A = topo.vertex_adjacency
    deg = np.maximum(np.asarray(A.sum(axis=1)).ravel(), 1.0)
    X = UV.copy()
    flips = flips0
    for _ in range(sweeps):
        bad = signed_areas(X, F) <= 0
        flips = int(np.count_nonzero(bad))
        if flips == 0:
            break
        sel = np.zeros(topo.n, dtype=bool)
        sel[F[bad].ravel()] = True
        sel |= np.asarray(A @ sel.astype(np.float64)).ravel() > 0
        X[sel] = (A @ X)[sel] / deg[sel, None]
    flips = int(np.count_nonzero(signed_areas(X, F) <= 0))
    return (X, flips) if flips < flips0 else (UV, flips0)


def _correct_flips(UV, springs: Springs, topo: MeshTopology, rounds: int = 4, max_iter: int = FLIP_ITERS,
                   progress=None, weight: float = FLIP_WEIGHT):
    """Overlap correction (4.5.3): push flipped triangles back with a growing penalty.

    Returns (UV, iterations, triangles still flipped)."""
    flipped = int(np.count_nonzero(signed_areas(UV, topo.F) <= 0))
    its = 0
    best = (flipped, UV)
    for k in range(rounds):
        if flipped == 0:
            break
        UV, flipped = _untangle(UV, topo)
        if flipped == 0:  # the lengths around the fold were smoothed: relax them back, folds kept out
            UV, it, _ = relax_lbfgs(UV, springs, max_iter=OUTLINE_ITERS, tol=PENALTY_TOL, F=topo.F, A0=topo.areas,
                                    flip_weight=max(weight, FLIP_WEIGHT * 100.0))
            its += it
            flipped = int(np.count_nonzero(signed_areas(UV, topo.F) <= 0))
            if flipped == 0:
                best = (0, UV)
                break
        sub = None if progress is None else (lambda f, k=k: progress((k + f) / rounds))
        UV, it, _ = relax_lbfgs(UV, springs, max_iter=max_iter, tol=PENALTY_TOL, F=topo.F, A0=topo.areas,
                                flip_weight=weight, progress=sub)
        its += it
        flipped = int(np.count_nonzero(signed_areas(UV, topo.F) <= 0))
        weight *= 10.0
        if flipped >= best[0] and k >= 1:
            break  # a stronger penalty did not help twice: the fold is not going away (our budget)
        if flipped < best[0]:
            best = (flipped, UV)
    if flipped > best[0]:
        flipped, UV = best
    return UV, its, flipped


def outline_term(verts: np.ndarray, edges: np.ndarray, lengths: np.ndarray, n: int, weight: float, margin: float):
    """Penalty pushing outline vertices out of the pattern across outline edges (4.5.3).

    For every (vertex v, boundary edge c->d with the pattern on its left) pair,
    s = (d - c) x (v - c) / L is v's distance to the left of the edge's line;
    energy 1/2 w max(0, s + margin)^2: the seed's "spring along the intersected edge"
    that moves a wrongly placed vertex back out.  Returns f(x) -> (energy, grad (2n,)).
    """
    def f(x):
        Q = x.reshape(n, 2)
        v, c, d = Q[verts], Q[edges[:, 0]], Q[edges[:, 1]]
        e, r = d - c, v - c
        s = cross2d(e, r) / lengths
        viol = np.maximum(s + margin, 0.0)
        coef = weight * viol / lengths  # dE/d(cross product)
        gv = np.stack([-e[:, 1], e[:, 0]], 1) * coef[:, None]
        gd = np.stack([r[:, 1], -r[:, 0]], 1) * coef[:, None]
        gc = -gv - gd
        gg = np.concatenate([gv, gd, gc])
        grad = np.empty((n, 2))
        grad[:, 0] = np.bincount(idx, gg[:, 0], minlength=n)
        grad[:, 1] = np.bincount(idx, gg[:, 1], minlength=n)
        return 0.5 * weight * float(np.dot(viol, viol)), grad.ravel()

    idx = np.concatenate([verts, edges[:, 1], edges[:, 0]])

    return f


def _defects(UV, F) -> tuple[int, int]:
    """(flipped triangles, overlapping triangles) of a pattern: lower is better."""
    return int(np.count_nonzero(signed_areas(UV, F) <= 0)), int(overlapping_faces(UV, F).sum())


def _correct_outline(UV, springs: Springs, topo: MeshTopology, rounds: int = OUTLINE_ROUNDS,
                     max_iter: int = OUTLINE_ITERS, progress=None):
    """Overlap correction of the outline (4.5.3, first method): where boundary edges cross,
    the vertex of one that lies inside the pattern is pushed back out across the other,
    with the flip penalty raised so that no triangle turns over on the way.  Constraints
    found in earlier rounds are kept.

    Budget (our change, issue 9): at most ``rounds`` rounds of ``max_iter`` L-BFGS
    iterations (the seed gives no limit; 16 x 300 took 40 s on a 700-triangle nostril
    patch), and the rounds stop early once the defects (flipped, crossing) have not
    improved for `OUTLINE_PATIENCE` rounds.  The best pattern seen is returned.
    progress(fraction, text) names the round.
    Returns (UV, iterations, crossings left, the last penalty term, to keep the outline
    apart in later steps)."""
    E = boundary_edge_array(topo.F)
    mean_len = float(topo.edge_lengths.mean())
    cons: set[tuple[int, int]] = set()
    its = 0
    pairs = boundary_self_intersections(UV, topo.F)
    weight = float(np.median(springs.stiffness)) * OUTLINE_WEIGHT
    flip_w = FLIP_WEIGHT * 100.0
    term = None
    flips = int(np.count_nonzero(signed_areas(UV, topo.F) <= 0))
    best = ((flips, len(pairs)), UV, term)
    stale = 0
    for k in range(rounds):
        if len(pairs) == 0 and flips == 0:
            break
        if flips:
            flip_w *= 10.0
        for i, j in pairs.tolist():
            for a, b in ((i, j), (j, i)):
                for v in E[a]:
                    if v not in E[b]:
                        cons.add((int(v), int(b)))
        if not cons:
            break
        if progress is not None:
            progress(k / rounds, f"overlap correction round {k + 1}/{rounds}")
        sub = None if progress is None else (
            lambda f, k=k: progress((k + f) / rounds, f"overlap correction round {k + 1}/{rounds}"))
        cv = np.array([c[0] for c in cons], dtype=np.int64)
        ce = E[np.array([c[1] for c in cons], dtype=np.int64)]
        L = np.maximum(np.linalg.norm(UV[ce[:, 1]] - UV[ce[:, 0]], axis=1), 1e-9 * mean_len)
        term = outline_term(cv, ce, L, topo.n, weight=weight, margin=0.01 * mean_len)
        UV, it, _ = relax_lbfgs(UV, springs, max_iter=max_iter, tol=PENALTY_TOL, F=topo.F, A0=topo.areas,
                                flip_weight=flip_w, extra=term, progress=sub)
        its += it
        pairs = boundary_self_intersections(UV, topo.F)
        flips = int(np.count_nonzero(signed_areas(UV, topo.F) <= 0))
        if len(pairs):
            weight *= 2.0
        if (flips, len(pairs)) < best[0]:
            best, stale = ((flips, len(pairs)), UV, term), 0
        else:
            stale += 1
            if stale >= OUTLINE_PATIENCE:
                break
    (_, crossings), UV, term = best
    return UV, its, crossings, term


LOCAL_RINGS = 3  # vertex rings around a crossing of the outline that `_local_outline` moves
LOCAL_ROUNDS = 6  # its rounds (penalty doubled each round)
LOCAL_ITERS = 40  # L-BFGS iterations per round (a few dozen moving vertices)
LOCAL_GROWTH = 2.0  # outline penalty factor from one local round to the next
LOCAL_FIRST = True  # try `_local_outline` before the whole-patch `_correct_outline`
IRLS_CLIP = 10.0  # the local solve's IRLS weights stay within this factor of their median
LOCAL_CROSSED = False  # crossed springs in the local solve (with them: nose p1 EL +0.45 % instead of +0.2 %)


def _local_outline(UV, springs: Springs, topo: MeshTopology, rings: int = LOCAL_RINGS, rounds: int = LOCAL_ROUNDS,
                   max_iter: int = LOCAL_ITERS) -> tuple[np.ndarray, int, int]:
    """Local overlap correction of the outline (our addition to 4.5.3, issue 9): only the
    vertices within ``rings`` edge rings of the crossing outline edges (and of the
    overlapping triangles) move; everything else stays where it is.  The energy is the
    one of `_correct_outline` restricted to them (the springs and triangles touching a
    moving vertex, the flip penalty, the outline penalty of the crossing pairs), with the
    tension and area springs weighted as in the length refinement (IRLS towards EL,
    eq. 3-30; weights clipped to IRLS_CLIP x their median) so that it does not undo that
    refinement; minimised with L-BFGS over the moving coordinates only (a few dozen
    vertices instead of the whole patch).  Rounds double the outline penalty and add the
    new crossing pairs.  UV (n,2) -> (UV, iterations, crossings left); UV is returned
    unchanged unless the defects (flipped, crossings) went down."""
    F, n = topo.F, topo.n
    E = boundary_edge_array(F)
    pairs = boundary_self_intersections(UV, F)
    flips0 = int(np.count_nonzero(signed_areas(UV, F) <= 0))
    if not len(pairs):
        return UV, 0, 0
    mean_len = float(topo.edge_lengths.mean())
    A = topo.vertex_adjacency
    nt = springs.n_tension
    weight = float(np.median(springs.stiffness)) * OUTLINE_WEIGHT
    flip_w = FLIP_WEIGHT * 1000.0
    face_count = topo.edge_face_count.astype(np.float64)
    stiff_med = float(np.median(springs.stiffness[:nt]))
    lam = AREA_BALANCE * float(springs.rest[:nt].dot(face_count)) / float(topo.areas.sum())
    X = UV.copy()
    cons: set[tuple[int, int]] = set()
    its = 0
    best = ((flips0, len(pairs)), UV)
    for k in range(rounds):
        for i, j in pairs.tolist():
            for a, b in ((i, j), (j, i)):
                for v in E[a]:
                    if v not in E[b]:
                        cons.add((int(v), int(b)))
        cv = np.array([c[0] for c in cons], dtype=np.int64)
        ce = E[np.array([c[1] for c in cons], dtype=np.int64)]
        free = np.zeros(n, dtype=bool)
        free[cv] = True
        free[ce.ravel()] = True
        free[F[overlapping_faces(X, F)].ravel()] = True
        for _ in range(rings):
            free |= np.asarray(A @ free.astype(np.float64)).ravel() > 0
        # the local problem: springs and triangles touching a moving vertex, re-indexed
        ssel = free[springs.ends].any(axis=1)
        ssel[nt:] &= LOCAL_CROSSED
        fsel = free[F].any(axis=1)
        touched = free.copy()
        touched[springs.ends[ssel].ravel()] = True
        touched[F[fsel].ravel()] = True
        gid = np.nonzero(touched)[0]
        loc = np.full(n, -1, dtype=np.int64)
        loc[gid] = np.arange(len(gid))
        nl = len(gid)
        mov = loc[np.nonzero(free)[0]]
        Xl = X[gid]
        ends, rest = loc[springs.ends[ssel]], springs.rest[ssel]
        stiff = springs.stiffness[ssel].copy()
        tsel = np.nonzero(ssel[:nt])[0]
        ntl = len(tsel)
        res_l = np.abs(np.linalg.norm(Xl[ends[:ntl, 0]] - Xl[ends[:ntl, 1]], axis=1) - rest[:ntl])
        w = face_count[tsel] / np.maximum(res_l, 1e-3 * rest[:ntl])
        w_med = float(np.median(w))
        stiff[:ntl] = np.clip(w / w_med, 1.0 / IRLS_CLIP, IRLS_CLIP) * stiff_med
        sub = Springs(ends, rest, stiff, ntl, np.zeros((0, 1), dtype=np.int64), np.zeros(0), np.zeros(0))
        Fs, A0s = loc[F[fsel]], topo.areas[fsel]
        ra = np.abs(signed_areas(Xl, Fs) - A0s)
        aw = 1.0 / np.maximum(ra, 1e-3 * A0s)
        aw_med = float(np.median(aw))
        aw = np.clip(aw / aw_med, 1.0 / IRLS_CLIP, IRLS_CLIP) * aw_med * lam * stiff_med / w_med
        L = np.maximum(np.linalg.norm(X[ce[:, 1]] - X[ce[:, 0]], axis=1), 1e-9 * mean_len)
        term = outline_term(loc[cv], loc[ce], L, nl, weight=weight, margin=0.01 * mean_len)

        moving = np.zeros(nl, dtype=bool)
        moving[mov] = True
        Xl, it, _ = relax_lbfgs(Xl, sub, max_iter=max_iter, tol=PENALTY_TOL, F=Fs, A0=A0s, flip_weight=flip_w,
                                area_weights=aw, extra=term, moving=moving)
        its += it
        X = X.copy()
        X[gid[mov]] = Xl[mov]
        pairs = boundary_self_intersections(X, F)
        flips = int(np.count_nonzero(signed_areas(X, F) <= 0))
        if (flips, len(pairs)) < best[0]:
            best = ((flips, len(pairs)), X)
        if not len(pairs) and not flips:
            break
        weight *= LOCAL_GROWTH
    (_, crossings), X = best
    return X, its, crossings


# --------------------------------------------------------------------------- pipeline
@dataclass
class Unfolding:
    """A flattened patch.

    UV (n2,2) mm positions of the unfolded vertices, F (m,3) the patch's triangles in
    the same order as given, indexing UV; vert_origin (n2,) the input vertex of each
    unfolded vertex (vertices on a cut appear twice).

    hopeless: the patch cannot lie flat in one piece within `HOPELESS_EL` / `HOPELESS_EA`
    (decided before the overlap correction, which is then skipped: see `unfold_patch`);
    angle_deficit / angle_excess: sum over interior vertices of max(0, 2 pi - theta) and
    max(0, theta - 2 pi) in radians (theta the angle sum, eq. 4-1: deficit = cap-like,
    excess = saddle-like material that would overlap); hopeless_reason: the figures
    that decided it.
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


def _lumped_masses(topo: MeshTopology) -> np.ndarray:
    """m_i = 1/3 rho sum of one-ring areas (eq. 3-24), rho = 1."""
    return np.bincount(topo.F.ravel(), weights=np.repeat(topo.areas / 3.0, 3), minlength=topo.n)


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


def curvature_sums(topo: MeshTopology) -> tuple[float, float]:
    """(angle deficit, angle excess) of a patch: sums over interior vertices of
    max(0, 2 pi - theta) and max(0, theta - 2 pi), theta the angle sum (eq. 4-1);
    their sum is sum varpi (eq. 4-2)."""
    d = 2.0 * np.pi - topo.angle_sums
    d = d[topo.interior_vertices]
    return float(np.maximum(d, 0.0).sum()), float(np.maximum(-d, 0.0).sum())


def unfold_patch(V, F, method: str = "lbfgs", refine_rounds: int = 3, max_iter: int | None = None,
                 progress=None, start: str = "auto", *, relax: bool = True, crossed_springs: bool = True,
                 disturbing_springs: bool = True) -> Unfolding:
    """Unfold one patch (V (n,3) mm, F (m,3)) into the plane at true scale.

    A patch that is not a disk is first cut to one (`cutting.cut_to_disk`).
    method: "lbfgs" (default) or "explicit" (the seed's integrator); refine_rounds:
    rounds of `refine_lengths_l1` (0 = the spring energy's minimum as it is).
    The result is counter-clockwise; flipped triangles are corrected (4.5.3) and any
    that remain, and any overlap of the outline, are counted and reported.
    progress(fraction in [0, 1], text): called at every stage ("initial unfolding",
    "relaxing springs", "length refinement", "overlap correction round k/n") and about
    every 0.5 s inside them.

    start: "auto" (= "conformal") starts from `conformal_unfolding`, "greedy" from the
    coordinate transformation of 4.5.1 (`initial_unfolding`; if that folds over, the
    conformal map is used and a warning says so).

    Stage switches (for the ablation of bench/unfold_bench.py; defaults = the full method):
    relax=False: no spring relaxation and no length refinement (``refine_rounds`` is
    ignored): the start as it is (for "greedy" with its own relaxation of the part
    unfolded so far, 4.5.3), mirrored to counter-clockwise; only if it has flipped
    triangles or outline crossings does the overlap correction (4.5.3) run on it, as in the
    full pipeline (flip rounds, local then whole-patch outline correction, `_untangle`);
    a flip-free start without crossings comes back unchanged.  crossed_springs=False /
    disturbing_springs=False: the model is built without the crossed springs (3.5) / the
    disturbing contour springs (eq. 4-25) (`build_springs`), in every stage.

    Speed (issue 9; the stages of the seed are kept, their budgets are ours):
    - the conformal start is one sparse solve; 4.5.1 reaches the same minimum where it
      does not fold, but folded on 6 of 8 scanned nose patches and costs seconds of
      Python on 20k-triangle patches;
    - the relaxation has the flip penalty on from its first step (the start is flip
      free), stops at `RELAX_ITERS` iterations or a relative energy decrease below
      `RELAX_TOL` over 5 iterations; the penalty minimisations at `PENALTY_TOL`;
    - hopeless patches (``hopeless``) are told early: a relaxation whose EL is still above
      `HOPELESS_FAR` x `HOPELESS_EL` after 50 iterations is stopped (a nostril pocket)
      and gets one short flip round; after the length refinement, a pattern with
      EL > `HOPELESS_EL` or EA > `HOPELESS_EA` cannot be rescued by the overlap
      correction (it only moves the outline), so that correction is skipped and the
      pattern is returned with the flag and the figures (``hopeless_reason``; no warning
      of its own: the operator warns on EL / EA with the user's threshold);
    - outline crossings are first corrected locally around them (`_local_outline`,
      `LOCAL_ROUNDS` x `LOCAL_ITERS`); only if crossings or flips remain, the whole-patch
      outline correction runs at most `OUTLINE_ROUNDS` rounds of `OUTLINE_ITERS`
      iterations and stops when the defects stop going down (`_correct_outline`),
      followed by the local correction again.
    """
    t0 = time.perf_counter()
    st = _Stages(progress)
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    if len(F) < 3:
        raise BolusError(f"a patch of {len(F)} triangles is too small to unfold (at least 3 are needed)")
    if method not in METHODS:
        raise BolusError(f"unknown unfolding method {method!r}; use one of {', '.join(METHODS)}")
    topo0 = MeshTopology(V, F)
    if float(topo0.areas.sum()) <= 0 or topo0.degenerate_faces().all():
        raise BolusError("the patch has no area to unfold")
    topo0.require_nondegenerate("the patch")
    # consistent winding: every interior edge is walked once in each direction
    he = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    if len(np.unique(he[:, 0] * topo0.n + he[:, 1])) < len(he):
        raise BolusError(
            "the patch's faces are not consistently oriented (some normals point the other way): "
            "recalculate the normals first (Mesh > Normals > Recalculate Outside)"
        )
    st.stage(0.0, 0.1, "initial unfolding")
    deficit, excess = curvature_sums(topo0)
    cut = cut_to_disk(V, F)
    topo = MeshTopology(cut.V, cut.F)
    springs = build_springs(topo, contour_window=CONTOUR_WINDOW if disturbing_springs else 0,
                            crossed=crossed_springs)
    warnings: list[str] = []
    if start == "auto":
        start = "conformal"
    if start not in ("greedy", "conformal"):
        raise BolusError(f"unknown start {start!r}; use auto, greedy or conformal")
    UV = initial_unfolding(topo, springs=springs) if start == "greedy" else conformal_unfolding(topo)
    if start == "greedy" and np.count_nonzero(signed_areas(UV, topo.F) <= 0):
        # the coordinate transformation of 4.5.1 folded over (a strongly curved patch):
        # start from the least-squares conformal map, which does not fold on a disk
        UV = conformal_unfolding(topo)
        warnings.append("started from a conformal map: the coordinate transformation of 4.5.1 folded over")
    if np.sum(signed_areas(UV, topo.F)) < 0:  # counter-clockwise, like the 3D corner order
        UV[:, 0] = -UV[:, 0]
    flip_free = not np.count_nonzero(signed_areas(UV, topo.F) <= 0)

    st.stage(0.1, 0.35, "relaxing springs")

    far: list[int] = []
    el_seen: list[float] = []

    def far_off(X, it):
        """Early hopeless test, every STOP_EVERY iterations: lengths still HOPELESS_FAR x the EL
        limit off after 50 iterations (a nostril pocket: EL 40-75 %), or above the limit and
        less than `HOPELESS_STALL` better than STOP_EVERY iterations before, will not come
        under the limit (and a long penalised relaxation starts to push triangles over)."""
        el = length_area_errors(topo.V, topo.F, X)[0]
        stalled = bool(el_seen) and el > HOPELESS_EL and el > (1.0 - HOPELESS_STALL) * el_seen[-1]
        if it >= 2 * STOP_EVERY and (el > HOPELESS_FAR * HOPELESS_EL or stalled):
            far.append(it)
        el_seen.append(el)
        return bool(far)

    it = 0
    if not relax:
        refine_rounds = 0
    elif method == "lbfgs":
        # from a flip-free start the flip penalty (4.5.3) is on from the first step, so the
        # relaxation does not fold the pattern (a nostril pocket folds flat otherwise, and
        # unfolding the fold afterwards took minutes of penalty rounds)
        UV, it, _ = relax_lbfgs(UV, springs, max_iter=max_iter or RELAX_ITERS, tol=RELAX_TOL, progress=st,
                                F=topo.F if flip_free else None, A0=topo.areas,
                                flip_weight=FLIP_WEIGHT * 10.0 if flip_free else 0.0, stop=far_off)
    else:
        UV, it, _ = relax_explicit(UV, springs, _lumped_masses(topo), max_iter=max_iter or 20000, progress=st)
    if np.sum(signed_areas(UV, topo.F)) < 0:
        UV[:, 0] = -UV[:, 0]
    st.stage(0.35, 0.45, "correcting flipped triangles")
    if far:  # hopeless: one short round with a strong penalty, only to take out the folds
        UV, it2, flipped = _correct_flips(UV, springs, topo, rounds=1, max_iter=OUTLINE_ITERS, progress=st,
                                          weight=FLIP_WEIGHT * 100.0)
    else:
        UV, it2, flipped = _correct_flips(UV, springs, topo, progress=st)
    it += it2
    if refine_rounds > 0 and not (far and flipped):
        st.stage(0.45, 0.6, "length refinement")
        face_count = topo.edge_face_count.astype(np.float64)
        UV, it2 = refine_lengths_l1(UV, springs, face_count, rounds=refine_rounds,
                                    F=topo.F if flipped == 0 else None, A0=topo.areas, progress=st)
        it += it2
        flipped = int(np.count_nonzero(signed_areas(UV, topo.F) <= 0))
        if flipped:
            UV, it2, flipped = _correct_flips(UV, springs, topo, rounds=1 if far else 4)
            it += it2
    EL, EA = length_area_errors(topo.V, topo.F, UV)
    hopeless = EL > HOPELESS_EL or EA > HOPELESS_EA
    reason = ""
    if hopeless:
        # no warning here: the operator warns on EL / EA with the user's threshold and
        # gives the advice; the flag and this text say why the correction was skipped
        reason = (f"after relaxation EL {100 * EL:.1f} % / EA {100 * EA:.1f} % (more than {100 * HOPELESS_EL:g} % / "
                  f"{100 * HOPELESS_EA:g} %); angle deficit {deficit:.2f} rad, angle excess {excess:.2f} rad: "
                  "the patch cannot lie flat in one piece, the overlap correction was skipped")
    if not hopeless and LOCAL_FIRST and len(boundary_self_intersections(UV, topo.F)):
        # first only around the crossings (cheap); the whole-patch correction if that fails
        st.stage(0.6, 0.7, "overlap correction (local)")
        UV2, it2, crossings2 = _local_outline(UV, springs, topo)
        it += it2
        if crossings2 == 0 and not np.count_nonzero(signed_areas(UV2, topo.F) <= 0):
            UV, flipped = UV2, 0
    if not hopeless and len(boundary_self_intersections(UV, topo.F)):
        st.stage(0.6, 0.95, "overlap correction")
        # big patches: fewer rounds (each costs ~m), at least 2 (OUTLINE_BIG triangles: all rounds)
        rounds = max(2, min(OUTLINE_ROUNDS, OUTLINE_ROUNDS * OUTLINE_BIG // topo.m))
        UV2, it2, crossings2, term = _correct_outline(UV, springs, topo, rounds=rounds, progress=st)
        it += it2
        if refine_rounds > 0 and term is not None:
            # the correction relaxed the plain spring energy: refine again, outline kept apart
            st.stage(st.last, 0.98, "length refinement (outline kept apart)")
            UV3, it3 = refine_lengths_l1(UV2, springs, topo.edge_face_count.astype(np.float64),
                                         rounds=refine_rounds, F=topo.F, A0=topo.areas, extra=term, progress=st)
            it += it3
            if _defects(UV3, topo.F) <= _defects(UV2, topo.F):
                UV2 = UV3
        if _defects(UV2, topo.F) <= _defects(UV, topo.F):
            UV = UV2
            flipped = int(np.count_nonzero(signed_areas(UV, topo.F) <= 0))
    if not hopeless and len(boundary_self_intersections(UV, topo.F)):
        # crossings left: a local correction around them only (the rest of the pattern stays)
        UV, it2, _ = _local_outline(UV, springs, topo)
        it += it2
        flipped = int(np.count_nonzero(signed_areas(UV, topo.F) <= 0))
    if flipped:  # last resort, no relaxation after it: smooth the few folds left away locally
        UV, flipped = _untangle(UV, topo)
    e, _ = spring_energy(UV.ravel(), springs, topo.n)
    if flipped:
        warnings.append(f"{flipped} triangles remain flipped after the overlap correction")
    crossings = len(boundary_self_intersections(UV, topo.F))
    overlaps = int(overlapping_faces(UV, topo.F).sum()) if crossings or flipped else 0
    if crossings or overlaps:
        warnings.append(f"the pattern overlaps itself ({overlaps} triangles)")
    EL, EA = length_area_errors(topo.V, topo.F, UV)
    st.stage(1.0, 1.0, "done")
    return Unfolding(UV, topo.F, cut.vert_origin, EL, EA, flipped, overlaps, it, float(e),
                     time.perf_counter() - t0, method, cut.description if cut.was_cut else "", warnings,
                     hopeless, deficit, excess, reason)


@dataclass
class Pattern:
    """All patches unfolded and laid out.

    UV (N,2) mm; F (M,3) triangles in the order of the input triangles (row t of F
    is input triangle t); vert_source (N,) input vertex of each pattern vertex;
    tri_patch (M,); patches: list of `Unfolding` (their UV before layout).
    """

    UV: np.ndarray
    F: np.ndarray
    vert_source: np.ndarray
    tri_patch: np.ndarray
    patches: list


def iter_unfold_patches(V, F, labels, method: str = "lbfgs", refine_rounds: int = 3, progress=None):
    """Yield (index, count, Unfolding) for every patch label 0..p-1 of the triangles (m,).

    progress(fraction, text): the overall fraction in [0, 1], each patch weighted by its
    triangle count, text "patch k/n: <step>" (called from inside `unfold_patch`).
    """
    labels = np.asarray(labels, dtype=np.int64)
    F = np.asarray(F, dtype=np.int64)
    ids = np.unique(labels[labels >= 0])
    sizes = np.array([np.count_nonzero(labels == p) for p in ids], dtype=np.float64)
    before = np.concatenate([[0.0], np.cumsum(sizes)]) / max(sizes.sum(), 1.0)
    for k, p in enumerate(ids):
        sel = labels == p
        Fs = F[sel]
        verts, inv = np.unique(Fs.ravel(), return_inverse=True)
        sub = None
        if progress is not None:
            lo, hi, head = before[k], before[k + 1], f"patch {k + 1}/{len(ids)}"

            def sub(f, text, lo=lo, hi=hi, head=head):
                progress(float(lo + (hi - lo) * min(max(f, 0.0), 1.0)), f"{head}: {text}")
        try:
            u = unfold_patch(V[verts], inv.reshape(-1, 3), method=method, refine_rounds=refine_rounds,
                             progress=sub)
        except BolusError as exc:
            raise BolusError(f"patch {p}: {exc}") from exc
        u.vert_origin = verts[u.vert_origin]  # back to the caller's vertex indices
        yield k, len(ids), u


def assemble_pattern(F, labels, patches: list[Unfolding], gap_mm: float = 10.0) -> Pattern:
    """Lay the unfolded patches out side by side (layout.pack_islands) in one pattern mesh."""
    labels = np.asarray(labels, dtype=np.int64)
    ids = np.unique(labels[labels >= 0])
    placed = pack_islands([u.UV for u in patches], gap_mm=gap_mm)
    UV_all, src_all = [], []
    F_all = np.full((len(F), 3), -1, dtype=np.int64)
    tri_patch = np.full(len(F), -1, dtype=np.int64)
    offset = 0
    for p, u, P in zip(ids, patches, placed):
        rows = np.nonzero(labels == p)[0]
        F_all[rows] = u.F + offset
        tri_patch[rows] = p
        UV_all.append(P)
        src_all.append(u.vert_origin)
        offset += len(P)
    return Pattern(np.concatenate(UV_all), F_all, np.concatenate(src_all), tri_patch, patches)
