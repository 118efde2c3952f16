"""Printing features and the print orientation search (seed 6.1, eqs. 6-1..6-20).

For a part with faces f (unit normal n_f, area A_f, centroid c_f) and a unit build
direction b pointing up from the build plate (SPEC "Print orientation"):

* cusp height gamma_f = |n_f . b| h (eq. 6-1), surface quality E(f) = gamma_f A_f
  (eq. 6-2) and E(M) = sum_f E(f) (eq. 6-3); over the part this is
  WQ(b) = sum_f h |n_f . b| A_f (eq. 6-7 with d = b), in mm^3;
* a face is an overhang when n_f . b < -cos 45 deg (critical angle of 6.1.2);
* the plate lies at z0 = min over the part's vertices of v . b, and a face's support
  column is l_f = c_f . b - z0 (eqs. 6-9..6-11 with the datum plane on the plate);
  WU(b) = sum_overhang A_f l_f (eq. 6-14, fill ratio lambda = 1), in mm^3;
* the physical support volume is sum_overhang A_f |n_f . b| l_f (projected area x
  height), in mm^3;
* normal curvature by the Moreton-Sequin estimate (eqs. 6-15..6-20).

The orientation objective is WQ + WU (both mm^3, so they add without weights).

Choices where the seed is vague (the seed searches only the face normals, eqs. 6-4,
6-7, 6-10; SPEC asks for the best b over any dense set of directions):

* Open or non-manifold meshes: every face counts once, with its own normal as given
  (one-sided).  A face needs support when *its* normal looks down; the other side of
  an open shell is not modelled, so for a bolus shell pass the surface whose normals
  point out of the material.  Support is counted from the face's centroid straight
  down to the plate, even when another part of the mesh lies in between (the seed's
  eq. 6-9; a conservative upper bound for nested overhangs).
* ``orient`` screens >= 2,048 directions (a Fibonacci sphere, turned by ``rng``) plus
  "special" directions -- +-the area-weighted mean normals of the largest normal
  clusters (the seed's candidates), +-principal axes, directions that stand the largest
  flat regions on edge, +-X, +-Y, +-Z -- on a reduced float32 model: faces are pooled
  by normal (m/8 bins, 128..1,024; each bin keeps its area, area vector and first
  moment) and the plate is taken over the lowest points in a few hundred directions.
  The best 32 distinct screened directions and the best 8 special ones are evaluated
  exactly.  The objective is only piecewise smooth and even jumps (WU changes by
  A_f l_f when a face crosses the 45 deg limit; many such steps make narrow dips of a
  few percent, about 1-2 deg wide, on scanned surfaces), so gradients and a plain
  pattern search get caught; the refinement is a derivative-free shrinking cap search:
  around each of the best ``starts`` distinct candidates, ``cap_points`` directions
  evenly spread (a Fibonacci disc) over a cap of 2 x the screening spacing (9 deg,
  about 1.3 deg between points, denser than a 10,000-direction sphere), the best kept,
  and the cap shrunk 4x (a third of the points) until it is below ``tol_deg``; starts
  more than 3 % above the best so far are dropped.  These local evaluations are exact
  but cheap: faces that cannot change side within the cap are summed once into
  3-vectors (`_Terms.evaluate_near`).  Exact evaluations use the convex-hull vertices
  for the plate (exact: a linear function is smallest at a hull vertex).  The result is
  the best direction evaluated exactly.
* ``favour`` (optional unit vector, e.g. the mean outward normal of the skin-contact
  side): only directions with b . favour >= ``favour_min_cos`` are allowed (default 0:
  the favoured side never looks down, so its mean direction is never an overhang).  A
  hard constraint, not a penalty, so WQ/WU keep their meaning.
* Normal curvature: eq. 6-17 gives one value per neighbour j; the vertex value is the
  mean over its one-ring edges (the mean of the normal curvatures in the edge
  directions, close to the mean curvature).  Vertex normals are eq. 3-2.  With outward
  normals a convex surface is negative and a concave one positive (eq. 6-19).  Eq. 6-20
  is taken between the 1st and 99th percentiles (``spectral.unit_interval``) so one
  spike does not squash every other value.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import BolusError
from .spectral import as_rng, submesh, unit_interval
from .topology import MeshTopology, as_mesh_arrays

__all__ = [
    "LAYER_MM",
    "CRITICAL_ANGLE_DEG",
    "PrintObjective",
    "Orientation",
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
    "orient_parts",
]

LAYER_MM = 0.2
CRITICAL_ANGLE_DEG = 45.0
TIE_REL = 5e-3  #: objectives within 0.5 % of the best count as equal; the lowest print wins (SPEC allows 1 %)
DEFAULT_CHUNK = 1 << 18  # floats per (faces x directions) block of print_objective

_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


# ----------------------------------------------------------------------------- helpers


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


def _unit_rows(B, what: str = "build direction") -> np.ndarray:
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


def _check_part(V, F, topo: MeshTopology | None = None) -> MeshTopology:
    topo = MeshTopology(V, F) if topo is None else topo
    if topo.m == 0:
        raise BolusError("the part has no faces; select at least one face")
    if not float(topo.areas.sum()) > 0.0:
        raise BolusError("the part has zero area (all its faces are degenerate); check the mesh")
    return topo


def _check_print_settings(h, critical_angle_deg) -> tuple[float, float]:
    """(h, cos of the critical angle) after checking both."""
    h = float(h)
    if not (h > 0 and np.isfinite(h)):
        raise BolusError(f"the layer height must be a positive number of mm, got {h}")
    a = float(critical_angle_deg)
    if not 0.0 < a < 90.0:
        raise BolusError(f"the critical angle must lie between 0 and 90 degrees, got {critical_angle_deg}")
    return h, float(np.cos(np.radians(a)))


def _random_rotation(rng) -> np.ndarray:
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


# ----------------------------------------------------------------- printing features


def cusp_height(N, b, h: float = LAYER_MM) -> np.ndarray:
    """Eq. 6-1: gamma = |n . b| h for unit normals N (m,3) and a direction b (3,) -> (m,)."""
    return np.abs(np.asarray(N, dtype=np.float64) @ _unit_rows(b)) * float(h)


def surface_quality(V, F, b, h: float = LAYER_MM) -> tuple[np.ndarray, float]:
    """Eqs. 6-2, 6-3: E(f) = gamma_f area(f) (m,) and E(M) = sum E(f), in mm^3."""
    topo = _check_part(V, F)
    E = cusp_height(topo.face_normals, b, h) * topo.areas
    return E, float(E.sum())


def overhang_faces(N, b, critical_angle_deg: float = CRITICAL_ANGLE_DEG) -> np.ndarray:
    """(m,) bool: n . b < -cos(critical angle) -- the face looks down (section 6.1.2)."""
    return np.asarray(N, dtype=np.float64) @ _unit_rows(b) < -np.cos(np.radians(critical_angle_deg))


def face_support(V, F, b, critical_angle_deg: float = CRITICAL_ANGLE_DEG) -> np.ndarray:
    """Eqs. 6-9..6-11 per face (m,): area(f) (c_f . b - z0) on overhangs, 0 elsewhere.

    z0 = min over the part's vertices of v . b (the plate); lambda = 1.  Sum it for WU.
    """
    topo = _check_part(V, F)
    b = _unit_rows(b)
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


class _Terms:
    """Sums over faces (or over normal bins) from which WQ, WU and support follow.

    A (q,) area, N (q,3) unit normal, P (q,3) first moment sum A c, H (r,3) the points
    whose lowest one is the plate.  All coordinates relative to ``origin``.
    """

    def __init__(self, A, N, P, H):
        self.A, self.N, self.P, self.H = A, N, P, H

    @classmethod
    def exact(cls, topo: MeshTopology) -> "_Terms":
        origin = topo.V[topo.used_vertices].mean(axis=0)
        C = topo.centroids - origin
        A = topo.areas
        return cls(A, topo.face_normals, A[:, None] * C, _hull_points(topo.V[topo.used_vertices] - origin))

    def binned(self, bin_of: np.ndarray, nbins: int) -> "_Terms":
        """Screening model in float32: faces pooled by normal bin (bin_of (q,) in 0..nbins-1) when
        there are more than 2 nbins faces, and the plate taken over the lowest points in
        max(64, nbins / 2) directions only (approximate)."""
        H = self.H
        nh = max(64, nbins // 2)
        if len(H) > nh:
            H = H[np.unique(np.argmin(fibonacci_sphere(nh) @ H.T, axis=1))]
        if len(self.A) <= 2 * nbins:
            return _Terms(self.A, self.N, self.P, H).astype(np.float32)
        A = np.bincount(bin_of, weights=self.A, minlength=nbins)
        a = np.stack([np.bincount(bin_of, weights=self.A * self.N[:, k], minlength=nbins) for k in range(3)], 1)
        P = np.stack([np.bincount(bin_of, weights=self.P[:, k], minlength=nbins) for k in range(3)], 1)
        keep = A > 0
        A, a, P = A[keep], a[keep], P[keep]
        ln = np.linalg.norm(a, axis=1, keepdims=True)
        N = np.divide(a, ln, out=np.zeros_like(a), where=ln > 0)
        return _Terms(A, N, P, H).astype(np.float32)

    def astype(self, dtype) -> "_Terms":
        return _Terms(*(x.astype(dtype) for x in (self.A, self.N, self.P, self.H)))

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
            D = self.N @ Bc  # n . b (q,kc)
            WQ[s : s + step] = self.A @ np.abs(D)
            ov = D < -cos_c
            PB = self.P @ Bc  # A (c . b)
            z0 = (self.H @ Bc).min(axis=0)
            # sum over overhangs of A (c . b - z0)
            WU[s : s + step] = np.einsum("qk,qk->k", ov, PB) - z0 * np.einsum("q,qk->k", self.A, ov)
            if support:
                Dm = np.where(ov, D, 0.0)
                SV[s : s + step] = z0 * (self.A @ Dm) - np.einsum("qk,qk->k", Dm, PB)
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
        fixed = ~band
        w = np.where(fixed, np.where(d > 0, self.A, -self.A), 0.0)
        a_abs = w @ self.N  # sum over fixed faces of A sign(n.b) n
        ov = fixed & (d < -cos_c)
        A_ov = self.A[ov].sum()
        P_ov = self.P[ov].sum(axis=0)
        hb = self.H @ b
        near = hb <= hb.min() + 2.0 * r * np.sqrt((self.H**2).sum(axis=1).max()) + 1e-12
        z0 = (self.H[near] @ T.T).min(axis=0)
        WQ = T @ a_abs
        WU = T @ P_ov - z0 * A_ov
        SV = np.full(len(T), np.nan)
        if support:
            a_ov = self.A[ov] @ self.N[ov]
            M_ov = self.N[ov].T @ self.P[ov]  # sum A n c^T
            SV = z0 * (T @ a_ov) - np.einsum("ki,ij,kj->k", T, M_ov, T)
        if band.any():
            Db = self.N[band] @ T.T  # (qb,k)
            Ab = self.A[band]
            WQ += Ab @ np.abs(Db)
            ovb = Db < -cos_c
            PB = self.P[band] @ T.T
            WU += np.einsum("qk,qk->k", ovb, PB) - z0 * np.einsum("q,qk->k", Ab, ovb)
            if support:
                Dm = np.where(ovb, Db, 0.0)
                SV += z0 * (Ab @ Dm) - np.einsum("qk,qk->k", Dm, PB)
        return h * WQ, np.maximum(WU, 0.0), np.maximum(SV, 0.0) if support else SV


def _hull_points(P: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull of P (r,3) (all of P when the hull cannot be built)."""
    if len(P) <= 64:
        return P
    try:
        from scipy.spatial import ConvexHull

        return P[ConvexHull(P).vertices]
    except Exception:  # flat or degenerate point sets (Qhull errors): use every point
        return P


def print_objective(
    V, F, B, h: float = LAYER_MM, critical_angle_deg: float = CRITICAL_ANGLE_DEG, chunk: int = DEFAULT_CHUNK
) -> PrintObjective:
    """WQ (eq. 6-7), WU (eq. 6-14) and support volume, in mm^3, for directions B (k,3) or (3,).

    Exact SPEC definitions, vectorised over faces and directions in blocks of at most
    ``chunk`` (faces x directions) floats (about six such blocks live at once), so
    memory stays bounded; never an (m, m) matrix.  B need not be unit length.
    """
    topo = _check_part(V, F)
    B = np.atleast_2d(_unit_rows(B))
    h, cos_c = _check_print_settings(h, critical_angle_deg)
    t = _Terms.exact(topo)
    WQ, WU, SV = t.evaluate(B, h, cos_c, chunk)
    return PrintObjective(WQ, WU, SV)


# ------------------------------------------------------------------- normal curvature


@dataclass
class NormalCurvature:
    """Moreton-Sequin normal curvature (1/mm): per vertex (n,) eq. 6-17 averaged over the
    one ring, per face (m,) eq. 6-18, and the face values mapped to [0, 1] (eq. 6-20)."""

    vertex: np.ndarray
    face: np.ndarray
    face_normalised: np.ndarray

    def concave(self, eps: float = 0.0) -> np.ndarray:
        """(m,) bool: eq. 6-19, K(f) > eps (concave for outward normals)."""
        return self.face > eps


def normal_curvature(V, F, topo: MeshTopology | None = None) -> NormalCurvature:
    """Eqs. 6-15..6-20 on a triangle mesh V (n,3), F (m,3) (see the module doc)."""
    topo = MeshTopology(V, F) if topo is None else topo
    E = topo.edges
    Nv = topo.vertex_normals
    d = topo.V[E[:, 1]] - topo.V[E[:, 0]]
    dd = np.einsum("ij,ij->i", d, d)
    dd = np.where(dd > 0, dd, np.inf)
    k01 = 2.0 * np.einsum("ij,ij->i", Nv[E[:, 0]], d) / dd  # eq. 6-17 at E[:,0] towards E[:,1]
    k10 = -2.0 * np.einsum("ij,ij->i", Nv[E[:, 1]], d) / dd
    n = topo.n
    s = np.bincount(E[:, 0], weights=k01, minlength=n) + np.bincount(E[:, 1], weights=k10, minlength=n)
    c = np.bincount(E.ravel(), minlength=n)
    Kv = np.divide(s, c, out=np.zeros(n), where=c > 0)
    Kf = Kv[topo.F].mean(axis=1)  # eq. 6-18
    return NormalCurvature(Kv, Kf, unit_interval(Kf))  # eq. 6-20


# ----------------------------------------------------------------------- placement


def rotation_to_z(b) -> np.ndarray:
    """The proper rotation R (3,3) with R @ b = +Z (shortest arc; b = -Z turns about X)."""
    b = _unit_rows(b)
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


def _normal_clusters(N: np.ndarray, A: np.ndarray, bin_of: np.ndarray, nbins: int, top: int = 16) -> np.ndarray:
    """Area-weighted mean normals (<= top, 3) of the largest normal bins, largest first."""
    area = np.bincount(bin_of, weights=A, minlength=nbins)
    a = np.stack([np.bincount(bin_of, weights=A * N[:, k], minlength=nbins) for k in range(3)], 1)
    order = np.argsort(-area)[:top]
    order = order[area[order] > 0]
    a = a[order]
    ln = np.linalg.norm(a, axis=1)
    keep = ln > 0.5 * area[order]  # a bin whose normals nearly cancel has no direction
    return a[keep] / ln[keep, None]


def _special_directions(topo: MeshTopology, bin_of: np.ndarray, nbins: int, favour) -> np.ndarray:
    """Candidate directions suggested by the geometry (see module doc)."""
    out = [np.eye(3), -np.eye(3)]
    big = _normal_clusters(topo.face_normals, topo.areas, bin_of, nbins)
    out += [big, -big]  # the seed's candidates: the normals of the largest flat regions, both ways
    C = topo.centroids - topo.centroids.mean(axis=0)
    w = topo.areas / topo.areas.sum()
    _, axes = np.linalg.eigh((C * w[:, None]).T @ C)
    out += [axes.T, -axes.T]
    top = big[:4]
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
    """Indices of up to ``count`` lowest f whose directions are >= min_angle apart."""
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


def orient(
    V,
    F,
    h: float = LAYER_MM,
    critical_angle_deg: float = CRITICAL_ANGLE_DEG,
    favour=None,
    favour_min_cos: float = 0.0,
    n_directions: int = 2048,
    starts: int = 4,
    cap_points: int = 160,
    cap_radius: float = 2.0,
    candidates: int = 32,
    tol_deg: float = 0.1,
    drop_above: float = 0.03,
    rng=0,
    topo: MeshTopology | None = None,
    progress=None,
) -> Orientation:
    """The build direction b minimising WQ + WU (eqs. 6-7, 6-14) of the part V (n,3), F (m,3).

    Screens ``n_directions`` (>= 2,048 recommended) Fibonacci directions plus special
    ones on a binned model, evaluates the best ``candidates`` exactly and refines
    ``starts`` of them by a shrinking cap search down to ``tol_deg`` (module doc).
    ``favour`` (3,): directions with b . favour < ``favour_min_cos`` are not allowed.
    ``rng`` turns the Fibonacci sphere.  ``topo``: a `MeshTopology` of (V, F) already built.
    """
    report = progress or (lambda f, t: None)
    topo = _check_part(V, F, topo)
    h, cos_c = _check_print_settings(h, critical_angle_deg)
    fav = None if favour is None else _unit_rows(favour, "favoured direction")
    if fav is not None and not -1.0 <= favour_min_cos < 1.0:
        raise BolusError(f"favour_min_cos must lie in [-1, 1), got {favour_min_cos}")
    n_directions = max(int(n_directions), 16)

    from scipy.spatial import cKDTree

    exact = _Terms.exact(topo)
    nbins = int(np.clip(topo.m // 8, 128, 1024))
    _, bin_of = cKDTree(fibonacci_sphere(nbins)).query(topo.face_normals)
    coarse = exact.binned(bin_of, nbins)
    evaluations = 0

    def allowed(B):
        return np.ones(len(B), bool) if fav is None else B @ fav >= favour_min_cos - 1e-12

    def f_exact(B):
        nonlocal evaluations
        ok = allowed(B)
        out = np.full(len(B), np.inf)
        if ok.any():
            WQ, WU, _ = exact.evaluate(B[ok], h, cos_c, support=False)
            out[ok] = WQ + WU
            evaluations += int(ok.sum())
        return out

    # 1. screening on the binned model
    report(0.05, "screening directions")
    Bfib = fibonacci_sphere(n_directions) @ _random_rotation(rng).T
    special = _special_directions(topo, bin_of, nbins, fav)
    B = np.concatenate([Bfib, special])
    ok = allowed(B)
    if fav is not None and not ok.any():
        B, ok = np.concatenate([B, fav[None]]), np.r_[ok, True]
    f_coarse = np.full(len(B), np.inf)
    WQc, WUc, _ = coarse.evaluate(B[ok], h, cos_c, support=False)
    f_coarse[ok] = WQc + WUc
    spacing = np.sqrt(4.0 * np.pi / n_directions)

    # 2. exact values of the best distinct screened directions (and of the best special ones)
    report(0.3, "evaluating candidates")
    pick = _distinct_best(B, f_coarse, candidates, 1.5 * spacing)
    sp_idx = len(Bfib) + _distinct_best(special, f_coarse[len(Bfib):], 8, 1e-3)
    pick = np.unique(np.r_[pick, sp_idx])
    Bc = B[pick]
    fc = f_exact(Bc)
    best_i = int(np.argmin(fc))
    best_b, best_f = Bc[best_i].copy(), float(fc[best_i])

    # 3. shrinking local search around the best few distinct candidates, all starts level by level
    report(0.5, "refining")
    sel = _distinct_best(Bc, fc, max(1, int(starts)), 2.0 * spacing)
    cur = [(Bc[i].copy(), float(fc[i])) for i in sel]
    radius, level, tol = cap_radius * spacing, 0, np.radians(tol_deg)
    while cur and radius >= tol:
        nxt = []
        for b, fb in cur:
            T = _cap_points(b, radius, cap_points if level == 0 else max(16, cap_points // 3), level * _GOLDEN_ANGLE)
            ok_t = allowed(T)
            ft = np.full(len(T), np.inf)
            if ok_t.any():
                WQ, WU, _ = exact.evaluate_near(b, T[ok_t], radius, h, cos_c, support=False)
                ft[ok_t] = WQ + WU
                evaluations += int(ok_t.sum())
            j = int(np.argmin(ft))
            if ft[j] < fb:
                b, fb = T[j], float(ft[j])
            if fb < best_f:
                best_f, best_b = fb, b.copy()
            nxt.append((b, fb))
        cur = [(b, fb) for b, fb in nxt if fb <= best_f * (1.0 + drop_above) + 1e-12]
        radius /= 4.0
        level += 1

    report(0.95, "figures")
    if not np.isfinite(best_f):
        raise BolusError("no allowed build direction: the favoured side cannot be kept off the plate")
    # ties: among the directions evaluated exactly whose objective is within TIE_REL of
    # the best (a symmetric part has whole families of them, e.g. every direction in the
    # no-overhang cone of a hemisphere), take the one that makes the lowest print
    # (special directions are few and may have been screened out as equals: those whose
    # screened value is near the best are evaluated exactly too)
    near_sp = special[f_coarse[len(Bfib):] <= best_f * (1.0 + 4.0 * TIE_REL) + 1e-12]
    pool_b = np.vstack([Bc, near_sp, best_b[None]] + [b[None] for b, _ in cur])
    pool_f = np.r_[fc, f_exact(near_sp), best_f, [fb for _, fb in cur]]
    tie = np.isfinite(pool_f) & (pool_f <= best_f * (1.0 + TIE_REL) + 1e-12)
    if tie.sum() > 1:
        proj = exact.H @ pool_b[tie].T  # hull vertices: the height is translation invariant
        height = proj.max(axis=0) - proj.min(axis=0)
        best_b = pool_b[tie][int(np.argmin(height))].copy()
    WQ, WU, SV = exact.evaluate(best_b[None], h, cos_c)
    evaluations += 1
    report(1.0, "done")
    return Orientation(best_b, float(WQ[0]), float(WU[0]), float(SV[0]), float(WQ[0] + WU[0]), evaluations,
                       int(ok.sum()), Bc[sel])


def _cap_points(b: np.ndarray, radius: float, n: int, turn: float = 0.0) -> np.ndarray:
    """n directions (n,3) evenly spread over the spherical cap of angular ``radius`` around b
    (a Fibonacci disc on the exponential map), turned by ``turn`` radians about b."""
    e1, e2 = _tangent_basis(b)
    i = np.arange(n) + 0.5
    rho = radius * np.sqrt(i / n)
    phi = _GOLDEN_ANGLE * i + turn
    T = np.cos(rho)[:, None] * b + np.sin(rho)[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    return T / np.linalg.norm(T, axis=1, keepdims=True)


def orient_parts(V, F, labels, progress=None, **kwargs) -> list[Orientation]:
    """`orient` each part of ``labels`` (m,) int 0..p-1 on its own; kwargs go to `orient`."""
    V, F = as_mesh_arrays(V, F)
    labels = np.asarray(labels)
    if labels.shape != (len(F),) or not np.issubdtype(labels.dtype, np.integer) or (labels.size and labels.min() < 0):
        raise BolusError("part labels must be one non-negative integer per triangle")
    report = progress or (lambda f, t: None)
    p = int(labels.max()) + 1 if labels.size else 0
    out = []
    for i in range(p):
        report(i / max(p, 1), f"part {i + 1} of {p}")
        if not np.any(labels == i):
            raise BolusError(f"part {i} has no faces; number the parts 0..{p - 1} without gaps")
        Fl, ids = submesh(F, labels == i)
        out.append(orient(V[ids], Fl, **kwargs))
    report(1.0, "done")
    return out
