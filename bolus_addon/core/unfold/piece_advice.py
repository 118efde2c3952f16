"""Which remedy a badly flattened piece needs: angle deficit or angle excess (seed ch. 4.1.1).

With the angle sum theta(v) of eq. 4-1 and the angle defect K(v) = 2 pi - theta(v) (rad) of the
interior vertices, a piece's sum varpi (eqs. 4-1, 4-2; FLV of eq. 4-3) splits by sign into

  deficit  D = sum over interior v of max(K(v), 0)    (nose tip, chin, a cap)
  excess   X = sum over interior v of max(-K(v), 0)   (eq. 4-4: pocket rims, grooves, folds)

with K first diffused over the surface at the analysis scale sigma (mm), `diffused_defect`:

    (M + t L) rho = K,   K' = M rho,   t = sigma^2 / 2,

L the cotangent stiffness, M the lumped mass, rho the defect per unit area (sum K' = sum K).
`piece_advice` (V (n,3) mm, F (m,3), the piece's EL / EA) turns the sign into the remedy: a
deficit wants a dart or smaller pieces; an excess (more material than a flat sheet has room for)
wants the cavity out of the treatment area, a split along the groove, or the printed bolus.

Design notes: docs/design/unfold.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..errors import BolusError
from ..analysis.saliency import DEFAULT_SMOOTHING_MM, analyse, cotangent_stiffness, lumped_mass
from ..mesh.topology import MeshTopology, as_mesh_arrays

__all__ = ["DEFAULT_WARN_FRACTION", "EXCESS_SHARE", "PieceAdvice", "diffused_defect", "piece_advice"]

#: EL or EA above this fraction (3 %) makes a piece one a clinic should not cut as it is.
DEFAULT_WARN_FRACTION = 0.03
#: share X / (X + D) of the diffused angle defect from which the excess decides the remedy
#: (between the nose tips' 0.14 and the nostril pockets' 0.37: docs/design/unfold.md).
EXCESS_SHARE = 0.3


@dataclass
class PieceAdvice:
    """Figures of one piece and what to do about it.

    excess_rad, deficit_rad: X and D above (rad, of the diffused defect); sum_varpi (eq. 4-2)
    and flv (eq. 4-3) of the raw angle sums;
    worst_excess_vertex / worst_deficit_vertex: index into V of the largest theta - 2 pi /
    2 pi - theta (-1 when there is none); kind: "flat" (nothing worth naming), "deficit" or
    "excess"; distorted: EL or EA (or flips / overlaps) above the threshold; advice: one
    sentence ("" when the piece is fine).
    """

    excess_rad: float
    deficit_rad: float
    sum_varpi: float
    flv: float
    worst_excess_vertex: int
    worst_deficit_vertex: int
    kind: str
    distorted: bool
    advice: str

    @property
    def short_advice(self) -> str:
        """A few words for a panel row ("" when the piece is fine)."""
        if not self.distorted:
            return ""
        return SHORT_ADVICE[self.kind]

    @property
    def excess_share(self) -> float:
        total = self.excess_rad + self.deficit_rad
        return self.excess_rad / total if total > 0 else 0.0

    def as_dict(self) -> dict:
        return {"excess_rad": self.excess_rad, "deficit_rad": self.deficit_rad, "sum_varpi": self.sum_varpi,
                "flv": self.flv, "kind": self.kind, "distorted": self.distorted, "advice": self.advice,
                "short_advice": self.short_advice}


DEFICIT_ADVICE = (
    "the skin here has less angle than a flat sheet (angle deficit {D:.2f} rad, excess {X:.2f} rad: "
    "a dome such as a nose tip, chin or cap), so the sheet is stretched: segment it into more, "
    "smaller patches, or cut a dart from the edge towards its most curved point"
)
EXCESS_ADVICE = (
    "parts of the skin here have more angle than a flat sheet (angle excess {X:.2f} rad beside a "
    "deficit of {D:.2f} rad: a pocket rim, groove or fold, where the sheet would overlap), so a dart "
    "would overlap and more "
    "patches around a pocket make it worse: leave the cavity out of the treatment area (deselect it "
    "in Edit Mode and segment again), split it into separate pieces along the groove, or use the "
    "printed bolus"
)
SHORT_ADVICE = {
    "deficit": "dome: more patches or a dart",
    "excess": "pocket/fold: leave out, split or print",
    "flat": "unfold again, refine on",
}
FLAT_ADVICE = (
    "its angle sums are those of a flat sheet (sum varpi {S:.3f} rad), so the distortion comes from "
    "the unfolding itself: unfold again with 'Refine lengths' on, or segment into more patches"
)


def diffused_defect(topo: MeshTopology, K: np.ndarray, sigma_mm: float) -> np.ndarray:
    """K (n,) angle defect per vertex diffused at scale sigma (module doc); sum kept."""
    if sigma_mm <= 0:
        return K.copy()
    V, F = topo.V, topo.F
    L = cotangent_stiffness(V, F)
    M = lumped_mass(V, F)
    A = (sp.diags(M) + 0.5 * float(sigma_mm) ** 2 * L).tocsc()
    used = M > 0  # isolated vertices carry no defect
    if not used.all():
        idx = np.nonzero(used)[0]
        out = np.zeros_like(K)
        out[idx] = M[idx] * splu(A[idx][:, idx].tocsc()).solve(K[idx])
        return out
    return M * splu(A).solve(K)


def piece_advice(V, F, EL: float = 0.0, EA: float = 0.0, flipped: int = 0, overlaps: int = 0,
                 threshold: float = DEFAULT_WARN_FRACTION, sigma_mm: float = DEFAULT_SMOOTHING_MM,
                 topo: MeshTopology | None = None) -> PieceAdvice:
    """Diagnose one piece: V (n,3) mm, F (m,3) its triangles (before any cut to a disk).

    EL, EA: its length and area errors as fractions (eqs. 3-30, 3-31); flipped /
    overlaps: triangle counts of its pattern.  The piece is `distorted` when EL or EA
    exceeds ``threshold`` (a fraction, 0.03 = 3 %) or any triangle is flipped or
    overlapping; the advice then says which remedy its curvature calls for (module
    doc).  theta, varpi, s of eqs. 4-1..4-4 come from `saliency.analyse` (boundary
    vertices count 0); the excess / deficit split is of the defect diffused at
    ``sigma_mm`` (0 = raw angle sums).
    """
    V, F = as_mesh_arrays(V, F)
    if len(F) == 0:
        raise BolusError("the piece has no faces")
    for name, x in (("EL", EL), ("EA", EA), ("threshold", threshold), ("sigma_mm", sigma_mm)):
        if not np.isfinite(x) or x < 0:
            raise BolusError(f"{name} must be a number >= 0, got {x}")
    topo = MeshTopology(V, F) if topo is None else topo
    res = analyse(V, F, 0.0, topo=topo)
    # signed defect 2pi - theta on interior vertices: deficit part varpi - s, excess part s (eqs. 4-1, 4-4)
    K = (res.varpi - res.saliency) - res.saliency
    Kd = diffused_defect(topo, K, sigma_mm)
    X, D = float(np.maximum(-Kd, 0.0).sum()), float(np.maximum(Kd, 0.0).sum())
    worst_x = int(np.argmin(Kd)) if X > 0 else -1
    worst_d = int(np.argmax(Kd)) if D > 0 else -1
    distorted = bool(EL > threshold or EA > threshold or flipped > 0 or overlaps > 0)
    total = X + D
    if total < 1e-3:  # under 0.06 degrees all together: developable for any practical purpose
        kind = "flat"
    elif X >= EXCESS_SHARE * total:
        kind = "excess"
    else:
        kind = "deficit"
    advice = ""
    if distorted:
        template = {"flat": FLAT_ADVICE, "excess": EXCESS_ADVICE, "deficit": DEFICIT_ADVICE}[kind]
        advice = template.format(X=X, D=D, S=res.sum_varpi)
    return PieceAdvice(X, D, res.sum_varpi, res.flv, worst_x, worst_d, kind, distorted, advice)
