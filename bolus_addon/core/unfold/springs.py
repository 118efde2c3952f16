"""The mass-spring model of a patch (seed 3.5, 4.5.2; eqs. 3-22, 3-28, 3-29, 4-25).

- tension springs on the edges, rest length the 3D edge (eq. 3-22);
- crossed springs between the two vertices opposite every interior edge, rest length
  the distance of those vertices when the two triangles are rotated into one plane about
  their common edge (the length the pair has in a perfect flattening; the 3D chord would
  pull folds shut);
- disturbing (contour) springs, the blue springs of Fig. 4-17: over every window of
  `CONTOUR_WINDOW` consecutive boundary edges, 1/2 c (sum |Q| - sum D)^2 with
  c = 1 / sum D (eq. 4-25), which keeps the outline's length right piece by piece.

Total energy E = sum 1/2 c (|Q_i Q_j| - D_ij)^2 (eqs. 3-28, 3-29) plus the contour terms;
stiffness c = 1 / D (Hooke's law for a uniform sheet, so the energy does not favour long
edges), crossed springs `CROSSED_WEIGHT` times stiffer (the seed gives no ratio).  What
they earn today (60 degree cap, tests/test_core_unfold.py): without the length
refinement EL 3.99 % with them, 4.06 % without, at EA 4.54 % against 4.37 %; after the
refinement EL 3.56 / 3.60 %, EA 2.63 / 2.36 %.  When this ratio was chosen (with an
older relaxation) they lowered EA from 5.7 % to 3.6 %; they no longer do.
`area_terms` adds energies on the signed triangle areas: the flip penalty of the overlap
correction (4.5.3) and the area springs of the length refinement.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..mesh.boundary import _edge_ids, boundary_loops
from ..mesh.topology import MeshTopology

__all__ = ["Springs", "build_springs", "spring_energy", "area_terms", "stiffness_laplacian", "sub_springs",
           "CONTOUR_WINDOW", "CROSSED_WEIGHT"]

CONTOUR_WINDOW = 8  # boundary edges per disturbing spring (eq. 4-25; the seed gives no window length)
CROSSED_WEIGHT = 3.0  # crossed / tension stiffness (the seed gives no ratio; see the module docstring)
MIN_REST = 1e-12  # rest lengths below this fraction of the longest are clamped (a stiffness 1/D stays finite)
FLIP_FRAC = 0.05  # the flip penalty starts when a triangle's area falls below this fraction of its 3D area


@dataclass
class Springs:
    """All springs of the model: endpoints (s,2), rest lengths (s,), stiffness (s,).

    The first `n_tension` springs are the edges (in `MeshTopology.edges` order), then the
    crossed springs.  Contour (disturbing) springs act on paths and are kept apart:
    `contour_edges` (w,W) holds the spring indices of the W boundary edges of each window,
    `contour_rest` (w,) and `contour_stiffness` (w,).
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

    def share_end_caches(self, other: "Springs") -> "Springs":
        """Give ``other`` (built on the very same ends array, another stiffness) the caches
        that depend on the ends only: incidence matrices, end columns, Laplacian pattern."""
        if other.ends is self.ends:
            for key in ("_incidence", "_cols", "_lap"):
                if key in self.__dict__:
                    other.__dict__.setdefault(key, self.__dict__[key])
        return other

    def _end_columns(self) -> tuple[np.ndarray, np.ndarray]:
        """(p (s,), q (s,)): the spring ends as contiguous arrays (cached; fast np.take gathers)."""
        cols = self.__dict__.get("_cols")
        if cols is None or cols[0] is not self.ends:
            cols = (self.ends, np.ascontiguousarray(self.ends[:, 0]), np.ascontiguousarray(self.ends[:, 1]))
            self.__dict__["_cols"] = cols
        return cols[1], cols[2]

    def _incidence_pair(self, n: int):
        """(B, B^T) as CSR matrices, cached per n (B^T @ g scatters spring forces to vertices)."""
        cache = self.__dict__.setdefault("_incidence", {})
        if n not in cache:
            s = len(self.ends)
            rows = np.r_[np.arange(s), np.arange(s)]
            B = sp.csr_matrix((np.r_[np.ones(s), -np.ones(s)], (rows, self.ends.T.ravel())), shape=(s, n))
            cache[n] = (B, B.T.tocsr())
        return cache[n]


def _hinge_distance(V: np.ndarray, i, j, a, b) -> np.ndarray:
    """Distance a-b (k,) after unfolding triangles (i,j,a) and (j,i,b) into one plane."""
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


def _crossed_pairs(topo: MeshTopology) -> tuple[np.ndarray, np.ndarray]:
    """Ends (k,2) and hinged rest lengths (k,) of the crossed springs, one per interior edge."""
    F, E = topo.F, topo.edges
    inner = np.nonzero(topo.edge_face_count == 2)[0]
    i, j = E[inner, 0], E[inner, 1]

    def opposite(f):  # the corner of each face that is neither i nor j
        tri = F[f]
        mask = (tri != i[:, None]) & (tri != j[:, None])
        return tri[np.arange(len(f)), np.argmax(mask, axis=1)]

    a, b = opposite(topo.edge_faces[inner, 0]), opposite(topo.edge_faces[inner, 1])
    return np.stack([a, b], axis=1), _hinge_distance(topo.V, i, j, a, b)


def _canonical_edge_loop(topo: MeshTopology, loop: np.ndarray) -> np.ndarray:
    """Edge indices (k,) of a closed vertex loop, starting at its lowest edge index and
    running on towards that edge's higher vertex (an order that does not depend on the
    walker; the energy sums in it, and on a hopeless patch their rounding matters)."""
    edges = _edge_ids(topo, np.stack([loop, np.roll(loop, -1)], axis=1))
    s = int(np.argmin(edges))
    edges = np.roll(edges, -s)
    if loop[(s + 1) % len(loop)] != topo.edges[edges[0], 1]:  # walked the other way
        edges = np.r_[edges[:1], edges[1:][::-1]]
    return edges


def _contour_windows(topo: MeshTopology, window: int) -> np.ndarray:
    """(w, window) tension-spring (= edge) indices of every window of consecutive boundary
    edges along each boundary loop longer than the window (`cutting.boundary_loops`)."""
    loops = []
    if window >= 2 and np.count_nonzero(topo.boundary_edges) > window:
        loops = [_canonical_edge_loop(topo, loop) for loop in boundary_loops(topo.F, topo) if len(loop) > window]
    if not loops:
        return np.zeros((0, max(window, 1)), dtype=np.int64)
    windows = []
    for edges in sorted(loops, key=lambda e: int(e[0])):
        k = np.arange(len(edges))
        windows.append(edges[(k[:, None] + np.arange(window)[None, :]) % len(edges)])
    return np.concatenate(windows)


def build_springs(topo: MeshTopology, contour_window: int = CONTOUR_WINDOW, crossed: bool = True) -> Springs:
    """Tension, crossed and disturbing springs of a patch (3.5, 4.5.2, eqs. 3-22, 4-25).

    Parameters: topo, the patch's `MeshTopology` (V (n,3), F (m,3)); contour_window, the
    boundary edges per disturbing spring (0 = no disturbing springs); crossed, whether the
    crossed springs are in the model.
    Returns `Springs`.  Raises `BolusError` (`topology.check_mesh`, naming the first) on
    no triangles, NaN/inf vertices, bad indices, zero-area triangles (no rest shape) and
    non-manifold edges (no pair of faces for a crossed spring).  Needle triangles are
    fine (their springs are short and stiff but finite).
    """
    topo.require_valid("the patch", manifold=True)
    return _build_springs(topo, contour_window, crossed)


def _build_springs(topo: MeshTopology, contour_window: int, crossed: bool) -> Springs:
    """`build_springs` without the input check (for callers that checked the patch already)."""
    E, rest_t = topo.edges, topo.edge_lengths
    ends, rest = [E], [rest_t]
    if crossed:
        ends_c, rest_c = _crossed_pairs(topo)
        ends.append(ends_c)
        rest.append(rest_c)
    ends = np.concatenate(ends).astype(np.int64)
    rest = np.concatenate(rest)
    stiffness = 1.0 / np.maximum(rest, MIN_REST * max(rest.max(), 1.0))
    stiffness[len(E):] *= CROSSED_WEIGHT
    cw = _contour_windows(topo, contour_window)
    crest = rest_t[cw].sum(axis=1) if len(cw) else np.zeros(0)
    return Springs(ends, rest, stiffness, len(E), cw, crest, 1.0 / np.maximum(crest, 1e-300))


def sub_springs(springs: Springs, keep_vertex: np.ndarray) -> tuple[Springs, np.ndarray]:
    """The springs between kept vertices (n,) bool, re-indexed, without contour springs.

    Returns (springs, kept vertex ids (k,))."""
    ids = np.nonzero(keep_vertex)[0]
    local = np.full(len(keep_vertex), -1, dtype=np.int64)
    local[ids] = np.arange(len(ids))
    sel = keep_vertex[springs.ends].all(axis=1)
    ntension = int(sel[: springs.n_tension].sum())
    empty = np.zeros((0, springs.contour_edges.shape[1]), dtype=np.int64)
    sub = Springs(local[springs.ends[sel]], springs.rest[sel], springs.stiffness[sel], ntension, empty,
                  np.zeros(0), np.zeros(0))
    return sub, ids


def spring_energy(x: np.ndarray, springs: Springs, n: int) -> tuple[float, np.ndarray]:
    """Total energy (eqs. 3-28, 3-29, plus eq. 4-25) and its gradient (2n,) at x = UV.ravel() (2n,)."""
    Q = x.reshape(n, 2)
    _, BT = springs._incidence_pair(n)
    # Q[p] - Q[q] for every spring (np.take: row gathers ~8x faster than Q[idx]; the same
    # numbers as the sparse product B @ Q, which they replace)
    p, q = springs._end_columns()
    d = Q.take(p, axis=0) - Q.take(q, axis=0)
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
    if abc is None:
        P = Q.take(F, axis=0)
        abc = P[:, 0], P[:, 1], P[:, 2]
    a, b, c = abc
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
               area_weights: np.ndarray | None = None, frac: float = FLIP_FRAC,
               mean_A0: float | None = None) -> tuple[float, np.ndarray]:
    """Energy terms on the signed areas A_t of the triangles F (m,3), and their gradient (2n,).

    flip penalty (overlap correction, 4.5.3): 1/2 w sum max(0, frac A0 - A)^2 / mean(A0),
    zero until a triangle is about to turn over; area springs (length refinement):
    1/2 sum a_t (A_t - A0_t)^2 with area_weights a (m,).  x = UV.ravel() (2n,), A0 (m,).
    """
    Q = x.reshape(n, 2)
    P = Q.take(F, axis=0)  # (m,3,2); np.take: row gathers ~8x faster than Q[F]
    a, b, c = P[:, 0], P[:, 1], P[:, 2]
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


def _laplacian_pattern(springs: Springs, n: int):
    """The sparsity pattern of `stiffness_laplacian` for the springs' ends (cached on them):
    (order, first, pair, off_ptr, full) with full = (rows, cols, positions of the diagonal
    entries, positions of the off-diagonal ones) of all entries in CSR order; None when three or more
    springs join one pair of vertices (then the general path sums them)."""
    cache = springs.__dict__.get("_lap")
    if cache is not None and cache[0] is springs.ends and cache[1] == n:
        return cache[2]
    p, q = springs.ends[:, 0], springs.ends[:, 1]
    key = np.r_[p * n + q, q * n + p]  # the entries (p, q) and (q, p) of every spring
    order = np.argsort(key, kind="stable")
    uniq, first, count = np.unique(key[order], return_index=True, return_counts=True)
    pattern = None
    if not len(count) or count.max() <= 2:
        rows, cols = uniq // n, uniq % n
        r_all = np.r_[rows, np.arange(n)]
        c_all = np.r_[cols, np.arange(n)]
        srt = np.lexsort((c_all, r_all))
        pos_d = np.nonzero(srt >= len(rows))[0]  # positions of the diagonal entries, in row order
        pos_o = np.nonzero(srt < len(rows))[0]  # positions of the off-diagonal ones, in their order
        off_ptr = np.r_[0, np.cumsum(np.bincount(rows, minlength=n))]
        pattern = (order, first, np.nonzero(count == 2)[0], off_ptr, (r_all[srt], c_all[srt], pos_d, pos_o))
    springs.__dict__["_lap"] = (springs.ends, n, pattern)
    return pattern


def laplacian_with_shift(springs: Springs, n: int, shift=None):
    """(K + shift I as CSC, diagonal of K (n,)) for `stiffness_laplacian`; shift None: K itself;
    shift a function diag -> eps: K + eps I with eps computed from K's diagonal (what
    `relax` factorises).  The same arrays as scipy's ``(K + eps * identity).tocsc()``."""
    pattern = _laplacian_pattern(springs, n) if len(springs.ends) else None
    if pattern is None:
        K = _laplacian_general(springs, n)
        diag = K.diagonal()
        if shift is None:
            return K, diag
        return (K + shift(diag) * sp.identity(n, format="csc")).tocsc(), diag
    order, first, pair, off_ptr, (rows, cols, pos_d, pos_o) = pattern
    v = np.r_[-springs.stiffness, -springs.stiffness][order]
    off = v[first]
    off[pair] = v[first[pair]] + v[first[pair] + 1]
    rowsum = np.zeros(n)
    major = np.flatnonzero(np.diff(off_ptr))
    if len(major):
        rowsum[major] = np.add.reduceat(off, off_ptr[major])  # as scipy's sum(axis=1)
    diag = -rowsum  # K = K_off - diags(rowsum): 0 - rowsum on the diagonal
    dvals = diag.copy()
    if shift is not None:
        # K + eps I: diagonal entries of K (where rowsum != 0) + eps, the others 0 + eps
        dvals = np.where(rowsum != 0, diag + shift(diag), shift(diag))
    data = np.empty(len(rows))
    data[pos_d] = dvals
    data[pos_o] = off
    keep = data != 0  # sparse sums drop the entries that come out zero
    data, rows_k, cols_k = data[keep], rows[keep], cols[keep]
    ptr = np.r_[0, np.cumsum(np.bincount(rows_k, minlength=n))]
    idx_dtype = np.int32 if max(n, len(data)) < 2**31 - 1 else np.int64
    # K is symmetric: its CSR arrays are its CSC arrays
    return sp.csc_matrix((data, cols_k.astype(idx_dtype), ptr.astype(idx_dtype)), shape=(n, n)), diag


def stiffness_laplacian(springs: Springs, n: int):
    """K (n,n) = sum_s c_s (e_p - e_q)(e_p - e_q)^T: the springs' Hessian at rest, per coordinate (CSC).

    Built on the cached pattern (`_laplacian_pattern`; the refinement asks for a new
    stiffness every round), step for step as the general path `_laplacian_general`
    (kept for three or more springs on one vertex pair, whose sum order would matter):
    duplicates summed, the row sums reduced as scipy's ``sum(axis=1)`` does, zero results
    dropped as sparse sums drop them: the same arrays."""
    return laplacian_with_shift(springs, n)[0]


def _laplacian_general(springs: Springs, n: int):
    """`stiffness_laplacian` by scipy's COO -> CSR path."""
    p, q = springs.ends[:, 0], springs.ends[:, 1]
    c = springs.stiffness
    K = sp.coo_matrix((np.r_[-c, -c], (np.r_[p, q], np.r_[q, p])), shape=(n, n)).tocsr()
    K = K - sp.diags(np.asarray(K.sum(axis=1)).ravel())
    return K.tocsc()

