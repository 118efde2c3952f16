"""Flattenability and segmentation saliency (seed 4.1.1, eqs. 4-1..4-4).

  theta(v)   sum of the inner angles at v                         (eq. 4-1)
  varpi(v) = |theta(v) - 2 pi| on interior vertices, 0 elsewhere   (eq. 4-1)
  sum varpi  over the vertices of a region                        (eq. 4-2)
  FLV      = 10 * 0.5 ** sum varpi                                 (eq. 4-3)
  s(v)     = theta(v) - 2 pi where positive, else 0                (eq. 4-4)

Per vertex (n,), in rad, for V (n,3) mm, F (m,3); boundary and non-manifold vertices get
varpi = s = 0.  `analyse` takes the angle sums on an analysis copy smoothed at a scale sigma
(mm, `smooth_for_analysis`; 0 = the raw mesh) and maps them back one-to-one to the original
vertices, which never move.  The smoothing is one implicit heat-diffusion step of the positions,

    (M + t K) V' = M V,   t = sigma^2 / 2,

K the cotangent stiffness (`cotangent_stiffness`), M the lumped mass (`lumped_mass`), boundary
and non-manifold vertices held fixed.

Design notes: docs/design/analysis.md.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import cg, splu

from ..errors import BolusError
from ..mesh.topology import MeshTopology, as_mesh_arrays, corner_angles, face_areas, refuse_zero_area, zero_area_mask

__all__ = [
    "DEFAULT_SMOOTHING_MM",
    "SMOOTHING_RTOL",
    "SaliencyResult",
    "flattenability",
    "segmentation_saliency",
    "flattenability_value",
    "cotangent_stiffness",
    "lumped_mass",
    "smooth_for_analysis",
    "analyse",
    "analysis_key",
]

#: Default analysis smoothing scale (mm).  Chosen on scanned faces: at 3 mm the
#: scanner noise (sub-mm bumps) is gone while a nose (radius of curvature 5-15 mm)
#: keeps its shape; see README "Flattenability preview".
DEFAULT_SMOOTHING_MM = 3.0

#: relative residual of the conjugate gradients of the analysis smoothing (`smooth_for_analysis`)
SMOOTHING_RTOL = 1e-9

TWO_PI = 2.0 * np.pi


def flattenability(topo: MeshTopology, theta: np.ndarray | None = None) -> np.ndarray:
    """varpi(v) = |theta(v) - 2pi| (eq. 4-1), 0 on non-interior vertices. Shape (n,)."""
    theta = topo.angle_sums if theta is None else theta
    varpi = np.abs(theta - TWO_PI)
    varpi[~topo.interior_vertices] = 0.0
    return varpi


def segmentation_saliency(topo: MeshTopology, theta: np.ndarray | None = None) -> np.ndarray:
    """s(v) = theta(v) - 2pi where that is positive, else 0 (eq. 4-4). Shape (n,)."""
    theta = topo.angle_sums if theta is None else theta
    s = np.maximum(theta - TWO_PI, 0.0)
    s[~topo.interior_vertices] = 0.0
    return s


def flattenability_value(sum_varpi: float) -> float:
    """FLV = 10 * 0.5 ** sum varpi (eq. 4-3)."""
    return float(10.0 * 0.5 ** float(sum_varpi))


def cotangent_stiffness(V: np.ndarray, F: np.ndarray, topo: MeshTopology | None = None) -> sp.csr_matrix:
    """Cotangent stiffness matrix K (n,n), positive semi-definite, rows summing to 0.

    K_ij = -(cot a_ij + cot b_ij) / 2 for an edge ij with opposite angles a, b.
    V (n,3), F (m,3); topo: the `MeshTopology` of (V, F) if the caller has it (its edge
    list is reused).  A zero-area triangle has no cotangents: `BolusError` names it.
    """
    topo = MeshTopology(V, F) if topo is None else topo
    V, F = topo.V, topo.F
    n = len(V)
    cr = 2.0 * topo.areas
    refuse_zero_area(F, topo.degenerate_faces())
    # One weight per edge (bincount over the half-edges), then one CSR build of the
    # 2e off-diagonal + n diagonal entries: at 1.12M triangles 1.8 s CPU instead of
    # 4.3 s for the former 6m-entry COO -> CSR build followed by K - diag(K 1).
    fe = topo.face_edges
    w = np.zeros(len(topo.edges))
    for k in range(3):
        o, i, j = F[:, k], F[:, (k + 1) % 3], F[:, (k + 2) % 3]
        cot = np.einsum("ij,ij->i", V[i] - V[o], V[j] - V[o]) / cr
        w += np.bincount(fe[:, (k + 1) % 3], weights=cot, minlength=len(w))
    w *= -0.5
    E = topo.edges
    diag = -(np.bincount(E[:, 0], weights=w, minlength=n) + np.bincount(E[:, 1], weights=w, minlength=n))
    idx = np.arange(n)
    K = sp.csr_matrix((np.r_[w, w, diag], (np.r_[E[:, 0], E[:, 1], idx], np.r_[E[:, 1], E[:, 0], idx])), shape=(n, n))
    return K


def lumped_mass(V: np.ndarray, F: np.ndarray, topo: MeshTopology | None = None) -> np.ndarray:
    """Barycentric lumped mass (n,): a third of the one-ring triangle areas (cf. eq. 3-24).

    V (n,3), F (m,3); the one implementation of the lumped mass in the core.  Zero-area
    triangles add nothing (sound: a vertex only on them gets mass 0).  topo: the
    `MeshTopology` of (V, F) if the caller has it (its checked arrays and cached areas
    are used: 0.8 s CPU less at 1.12M triangles)."""
    if topo is not None:
        V, F, A = topo.V, topo.F, topo.areas
        return np.bincount(F.ravel(), weights=np.repeat(A / 3.0, 3), minlength=len(V))
    V, F = as_mesh_arrays(V, F)
    A = face_areas(V, F)
    return np.bincount(F.ravel(), weights=np.repeat(A / 3.0, 3), minlength=len(V))


def smooth_for_analysis(topo: MeshTopology, smoothing_mm: float) -> np.ndarray:
    """Smoothed copy of the vertices at scale ``smoothing_mm`` (see module doc).

    Parameters: topo the mesh's `MeshTopology` (V (n,3) mm, F (m,3)); smoothing_mm >= 0.
    Returns Vs (n,3): boundary and non-manifold vertices stay where they are.  The input
    arrays are not modified; ``smoothing_mm == 0`` returns a copy of V.
    """
    if not np.isfinite(smoothing_mm) or smoothing_mm < 0:
        raise BolusError(f"the smoothing scale must be 0 or a positive number of mm, got {smoothing_mm}")
    V, F = topo.V, topo.F
    if smoothing_mm == 0 or topo.m == 0:
        return V.copy()
    t = 0.5 * float(smoothing_mm) ** 2
    K = cotangent_stiffness(V, F, topo)
    M = lumped_mass(V, F, topo)
    fixed = ~topo.interior_vertices
    free = np.nonzero(~fixed)[0]
    out = V.copy()
    if len(free) == 0:
        return out
    A = (sp.diags(M) + t * K).tocsr()
    if len(free) == topo.n:  # a closed surface: nothing held (no slicing copies)
        A_ff, rhs = A, M[:, None] * V
    else:
        A_ff = A[free][:, free]
        rhs = M[free, None] * V[free] - A[free][:, np.nonzero(fixed)[0]] @ V[fixed]
    # A_ff is symmetric positive definite: conjugate gradients with a Jacobi
    # preconditioner, started from the input positions, one coordinate at a time (at
    # 1.12M triangles ~180 iterations each; iterating the three as one (n,3) block was
    # tried and measured slower: 21 s CPU against 11 s, the sparse product does not get
    # cheaper per column and the column-wise norms cost more); a direct factorisation
    # is the fallback.  Residual SMOOTHING_RTOL: at 1.12M triangles 1e-12 took 178-186
    # iterations per coordinate and 1e-9 121-133, the angle deficits of the two differing
    # by at most 2.5e-7 rad (their sum by 1e-6 of 215 rad).
    Pinv = sp.diags(1.0 / A_ff.diagonal())
    for c in range(3):
        x, info = cg(A_ff, rhs[:, c], x0=V[free, c], rtol=SMOOTHING_RTOL, atol=0.0, maxiter=2000, M=Pinv)
        if info != 0:
            out[free] = splu(A_ff.tocsc()).solve(rhs)
            break
        out[free, c] = x
    return out


@dataclass
class SaliencyResult:
    """Per-vertex analysis of a region (all arrays (n,) over the region's vertices)."""

    theta: np.ndarray | None  #: angle sums (eq. 4-1), on the analysis copy (None: not kept)
    varpi: np.ndarray  #: flattenability |theta - 2pi| (eq. 4-1), 0 off the interior
    saliency: np.ndarray  #: segmentation saliency (eq. 4-4)
    sum_varpi: float  #: eq. 4-2
    flv: float  #: eq. 4-3
    smoothing_mm: float
    V_analysis: np.ndarray | None  #: (n,3) the vertices the angles were measured on (None: not kept)

    @property
    def interior_count(self) -> int:
        return int(np.count_nonzero(self.varpi > 0))


def analyse(V, F, smoothing_mm: float = 0.0, topo: MeshTopology | None = None) -> SaliencyResult:
    """Flattenability and saliency of a triangle mesh (eqs. 4-1..4-4).

    Parameters
    ----------
    V : (n,3) float, millimetres; F : (m,3) int
    smoothing_mm : scale of `smooth_for_analysis` (0 = the raw angle sums)
    topo : the `MeshTopology` of (V, F) if the caller has it

    Returns
    -------
    SaliencyResult: theta, varpi, saliency (n,) indexing V's vertices (0 off the
    interior), sum_varpi (eq. 4-2), flv (eq. 4-3), V_analysis (n,3).

    Raises `BolusError` for an empty mesh, zero-area triangles (named) and the array
    errors of `topology.as_mesh_arrays`; non-manifold vertices count as boundary.
    """
    topo = MeshTopology(V, F) if topo is None else topo
    if topo.m == 0:
        raise BolusError("the region has no faces")
    topo.require_nondegenerate("the region")
    Vs = smooth_for_analysis(topo, smoothing_mm)
    theta = corner_angle_sums(Vs, topo)
    varpi = flattenability(topo, theta)
    sal = segmentation_saliency(topo, theta)
    total = float(varpi.sum())
    return SaliencyResult(theta, varpi, sal, total, flattenability_value(total), float(smoothing_mm), Vs)


def analysis_key(V, F, smoothing_mm: float) -> str:
    """A fingerprint of what `analyse` depends on: the vertices (n,3) and triangles (m,3)
    (exact bytes, as float64 / int64) and the smoothing scale.  Equal keys: equal analyses
    (`analyse` is deterministic), so a caller may reuse one (`spectral.segment(analysis=)`)."""
    h = hashlib.blake2b(digest_size=20)
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    for part in (repr(V.shape).encode(), V.tobytes(), repr(F.shape).encode(), F.tobytes(),
                 repr(float(smoothing_mm)).encode()):
        h.update(part)
    return h.hexdigest()


def corner_angle_sums(Vs: np.ndarray, topo: MeshTopology) -> np.ndarray:
    """theta (n,) measured on positions Vs with the connectivity of ``topo``."""
    if Vs is topo.V:
        return topo.angle_sums
    ang = corner_angles(Vs, topo.F)
    return np.bincount(topo.F.ravel(), weights=ang.ravel(), minlength=topo.n)
