"""Quality measures of a flat pattern against its skin (seed eqs. 3-30, 3-31, 4-1; SPEC).

- EL = sum |L - L0| / sum L0 over the three edges of every triangle (eq. 3-30);
- EA = sum |A - A0| / sum A0 with A the *signed* 2D area, so a flipped triangle counts
  fully (eq. 3-31);
- the angle deficit / excess of a patch (eq. 4-1).

One implementation (`_triangle_errors` + `_ratios`) serves triangles
(`length_area_errors`) and polygons fanned from their first corner (`polygon_errors`,
`polygon_area_error`).  No scale is fitted: the pattern is measured as it is.
"""
from __future__ import annotations

import numpy as np

from ..errors import BolusError
from .overlap import signed_areas
from ..mesh.topology import MeshTopology, check_mesh, face_areas, triangulate_polygons, zero_area_mask

__all__ = ["length_area_errors", "check_positions", "polygon_errors", "polygon_area_error", "curvature_sums"]


def _edge_lengths3(P: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Lengths (m,3) of the edges F[:, k] -> F[:, k+1] of every triangle."""
    return np.stack([np.linalg.norm(P[F[:, k]] - P[F[:, (k + 1) % 3]], axis=1) for k in range(3)], 1)


def _triangle_errors(V: np.ndarray, F: np.ndarray, P: np.ndarray, Fp: np.ndarray | None = None):
    """Per-triangle lengths and areas of a pattern and its source.

    Parameters: V (n,3) source vertices, F (m,3) source triangles, P (k,2 or more) pattern
    vertices (the first two columns are used), Fp (m,3) pattern triangles (default F).
    Returns (L0 (m,3), L (m,3), A0 (m,), A (m,)): 3D and 2D edge lengths, 3D area and
    signed 2D area.  No checks (internal; the public measures check their input).
    """
    P = np.asarray(P, dtype=np.float64)[:, :2]
    Fp = F if Fp is None else Fp
    return _edge_lengths3(V, F), _edge_lengths3(P, Fp), face_areas(V, F), signed_areas(P, Fp)


def _ratios(L0, L, A0, A) -> tuple[float, float]:
    """(EL, EA) of eqs. 3-30, 3-31 from the arrays of `_triangle_errors` (any selection)."""
    return float(np.abs(L - L0).sum() / L0.sum()), float(np.abs(A - A0).sum() / A0.sum())


def check_positions(P, n: int | None = None, what: str = "the pattern", n_min: int = 0) -> np.ndarray:
    """P (n, >=2) as float64 with finite first two columns, else `BolusError` naming the
    problem (shape, or the first NaN/inf vertex).  n: the exact row count, or None with
    at least ``n_min`` rows."""
    P = np.asarray(P, dtype=np.float64)
    rows_ok = P.ndim == 2 and (P.shape[0] == n if n is not None else P.shape[0] >= n_min)
    if not rows_ok or P.shape[1] < 2:
        want = f"({n}, 2)" if n is not None else f"(n, 2) with n >= {n_min}"
        raise BolusError(f"{what} must be an array of positions of shape {want}, got shape {P.shape}")
    bad = np.nonzero(~np.isfinite(P[:, :2]).all(axis=1))[0]
    if len(bad):
        raise BolusError(f"{what} has {len(bad)} non-finite (NaN or infinite) position(s), e.g. vertex {int(bad[0])}")
    return P


def length_area_errors(V, F, UV) -> tuple[float, float]:
    """EL and EA of eqs. 3-30, 3-31 as SPEC measures them (no scale fitted).

    Parameters: V (n,3) skin vertices, F (m,3) triangles, UV (n,2) pattern positions
    (same vertex numbering, same unit).
    Returns (EL, EA), fractions (0.01 = 1 %).
    Zero-area or needle source triangles and non-manifold edges are measured like any
    other (their |A - A0| counts, A0 = 0 adds nothing to the sum); a mesh with no area
    raises `BolusError`, as do NaN/inf positions and bad indices (naming the first).
    """
    V, F = check_mesh(V, F, "the mesh", nondegenerate=False, min_faces=0)
    UV = check_positions(UV, len(V), "the pattern")
    L0, L, A0, A = _triangle_errors(V, F, UV)
    if not L0.sum() > 0 or not A0.sum() > 0:
        raise BolusError(f"the mesh ({len(F)} triangles) has no area to measure the pattern against")
    return _ratios(L0, L, A0, A)


def _fanned(V_src, corners_src, V_pat, corners_pat, sizes):
    """Matching polygons fanned from their first corner: (tri_poly (t,), L0, L (t,3), A0, A (t,))."""
    Fs, tri_poly = triangulate_polygons(corners_src, sizes)
    Fp, _ = triangulate_polygons(corners_pat, sizes)
    V_src, Fs = check_mesh(V_src, Fs, "the source mesh", nondegenerate=False, min_faces=0)
    P = np.asarray(V_pat, dtype=np.float64)
    P = check_positions(P, len(P), "the pattern")
    if len(Fp) and (Fp.min() < 0 or Fp.max() >= len(P)):
        raise BolusError(f"a pattern polygon refers to a vertex outside the pattern ({len(P)} vertices)")
    return (tri_poly, *_triangle_errors(V_src, Fs, P, Fp))


def polygon_errors(V_src, corners_src, V_pat, corners_pat, sizes, groups=None) -> dict:
    """EL and EA exactly as SPEC measures a pattern against its source, per group.

    Parameters: V_src (n,3) and V_pat (k,2 or 3) in the same unit; corners_* (c,) the
    corner vertices of matching polygons (same order, same sizes (p,)); every polygon is
    fanned from its first corner; groups (p,) optional labels (e.g. patches).
    Returns {group: (EL, EA, flipped triangles)} and the key None for all polygons
    together.  Zero-area source polygons are measured like any other (as in
    `length_area_errors`); a group without any area, NaN/inf positions or corners out of
    range raise `BolusError`.
    """
    tri_poly, L0, L, A0, A = _fanned(V_src, corners_src, V_pat, corners_pat, sizes)
    out = {}
    g = np.zeros(len(sizes), dtype=np.int64) if groups is None else np.asarray(groups)
    tg = g[tri_poly]
    for key in [None, *np.unique(tg).tolist()]:
        sel = np.ones(len(tg), dtype=bool) if key is None else tg == key
        if not (L0[sel].sum() > 0 and A0[sel].sum() > 0):
            raise BolusError(f"the source polygons{'' if key is None else f' of group {key}'} have no area "
                             "to measure the pattern against")
        el, ea = _ratios(L0[sel], L[sel], A0[sel], A[sel])
        out[key] = (el, ea, int(np.count_nonzero(A[sel] <= 0)))
    return out


def polygon_area_error(V_src, corners_src, V_pat, corners_pat, sizes) -> np.ndarray:
    """A / A0 - 1 (p,) of every pattern polygon against its source polygon (signed area).

    Same parameters as `polygon_errors`.  A zero-area source polygon (`topology.zero_area_mask`:
    coincident or collinear corners) has no ratio and raises `BolusError` naming it.
    """
    tri_poly, L0, _, A0, A = _fanned(V_src, corners_src, V_pat, corners_pat, sizes)
    a0 = np.bincount(tri_poly, A0, minlength=len(sizes))
    bad = np.nonzero(zero_area_mask(a0, L0.ravel()))[0]
    if len(bad):
        raise BolusError(f"{len(bad)} source polygon(s) have no area (coincident or collinear corners), "
                         f"e.g. polygon {int(bad[0])}: its area ratio is undefined")
    return np.bincount(tri_poly, A, minlength=len(sizes)) / a0 - 1.0


def curvature_sums(topo: MeshTopology) -> tuple[float, float]:
    """(angle deficit, angle excess) of a patch in radians: sums over interior vertices of
    max(0, 2 pi - theta) and max(0, theta - 2 pi), theta the angle sum (eq. 4-1); their
    sum is sum varpi (eq. 4-2).  topo: the patch's `MeshTopology`; `BolusError`
    (`topology.check_mesh`) on zero-area triangles (no angles) and non-manifold edges."""
    topo.require_valid("the patch", manifold=True)
    return _curvature_sums(topo)


def _curvature_sums(topo: MeshTopology) -> tuple[float, float]:
    """`curvature_sums` without the input check."""
    d = 2.0 * np.pi - topo.angle_sums
    d = d[topo.interior_vertices]
    return float(np.maximum(d, 0.0).sum()), float(np.maximum(-d, 0.0).sum())
