"""A smoothed path along the surface: the patch indicator diffused by MBO steps (seed 4.1.2 fallback).

Where no plane curve fits a border (the surface folds, the border winds), the cut is
the zero set of the indicator of the two patches (+1 on patch a, -1 on patch b)
diffused on the surface: an implicit heat step (M + sigma^2/2 K) u = M u0 with the
lumped mass M and the cotangent stiffness K (the seed's Laplacian, `saliency`),
a threshold, and a heat step again (Merriman-Bence-Osher: a short curve-shortening
flow of the border).  `levelset_cut.cut_band` cuts the triangles along its zero set.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import factorized
from scipy.spatial import cKDTree

from .borders import edge_samples
from ..errors import BolusError
from ..analysis.saliency import cotangent_stiffness, lumped_mass

__all__ = ["diffused_indicator"]

MBO_ITERATIONS = 2  #: heat step, threshold, heat step: the threshold removes the zig-zag, the last step smooths
REACH_SAMPLES = 3  #: points per border edge when measuring which faces are within reach


def diffused_indicator(V: np.ndarray, F: np.ndarray, labels: np.ndarray, a: int, b: int, sigma: float,
                       border_edges: np.ndarray | None = None, reach: float = np.inf) -> np.ndarray:
    """MBO field on the vertices of patches a and b: > 0 on the a side.

    Parameters
    ----------
    V : (n,3) mm; F : (m,3); labels : (m,) patch of each face; a, b : the two patches.
    sigma : diffusion length, mm (> 0).
    border_edges : optional (k,2) edges of the border; with a finite ``reach`` (mm)
        only the faces of a and b whose centroid is within reach of it take part: the
        field near the border, where the cut is looked for, depends on the patches
        within a few sigma of it only (the implicit step's kernel decays like
        exp(-sqrt(2) d / sigma)).

    Returns
    -------
    (n,) the field at the vertices of the faces taking part, NaN elsewhere.
    Raises `BolusError` for sigma <= 0 or a zero-area triangle among those faces
    (the heat step would be singular there).
    """
    if not sigma > 0:
        raise BolusError(f"the diffusion length must be positive, got {sigma}")
    in_u = (labels == a) | (labels == b)
    if border_edges is not None and np.isfinite(reach):
        in_u = _faces_within(V, F, in_u, edge_samples(border_edges, V, REACH_SAMPLES), reach)
    Fu = F[in_u]
    ids, inv = np.unique(Fu.ravel(), return_inverse=True)
    Fl = inv.reshape(-1, 3)
    Vl = V[ids]
    area = 0.5 * np.linalg.norm(np.cross(Vl[Fl[:, 1]] - Vl[Fl[:, 0]], Vl[Fl[:, 2]] - Vl[Fl[:, 0]]), axis=1)
    if (area <= 0).any():
        f = int(np.nonzero(in_u)[0][np.argmax(area <= 0)])
        raise BolusError(f"triangle {f} (vertices {', '.join(map(str, F[f].tolist()))}) has zero area: "
                         "no diffusion across it")
    sgn = np.where(labels[in_u] == a, 1.0, -1.0)
    num = np.bincount(Fl.ravel(), weights=np.repeat(area * sgn, 3), minlength=len(ids))
    den = np.bincount(Fl.ravel(), weights=np.repeat(area, 3), minlength=len(ids))
    u = _mbo_steps(Vl, Fl, num / np.maximum(den, 1e-300), sigma)
    out = np.full(len(V), np.nan)
    out[ids] = u
    return out


def _faces_within(V: np.ndarray, F: np.ndarray, mask: np.ndarray, pts: np.ndarray, reach: float) -> np.ndarray:
    """(m,) bool: the faces of ``mask`` whose centroid is within ``reach`` of a point of pts (k,3)."""
    faces = np.nonzero(mask)[0]
    C = V[F[faces]].mean(axis=1)
    box = np.all((C >= pts.min(axis=0) - reach) & (C <= pts.max(axis=0) + reach), axis=1)
    near = np.zeros(len(faces), dtype=bool)
    d, _ = cKDTree(pts).query(C[box], distance_upper_bound=reach)
    near[np.nonzero(box)[0]] = np.isfinite(d)
    out = np.zeros(len(F), dtype=bool)
    out[faces[near]] = True
    return out


def _mbo_steps(V: np.ndarray, F: np.ndarray, u: np.ndarray, sigma: float) -> np.ndarray:
    """MBO_ITERATIONS implicit heat steps (M + sigma^2/2 K) u' = M u, thresholding to +-1 between them."""
    K = cotangent_stiffness(V, F)
    M = lumped_mass(V, F)
    solve = factorized((sp.diags(M) + 0.5 * sigma**2 * K).tocsc())
    for it in range(MBO_ITERATIONS):
        u = solve(M * u)
        if it < MBO_ITERATIONS - 1:
            u = np.where(u >= 0, 1.0, -1.0)
    return u
