"""Thick sheets: the mid-surface to unfold and the sheet-or-print advice.

A sheet of thickness t (mm) laid on the skin bends about its middle, strained by about +-t / (2 R)
where the skin bends to radius R: the piece to cut is the mid-surface, the skin moved out by t/2,
and where R < `SHEET_RADIUS_FACTOR` t (5 t: +-10 % strain) a sheet should not be used.  Input
V (n,3) mm, F (m,3); normals and curvature are taken at the analysis scale sigma (mm):

* `principal_curvatures`: per vertex the unit normal (n,3) and k1 >= k2 (n,) in 1/mm, from a
  weighted least-squares linear field fitted to the neighbours' raw normals (eq. 3-2), two passes;
  k > 0 where the surface bends away from the side its normals point to;
* `mid_surface`: every vertex moved by t/2 along its normal, at most `CLAMP_FRACTION` of the concave
  radius 1 / |k2|, halved on triangles that would fold (`folded_triangles`, `MIN_AREA_RATIO`);
* `piece_bending`: per piece R_min = 1 / the area-weighted (1 - `BENDING_AREA_SHARE`) quantile of
  max(|k1|, |k2|), strain t / (2 R_min); "sheet" iff R_min >= 5 t and EL <= max_el, else "print";
* `check_sheet_thickness`: a thickness above the region's width (`region_width`, mm) is refused.

NaN/inf, bad indices and zero-area triangles raise `BolusError` (`topology.check_mesh`).

Design notes: docs/design/unfold.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from ..errors import BolusError
from .piece_advice import DEFAULT_WARN_FRACTION
from ..analysis.saliency import DEFAULT_SMOOTHING_MM, lumped_mass
from ..mesh.topology import MeshTopology, check_mesh

__all__ = [
    "SHEET_RADIUS_FACTOR",
    "CLAMP_FRACTION",
    "MIN_AREA_RATIO",
    "BENDING_AREA_SHARE",
    "MidSurface",
    "PieceBending",
    "PrincipalCurvatures",
    "mid_surface",
    "check_sheet_thickness",
    "check_thickness",
    "region_width",
    "folded_triangles",
    "piece_bending",
    "principal_curvatures",
]

#: a sheet is advised only where the skin's smallest radius is at least this times the
#: thickness (strain t / (2 R) at most 10 %)
SHEET_RADIUS_FACTOR = 5.0
#: the offset never exceeds this fraction of the local concave radius (docs/design/unfold.md)
CLAMP_FRACTION = 0.5
#: an offset triangle keeps at least this share of its skin triangle's (projected) area
MIN_AREA_RATIO = 0.05
#: R_min is the radius reached by the most tightly curved 5 % of a piece's area
BENDING_AREA_SHARE = 0.05
#: neighbours (nearest in space) in the window of the normal fit, at most
WINDOW_NEIGHBOURS = 96
#: the window's width is at least the distance to this neighbour (coarse meshes)
MIN_WINDOW_NEIGHBOURS = 8
#: halving rounds of the flip check before the offending corners are set to 0 at once
_FLIP_ROUNDS = 60


@dataclass
class MidSurface:
    """The mid-surface of a sheet on the skin (docs/design/unfold.md).

    V (n,3) mm: the skin moved out by offset along normals; offset (n,) mm actually moved
    (t/2, less where clamped); clamped (n,) bool: moved less than t/2; normals (n,3) unit
    normals at the analysis scale (zero for vertices in no triangle)."""

    V: np.ndarray
    offset: np.ndarray
    clamped: np.ndarray
    normals: np.ndarray


@dataclass
class PieceBending:
    """Bending of one piece: R_min_mm (inf for a flat piece), strain t / (2 R_min) as a
    fraction, advice "sheet" or "print", reason: one sentence why print ("" for sheet)."""

    R_min_mm: float
    strain: float
    advice: str
    reason: str

    def as_dict(self) -> dict:
        """JSON-safe: R_min_mm None for a flat piece (infinite radius)."""
        R = self.R_min_mm if np.isfinite(self.R_min_mm) else None
        return {"R_min_mm": R, "strain": self.strain, "advice": self.advice, "reason": self.reason}


@dataclass
class PrincipalCurvatures:
    """k1 >= k2 (n,) 1/mm at every vertex (positive: bends away from the normals' side),
    normals (n,3) the unit normals at the analysis scale they refer to."""

    k1: np.ndarray
    k2: np.ndarray
    normals: np.ndarray

    @property
    def kmax(self) -> np.ndarray:
        """(n,) max(|k1|, |k2|): 1 / the smallest principal radius."""
        return np.maximum(np.abs(self.k1), np.abs(self.k2))


def check_thickness(thickness_mm) -> float:
    """The sheet thickness in mm as a float; BolusError unless a number >= 0."""
    try:
        t = float(thickness_mm)
    except (TypeError, ValueError):
        raise BolusError(f"the sheet thickness must be a number of mm, got {thickness_mm!r}") from None
    if not np.isfinite(t) or t < 0:
        raise BolusError(f"the sheet thickness must be 0 (no sheet) or a positive number of mm, got {thickness_mm}")
    return t


def _check_sigma(sigma_mm) -> float:
    try:
        s = float(sigma_mm)
    except (TypeError, ValueError):
        s = float("nan")
    if not np.isfinite(s) or s < 0:
        raise BolusError(f"the smoothing scale must be 0 or a positive number of mm, got {sigma_mm}")
    return s


def _unit(X: np.ndarray) -> np.ndarray:
    ln = np.linalg.norm(X, axis=-1, keepdims=True)
    return np.divide(X, ln, out=np.zeros_like(X), where=ln > 0)


def _tangent_frame(N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents (e1, e2), each (n,3), with (e1, e2, N) right-handed."""
    helper = np.where(np.abs(N[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = _unit(np.cross(N, helper))
    return e1, np.cross(N, e1)


def _normal_fit(Nn, w, D, frame):
    """Weighted least squares n_j ~ c + g_u u_j + g_v v_j in the tangent frame of ``frame``
    (n,3): D (n,k,3) offsets to the neighbours, Nn (n,k,3) their normals, w (n,k) weights.
    Returns (c, g_u, g_v, e1, e2), each (n,3)."""
    e1, e2 = _tangent_frame(frame)
    X = np.ones(D.shape)  # (n,k,3): 1, u, v (batched matmul: far faster than einsum here)
    X[..., 1:] = D @ np.stack([e1, e2], axis=2)
    XWt = (X * w[..., None]).transpose(0, 2, 1)
    A = XWt @ X
    B = XWt @ Nn
    # a tiny ridge on the gradient keeps a window of collinear points solvable (gradient 0 across)
    ridge = 1e-9 * (A[:, 1, 1] + A[:, 2, 2]) + 1e-30
    A[:, 1, 1] += ridge
    A[:, 2, 2] += ridge
    beta = np.linalg.solve(A, B)
    return beta[:, 0], beta[:, 1], beta[:, 2], e1, e2


def principal_curvatures(V, F, sigma_mm: float = DEFAULT_SMOOTHING_MM,
                         topo: MeshTopology | None = None) -> PrincipalCurvatures:
    """Principal curvatures k1 >= k2 (n,) 1/mm and unit normals (n,3) at the analysis scale.

    V (n,3) mm, F (m,3); sigma_mm >= 0 the window scale (docs/design/unfold.md; 0: the smallest window
    the mesh allows, about two rings); topo: the `MeshTopology` of (V, F) if at hand.
    Vertices in no triangle get k = 0 and a zero normal.  `BolusError` on NaN/inf, bad
    indices and zero-area triangles.
    """
    sigma = _check_sigma(sigma_mm)
    if topo is None:
        topo = MeshTopology(*check_mesh(V, F, "the region"))
    else:
        topo.require_valid("the region")
    N0 = topo.vertex_normals
    idx = np.nonzero(topo.used_vertices & (np.einsum("ij,ij->i", N0, N0) > 0))[0]
    P, Ni = topo.V[idx], N0[idx]
    k = min(WINDOW_NEIGHBOURS, len(idx))
    dist, nb = cKDTree(P).query(P, k=k)
    dist, nb = dist.reshape(len(idx), k), nb.reshape(len(idx), k)
    h = np.maximum(sigma, dist[:, min(MIN_WINDOW_NEIGHBOURS, k - 1)])
    Nn = Ni[nb]
    mass = lumped_mass(topo.V, topo.F)[idx]
    # the other side of a thin wall (a nostril) is near in space, not on the surface: left out
    w = mass[nb] * np.exp(-0.5 * (dist / h[:, None]) ** 2) * ((Nn @ Ni[:, :, None])[..., 0] > 0)
    D = P[nb] - P[:, None, :]
    frame = _unit((w[:, None, :] @ Nn)[:, 0])
    frame = np.where(np.einsum("ij,ij->i", frame, frame)[:, None] > 0, frame, Ni)
    for _ in range(2):  # the second pass fits the first pass's normals, in their tangent planes
        c, gu, gv, e1, e2 = _normal_fit(Nn, w, D, frame)
        nrm = _unit(c)
        frame = np.where(np.einsum("ij,ij->i", nrm, nrm)[:, None] > 0, nrm, frame)
        Nn = frame[nb]
    a, d = np.einsum("ij,ij->i", gu, e1), np.einsum("ij,ij->i", gv, e2)
    b = 0.5 * (np.einsum("ij,ij->i", gv, e1) + np.einsum("ij,ij->i", gu, e2))
    mean, rad = 0.5 * (a + d), np.sqrt(0.25 * (a - d) ** 2 + b * b)
    k1, k2, N = np.zeros(topo.n), np.zeros(topo.n), np.zeros((topo.n, 3))
    k1[idx], k2[idx], N[idx] = mean + rad, mean - rad, frame
    return PrincipalCurvatures(k1, k2, N)


def _curvatures(topo: MeshTopology, sigma_mm, given: PrincipalCurvatures | None) -> PrincipalCurvatures:
    """`principal_curvatures` of topo, or the ``given`` ones after a shape check."""
    if given is None:
        return principal_curvatures(topo.V, topo.F, sigma_mm, topo=topo)
    ok = all(np.shape(a) == (topo.n,) for a in (given.k1, given.k2)) and np.shape(given.normals) == (topo.n, 3)
    if not ok:
        raise BolusError(f"the curvatures given are not those of this region ({topo.n} vertices)")
    return given


def mid_surface(V, F, thickness_mm, *, sigma_mm: float = DEFAULT_SMOOTHING_MM,
                curvatures: PrincipalCurvatures | None = None) -> MidSurface:
    """The skin V (n,3) mm, F (m,3) moved out by thickness_mm / 2 along its normals (docs/design/unfold.md).

    thickness 0: V unchanged (a copy), offset 0.  The offset is clamped where the surface is
    concave towards the offset side with radius under t / (2 `CLAMP_FRACTION`), then
    wherever an offset triangle would flip or keep less than `MIN_AREA_RATIO` of its area.
    sigma_mm: the scale of normals and curvature (keyword; 0 = the smallest window);
    curvatures: `principal_curvatures` of (V, F) already computed (keyword; then sigma_mm
    is not used), e.g. shared with `piece_bending`.
    `BolusError` on a negative / NaN / infinite thickness and on degenerate meshes.
    """
    t = check_thickness(thickness_mm)
    topo = MeshTopology(*check_mesh(V, F, "the region"))
    curv = _curvatures(topo, sigma_mm, curvatures)
    V, F, N = topo.V, topo.F, curv.normals
    used = topo.used_vertices
    if t == 0:
        return MidSurface(V.copy(), np.zeros(topo.n), np.zeros(topo.n, dtype=bool), N)
    concave = np.maximum(-curv.k2, 0.0)
    limit = np.divide(CLAMP_FRACTION, concave, out=np.full(topo.n, np.inf), where=concave > 0)
    d = np.where(used, np.minimum(0.5 * t, limit), 0.0)
    rounds = 0
    while True:
        W = V + d[:, None] * N
        bad = folded_triangles(V, W, F)
        if not bad.any():
            break
        corners = np.unique(F[bad])
        # halve a few times; then give up on the offset at those corners (terminates:
        # every round sets at least one more offset to 0, and offset 0 is the skin)
        d[corners] = 0.5 * d[corners] if rounds < _FLIP_ROUNDS else 0.0
        rounds += 1
    clamped = used & (d < 0.5 * t * (1.0 - 1e-9))
    return MidSurface(W, d, clamped, N)


def folded_triangles(V, W, F) -> np.ndarray:
    """(m,) bool: triangles of F (m,3) whose copy on W (n,3) has flipped against, or kept less
    than `MIN_AREA_RATIO` of, its triangle on V (n,3) (area projected on its normal), or
    has an edge pointing backwards (a fold through both directions at once, such as a
    sphere offset past its centre, keeps the normal but reverses every edge)."""
    c0 = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    c1 = np.cross(W[F[:, 1]] - W[F[:, 0]], W[F[:, 2]] - W[F[:, 0]])
    bad = np.einsum("ij,ij->i", c0, c1) <= MIN_AREA_RATIO * np.einsum("ij,ij->i", c0, c0)
    for k in range(3):
        a, b = F[:, k], F[:, (k + 1) % 3]
        bad |= np.einsum("ij,ij->i", V[b] - V[a], W[b] - W[a]) <= 0
    return bad


def region_width(V, F) -> float:
    """The region's width in mm (docs/design/unfold.md): twice the largest distance from the boundary of
    a vertex (edge paths) or of the middle of an inner edge joining two border vertices (half
    its length: a strip one triangle wide has no inner vertex), at least the largest
    inscribed circle of a triangle; a closed region: its smallest extent along its
    principal axes.  V (n,3) mm, F (m,3)."""
    topo = MeshTopology(*check_mesh(V, F, "the region", nondegenerate=False))
    used = np.nonzero(topo.used_vertices)[0]
    border = np.nonzero(topo.boundary_vertices)[0]
    if len(border) == 0:
        P = topo.V[used] - topo.V[used].mean(axis=0)
        _, _, axes = np.linalg.svd(P, full_matrices=False)
        proj = P @ axes.T
        return float((proj.max(axis=0) - proj.min(axis=0)).min())
    E, L = topo.edges, topo.edge_lengths
    G = sp.coo_matrix((L, (E[:, 0], E[:, 1])), shape=(topo.n, topo.n)).tocsr()
    dist = dijkstra(G, directed=False, indices=border, min_only=True)
    across = ~topo.boundary_edges & topo.boundary_vertices[E[:, 0]] & topo.boundary_vertices[E[:, 1]]
    mid = 0.5 * L[across]  # an inner edge from border to border: its middle is about L/2 inside
    perimeter = L[topo.face_edges].sum(axis=1)
    incircle = np.divide(4.0 * topo.areas, perimeter, out=np.zeros(topo.m), where=perimeter > 0)
    r = np.r_[dist[used], mid, 0.5 * incircle]
    return float(2.0 * r[np.isfinite(r)].max())


def check_sheet_thickness(V, F, thickness_mm) -> None:
    """`BolusError` when the sheet thickness is larger than the region's width
    (`region_width`, docs/design/unfold.md) or not a number >= 0; the message gives the width in mm
    and what to choose.  V (n,3) mm, F (m,3)."""
    t = check_thickness(thickness_mm)
    width = region_width(V, F)
    if t > width:
        raise BolusError(
            f"the sheet thickness {t:g} mm is larger than the region, which is about {width:.1f} mm across "
            f"at its widest (twice the largest distance from its border): choose a thickness below "
            f"{width:.1f} mm (a sheet is advised only where the skin's radius is at least "
            f"{SHEET_RADIUS_FACTOR:g} x the thickness), select a larger region, or use the printed bolus")


def _weighted_quantile(x: np.ndarray, w: np.ndarray, q: float) -> float:
    order = np.argsort(x)
    cw = np.cumsum(w[order])
    if cw[-1] <= 0:
        return float(np.quantile(x, q))
    k = int(np.searchsorted(cw, q * cw[-1], side="left"))
    return float(x[order][min(k, len(x) - 1)])


def piece_bending(V, F, piece, thickness_mm, EL, max_el, sigma_mm: float = DEFAULT_SMOOTHING_MM, *,
                  curvatures: PrincipalCurvatures | None = None) -> list[PieceBending]:
    """Bending strain and sheet-or-print advice of every piece (docs/design/unfold.md).

    V (n,3) mm, F (m,3): the SKIN region (not the mid-surface); piece (m,) int: the piece
    of every triangle (-1: none); thickness_mm >= 0; EL: sequence, the EL of pieces 0..p-1
    (fractions); max_el: fraction (0: the EL test uses `piece_advice.DEFAULT_WARN_FRACTION`);
    sigma_mm: scale of the curvature (curvatures: as in `mid_surface`).  Returns p `PieceBending`: advice "sheet" iff
    R_min >= `SHEET_RADIUS_FACTOR` t and EL <= max_el; thickness 0: strain 0, advice from
    EL only.  `BolusError` on bad arrays / numbers and a piece with no triangle.
    """
    t = check_thickness(thickness_mm)
    topo = MeshTopology(*check_mesh(V, F, "the region"))
    EL = np.asarray(EL, dtype=np.float64).ravel()
    if len(EL) == 0 or not np.isfinite(EL).all() or (EL < 0).any():
        raise BolusError(f"EL must give a number >= 0 for every piece, got {EL.tolist()}")
    try:
        max_el = float(max_el)
    except (TypeError, ValueError):
        raise BolusError(f"max_el must be a number, got {max_el!r}") from None
    if not np.isfinite(max_el) or max_el < 0:
        raise BolusError(f"max_el must be 0 (off) or a positive fraction, got {max_el}")
    piece = np.asarray(piece)
    if piece.shape != (topo.m,) or (piece.size and not np.issubdtype(piece.dtype, np.integer)):
        raise BolusError(f"piece must give an integer piece for each of the {topo.m} triangles, "
                         f"got shape {piece.shape}")
    p = len(EL)
    out_of_range = np.nonzero((piece < -1) | (piece >= p))[0]
    if len(out_of_range):
        raise BolusError(f"triangle {int(out_of_range[0])} has piece {int(piece[out_of_range[0]])}, "
                         f"but EL gives {p} piece(s) (0..{p - 1}, -1 for none)")
    counts = np.bincount(piece[piece >= 0], minlength=p)
    if (counts == 0).any():
        raise BolusError(f"piece {int(np.argmin(counts))} has no triangles")
    curv = _curvatures(topo, sigma_mm, curvatures)
    kf = curv.kmax[topo.F].mean(axis=1)
    el_limit = max_el if max_el > 0 else DEFAULT_WARN_FRACTION
    out = []
    for j in range(p):
        sel = piece == j
        q = _weighted_quantile(kf[sel], topo.areas[sel], 1.0 - BENDING_AREA_SHARE)
        R = 1.0 / q if q > 0 else float("inf")
        strain = 0.0 if t == 0 or not np.isfinite(R) else t / (2.0 * R)
        why = []
        if t > 0 and R < SHEET_RADIUS_FACTOR * t:
            why.append(f"the skin bends to a radius of {R:.0f} mm, under {SHEET_RADIUS_FACTOR:g} x the {t:g} mm "
                       f"thickness (strain +-{100 * strain:.0f} %)")
        if EL[j] > el_limit:
            why.append(f"its pattern's length error EL {100 * EL[j]:.1f} % is above {100 * el_limit:.1f} %")
        reason = ("use the printed bolus: " + " and ".join(why) + ".") if why else ""
        out.append(PieceBending(float(R), float(strain), "print" if why else "sheet", reason))
    return out
