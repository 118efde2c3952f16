"""Printing features of a part for a build direction (seed 6.1, eqs. 6-1..6-14; SPEC "Print orientation").

For a part with faces f (unit normal n_f, area A_f mm^2, centroid c_f mm) and a unit build
direction b pointing up from the build plate, h the layer height (mm):

* cusp height gamma_f = |n_f . b| h (eq. 6-1), surface quality E(f) = gamma_f A_f
  (eq. 6-2) and E(M) = sum_f E(f) (eq. 6-3); over the part this is
  WQ(b) = sum_f h |n_f . b| A_f (eq. 6-7 with d = b), in mm^3;
* a face is an overhang when n_f . b < -cos 45 deg (critical angle of 6.1.2);
* the plate lies at z0 = min over the part's vertices of v . b, and a face's support
  column is l_f = c_f . b - z0 (eqs. 6-9..6-11 with the datum plane on the plate);
  WU(b) = sum_overhang A_f l_f (eq. 6-14, fill ratio lambda = 1), in mm^3;
* the physical support volume is sum_overhang A_f |n_f . b| l_f, in mm^3.

Every face counts once, with its own normal as given; NaN/inf coordinates and bad indices
raise `BolusError`, zero-area faces add nothing.  `PrintTerms` holds the sums over faces from
which WQ, WU and support follow, for many directions at once (`orientation`).

Design notes: docs/design/printing.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import BolusError
from ..mesh.topology import MeshTopology, check_mesh

__all__ = [
    "LAYER_MM",
    "CRITICAL_ANGLE_DEG",
    "DEFAULT_CHUNK",
    "PrintObjective",
    "PrintTerms",
    "fibonacci_sphere",
    "unit_rows",
    "check_part",
    "check_print_settings",
    "cusp_height",
    "surface_quality",
    "overhang_faces",
    "face_support",
    "print_objective",
    "open_surface_note",
]

LAYER_MM = 0.2  #: SPEC's layer height h
CRITICAL_ANGLE_DEG = 45.0  #: SPEC's overhang limit (section 6.1.2)
DEFAULT_CHUNK = 1 << 18  #: floats per (faces x directions) block: bounded memory, still vectorised
HULL_ALL_POINTS = 64  #: below this many points the plate is searched over all of them (no hull needed)

_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


def fibonacci_sphere(k: int) -> np.ndarray:
    """k (>= 1) nearly uniform unit directions (k,3) on the sphere (Fibonacci lattice)."""
    k = int(k)
    if k < 1:
        raise BolusError(f"ask for at least one direction, got {k}")
    i = np.arange(k) + 0.5
    z = 1.0 - 2.0 * i / k
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    t = _GOLDEN_ANGLE * i
    return np.stack([r * np.cos(t), r * np.sin(t), z], axis=1)


def unit_rows(B, what: str = "build direction") -> np.ndarray:
    """B (3,) or (k,3) scaled to unit length; BolusError for NaN/inf or zero vectors."""
    B = np.asarray(B, dtype=np.float64)
    single = B.ndim == 1
    B = np.atleast_2d(B)
    if B.shape[-1] != 3 or B.ndim != 2:
        raise BolusError(f"a {what} must be a 3-vector (or a (k, 3) array), got shape {np.shape(B)}")
    n = np.linalg.norm(B, axis=1, keepdims=True)
    if not np.all(np.isfinite(B)) or np.any(n < 1e-12):
        raise BolusError(f"a {what} must be a finite, non-zero vector")
    B = B / n
    return B[0] if single else B


def check_part(V, F, topo: MeshTopology | None = None) -> MeshTopology:
    """The `MeshTopology` of the part V (n,3) mm, F (m,3), checked (module doc: degenerate input)."""
    if topo is None:
        topo = MeshTopology(*check_mesh(V, F, "the part", nondegenerate=False, min_faces=0))
    if topo.m == 0:
        raise BolusError("the part has no faces; select at least one face")
    if not float(topo.areas.sum()) > 0.0:
        raise BolusError("the part has zero area (all its faces are degenerate); check the mesh")
    return topo


def check_print_settings(h, critical_angle_deg) -> tuple[float, float]:
    """(h, cos of the critical angle) after checking both."""
    h = float(h)
    if not (h > 0 and np.isfinite(h)):
        raise BolusError(f"the layer height must be a positive number of mm, got {h}")
    a = float(critical_angle_deg)
    if not 0.0 < a < 90.0:
        raise BolusError(f"the critical angle must lie between 0 and 90 degrees, got {critical_angle_deg}")
    return h, float(np.cos(np.radians(a)))


def cusp_height(N, b, h: float = LAYER_MM) -> np.ndarray:
    """Eq. 6-1: gamma = |n . b| h for unit normals N (m,3) and a direction b (3,) -> (m,)."""
    return np.abs(np.asarray(N, dtype=np.float64) @ unit_rows(b)) * float(h)


def surface_quality(V, F, b, h: float = LAYER_MM) -> tuple[np.ndarray, float]:
    """Eqs. 6-2, 6-3: E(f) = gamma_f area(f) (m,) and E(M) = sum E(f), in mm^3."""
    topo = check_part(V, F)
    E = cusp_height(topo.face_normals, b, h) * topo.areas
    return E, float(E.sum())


def overhang_faces(N, b, critical_angle_deg: float = CRITICAL_ANGLE_DEG) -> np.ndarray:
    """(m,) bool: n . b < -cos(critical angle) -- the face looks down (section 6.1.2)."""
    return np.asarray(N, dtype=np.float64) @ unit_rows(b) < -np.cos(np.radians(critical_angle_deg))


def face_support(V, F, b, critical_angle_deg: float = CRITICAL_ANGLE_DEG) -> np.ndarray:
    """Eqs. 6-9..6-11 per face (m,): area(f) (c_f . b - z0) on overhangs, 0 elsewhere.

    z0 = min over the part's vertices of v . b (the plate); lambda = 1.  Sum it for WU.
    """
    topo = check_part(V, F)
    b = unit_rows(b)
    z0 = float((topo.V[topo.used_vertices] @ b).min())
    ov = overhang_faces(topo.face_normals, b, critical_angle_deg)
    return np.where(ov, topo.areas * (topo.centroids @ b - z0), 0.0)


@dataclass
class PrintObjective:
    """WQ, WU and support volume (mm^3) for k build directions, each (k,)."""

    WQ: np.ndarray
    WU: np.ndarray
    support_volume: np.ndarray

    @property
    def objective(self) -> np.ndarray:
        """WQ + WU (k,), the quantity `orient` minimises."""
        return self.WQ + self.WU


def hull_points(P: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull of P (r,3) (all of P when the hull cannot be built).

    The plate min_v v . b is attained at a hull vertex (a linear function), so this is exact.
    """
    if len(P) <= HULL_ALL_POINTS:
        return P
    try:
        from scipy.spatial import ConvexHull

        return P[ConvexHull(P).vertices]
    except Exception:  # flat or degenerate point sets (Qhull errors): use every point
        return P


def _column_sums(A, N, P, D, PB, z0, cos_c, support: bool):
    """sum A |n.b|, WU and support volume (each (k,)) of faces with n.b = D (q,k), A c.b = PB (q,k).

    Eqs. 6-7 (without h), 6-14 and SPEC's support volume, for the plates z0 (k,).
    """
    WQ = A @ np.abs(D)
    ov = D < -cos_c
    WU = np.einsum("qk,qk->k", ov, PB) - z0 * np.einsum("q,qk->k", A, ov)  # sum_ov A (c.b - z0)
    SV = None
    if support:
        Dm = np.where(ov, D, 0.0)
        SV = z0 * (A @ Dm) - np.einsum("qk,qk->k", Dm, PB)  # sum_ov A |n.b| (c.b - z0)
    return WQ, WU, SV


class PrintTerms:
    """Sums over faces (or over normal bins) from which WQ, WU and support follow.

    A (q,) area, N (q,3) unit normal, P (q,3) first moment sum A c, H (r,3) the points
    whose lowest one is the plate.  All coordinates relative to an origin inside the
    part (translation does not change the figures; it keeps float32 screening accurate).
    """

    def __init__(self, A, N, P, H):
        self.A, self.N, self.P, self.H = A, N, P, H

    @classmethod
    def exact(cls, topo: MeshTopology) -> "PrintTerms":
        """Per-face terms of a part, the plate over its convex-hull vertices."""
        origin = topo.V[topo.used_vertices].mean(axis=0)
        C = topo.centroids - origin
        A = topo.areas
        return cls(A, topo.face_normals, A[:, None] * C, hull_points(topo.V[topo.used_vertices] - origin))

    def astype(self, dtype) -> "PrintTerms":
        return PrintTerms(*(x.astype(dtype) for x in (self.A, self.N, self.P, self.H)))

    def evaluate(self, B: np.ndarray, h: float, cos_c: float, chunk: int = DEFAULT_CHUNK, support: bool = True):
        """(WQ, WU, SV) each (k,) for unit directions B (k,3), in blocks of <= chunk floats.

        With ``support=False`` SV is not computed (returned as NaN).
        """
        k = len(B)
        WQ, WU, SV = np.empty(k), np.empty(k), np.full(k, np.nan)
        step = max(1, int(chunk) // max(len(self.A), 1))
        B = B.astype(self.A.dtype, copy=False)
        for s in range(0, k, step):
            Bc = B[s : s + step].T  # (3,kc)
            z0 = (self.H @ Bc).min(axis=0)
            q, u, v = _column_sums(self.A, self.N, self.P, self.N @ Bc, self.P @ Bc, z0, cos_c, support)
            WQ[s : s + step], WU[s : s + step] = q, u
            if support:
                SV[s : s + step] = v
        return h * WQ, np.maximum(WU, 0.0), np.maximum(SV, 0.0) if support else SV

    def evaluate_near(self, b: np.ndarray, T: np.ndarray, radius: float, h: float, cos_c: float,
                      support: bool = True):
        """Exactly what `evaluate` gives for directions T (k,3) within ``radius`` (rad) of b (3,).

        Faces that cannot change side (of n . b = 0 or of the overhang limit) for any
        direction that close are summed once into 3-vectors and a 3x3 moment (WQ, WU and
        support are linear or quadratic in b over them); only the faces in the band are
        evaluated one by one, and the plate only over the vertices that can be lowest.
        """
        r = 2.0 * np.sin(min(radius, np.pi) / 2.0) * (1.0 + 1e-9) + 1e-12  # chord >= |n.t - n.b|
        d = self.N @ b
        band = (np.abs(d) <= r) | (np.abs(d + cos_c) <= r)
        z0 = self._plate_near(b, T, r)
        WQ, WU, SV = self._fixed_sums(d, ~band, T, z0, cos_c, support)
        if band.any():
            q, u, v = _column_sums(self.A[band], self.N[band], self.P[band], self.N[band] @ T.T,
                                   self.P[band] @ T.T, z0, cos_c, support)
            WQ, WU = WQ + q, WU + u
            if support:
                SV = SV + v
        return h * WQ, np.maximum(WU, 0.0), np.maximum(SV, 0.0) if support else SV

    def _plate_near(self, b: np.ndarray, T: np.ndarray, r: float) -> np.ndarray:
        """Plates z0 (k,) of the directions T (k,3) within chord r of b, over the points that can be lowest."""
        hb = self.H @ b
        near = hb <= hb.min() + 2.0 * r * np.sqrt((self.H**2).sum(axis=1).max()) + 1e-12
        return (self.H[near] @ T.T).min(axis=0)

    def _fixed_sums(self, d, fixed, T, z0, cos_c, support: bool):
        """sum A |n.t|, WU and SV (each (k,)) over the faces that keep their side for all T (k,3)."""
        w = np.where(fixed, np.where(d > 0, self.A, -self.A), 0.0)
        WQ = T @ (w @ self.N)  # sum over fixed faces of A sign(n.b) n . t
        ov = fixed & (d < -cos_c)
        WU = T @ self.P[ov].sum(axis=0) - z0 * self.A[ov].sum()
        SV = np.full(len(T), np.nan)
        if support:
            a_ov = self.A[ov] @ self.N[ov]
            M_ov = self.N[ov].T @ self.P[ov]  # sum A n c^T
            SV = z0 * (T @ a_ov) - np.einsum("ki,ij,kj->k", T, M_ov, T)
        return WQ, WU, SV


def print_objective(
    V, F, B, h: float = LAYER_MM, critical_angle_deg: float = CRITICAL_ANGLE_DEG, chunk: int = DEFAULT_CHUNK
) -> PrintObjective:
    """WQ (eq. 6-7), WU (eq. 6-14) and support volume, in mm^3, for directions B (k,3) or (3,).

    Parameters: V (n,3) mm, F (m,3) int, B (k,3) or (3,) (need not be unit length).
    Returns a `PrintObjective` of three (k,) arrays.  Exact SPEC definitions,
    vectorised over faces and directions in blocks of at most ``chunk`` (faces x
    directions) floats, so memory stays bounded; never an (m, m) matrix.
    """
    topo = check_part(V, F)
    B = np.atleast_2d(unit_rows(B))
    h, cos_c = check_print_settings(h, critical_angle_deg)
    WQ, WU, SV = PrintTerms.exact(topo).evaluate(B, h, cos_c, chunk)
    return PrintObjective(WQ, WU, SV)


def open_surface_note(topo: MeshTopology) -> str | None:
    """What the one-sided measures mean on an open surface (module doc), or None when it is closed."""
    nb = int(topo.boundary_edges.sum())
    if not nb:
        return None
    return (f"open surface ({nb} boundary edges): every face is counted once with its normal as given; "
            "support is measured under the faces that look down")
