"""The skin from a CT volume: the outer iso-surface of the largest body at a HU threshold.

1. mask = HU > threshold; eroded in-plane by `OPEN_MM`, which breaks thin contacts (a couch or
   mask touching the body); its largest 6-connected component is grown back by as much inside
   the mask, and the pieces this cut off that touch it and are small against it (an ear's rim)
   are given back: the couch and immobilisation are left out;
2. holes are filled slice by slice (lungs, airways, also where they open to the nose above);
3. marching cubes (libigl, `core.solid.marching`) on HU - threshold cropped to the body's box
   and masked to the body (elsewhere negative, cavities positive), so the surface has the
   sub-voxel interpolation of the HU values; vertices mapped through the volume's affine to LPS mm;
4. smoothing only as much as the voxel steps need: `TAUBIN_STEPS` of Taubin's lambda/mu pairs
   (no shrinkage) take out the marching's staircase, whose step is below one voxel;
5. outward winding (signed volume > 0).
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage, sparse

from ..errors import BolusError
from ..solid.marching import marching_cubes
from .series import CTVolume

__all__ = ["OPEN_MM", "KEEP_FRACTION", "TAUBIN_STEPS", "body_mask", "skin_from_ct", "mesh_field", "taubin", "signed_volume"]

#: radius (mm) of the in-plane opening that breaks a couch's thin contact with the body
OPEN_MM = 3.0
#: a piece cut off by the opening is given back when smaller than this fraction of the body
KEEP_FRACTION = 0.02
#: Taubin lambda/mu pairs: enough to take out a voxel's staircase, too few to move the skin
TAUBIN_STEPS = 3


def _box(mask: np.ndarray, radius_px, grow: bool) -> np.ndarray:
    """In-plane erosion (grow=False) or dilation of a (k, rows, cols) bool array by a box of
    half-widths ``radius_px`` (rows, cols): two 1D min / max filters, linear in the box size."""
    out = mask.view(np.uint8)
    f = ndimage.maximum_filter1d if grow else ndimage.minimum_filter1d
    for axis, r in ((1, radius_px[0]), (2, radius_px[1])):
        if r > 0:
            out = f(out, 2 * r + 1, axis=axis, mode="constant", cval=0)
    return out.view(bool)


def _sizes(lab: np.ndarray, n: int) -> np.ndarray:
    """(n+1,) approximate voxel counts of the labels (every other voxel along each axis, x 8):
    enough to tell a body from a couch, without an int64 copy of the whole label array."""
    sizes = np.bincount(lab[::2, ::2, ::2].ravel(), minlength=n + 1) * 8
    sizes[0] = 0
    return sizes


def _largest(mask: np.ndarray) -> np.ndarray:
    lab, n = ndimage.label(mask)
    if n == 0:
        return np.zeros_like(mask)
    if n == 1:
        return lab.astype(bool)
    sizes = _sizes(lab, n)
    if not sizes.any():  # every piece missed by the sampling: count them all
        sizes = np.bincount(lab.ravel(), minlength=n + 1)
        sizes[0] = 0
    return lab == int(np.argmax(sizes))


def body_mask(hu: np.ndarray, threshold: float, spacing, progress=None):
    """The largest body above ``threshold`` HU, its cavities filled: (bool (k', r', c') cropped
    to its bounding box, lower corner (3,) of the box in voxels)."""
    mask = hu > threshold
    if not mask.any():
        raise BolusError(f"no voxel of the CT is above {threshold:g} HU: lower the threshold")
    r = (max(int(OPEN_MM / spacing[0]), 1), max(int(OPEN_MM / spacing[1]), 1))
    core = _largest(_box(mask, r, False))  # eroded: thin contacts with a couch are broken
    if progress is not None:
        progress(0.3, "separating the body from the couch")
    if not core.any():  # the body is thinner than the opening: no couch step
        body = _largest(mask)
    else:
        body = _box(core, r, True) & mask  # the opening of the body alone
        del core
        body = _regrow_small(mask, body)
    del mask
    idx = [np.flatnonzero(body.any(axis=tuple(a for a in range(3) if a != ax))) for ax in range(3)]
    lo = np.array([i[0] for i in idx])
    box = tuple(slice(i[0], i[-1] + 1) for i in idx)
    if progress is not None:
        progress(0.5, "filling the cavities")
    return _fill_slices(np.ascontiguousarray(body[box])), lo


def _fill_slices(body: np.ndarray) -> np.ndarray:
    """Holes filled slice by slice: the background pieces (in-plane connectivity) that do not
    reach a slice's border are cavities (lungs, airways, also where they open to the nose above)."""
    plane = np.zeros((3, 3, 3), dtype=bool)
    plane[1] = ndimage.generate_binary_structure(2, 1)
    lab, n = ndimage.label(~body, structure=plane)
    outside = np.zeros(n + 1, dtype=bool)
    for edge in (lab[:, 0, :], lab[:, -1, :], lab[:, :, 0], lab[:, :, -1]):
        outside[np.unique(edge)] = True
    outside[0] = True  # label 0: the body itself
    keep = ~outside
    keep[0] = True
    return keep[lab]


def _regrow_small(mask: np.ndarray, body: np.ndarray) -> np.ndarray:
    """``body`` plus the pieces of ``mask`` the opening cut off that touch it and are smaller than
    `KEEP_FRACTION` of it (an ear's rim, a finger): a couch or a mask plate is far larger."""
    rest = mask & ~body
    lab, n = ndimage.label(rest)
    if n:
        sizes = _sizes(lab, n)
        touching = np.unique(lab[_box(body, (1, 1), True) & rest])
        keep = touching[(touching > 0) & (sizes[touching] < KEEP_FRACTION * 8 * body[::2, ::2, ::2].sum())]
        if len(keep):
            table = np.zeros(n + 1, dtype=bool)
            table[keep] = True
            body |= table[lab]
    return body


def mesh_field(field: np.ndarray, vol: CTVolume, offset) -> tuple[np.ndarray, np.ndarray]:
    """Marching cubes of ``field`` (positive inside) whose index (0,0,0) is voxel ``offset``
    (k, r, c) of ``vol``: (V (n,3) LPS mm, F (m,3)) wound outward."""
    V, F = marching_cubes(field, np.asarray(offset, dtype=np.float64), np.ones(3), pad=True)
    if len(F) == 0:
        raise BolusError("the surface is empty")
    V = vol.to_patient(V)
    if signed_volume(V, F) < 0:
        F = F[:, ::-1]
    return V, np.ascontiguousarray(F)


def skin_from_ct(vol: CTVolume, threshold: float = -350.0, progress=None,
                 smooth_steps: int = TAUBIN_STEPS) -> tuple[np.ndarray, np.ndarray]:
    """The skin of ``vol`` at ``threshold`` HU: (V (n,3) LPS mm, F (m,3) int64), closed, outward."""
    sub, lo = body_mask(vol.hu, threshold, vol.spacing, progress)
    box = tuple(slice(a, a + n) for a, n in zip(lo, sub.shape))
    field = vol.hu[box] - np.float32(threshold)
    # outside the body (couch, other parts): at most just below the threshold; inside: at least above
    np.minimum(field, -1.0, out=field, where=~sub)
    np.maximum(field, 1.0, out=field, where=sub & (field <= 0))
    del sub
    if progress is not None:
        progress(0.7, "marching cubes")
    V, F = mesh_field(field, vol, lo)
    del field
    if smooth_steps:
        V = taubin(V, F, smooth_steps)
    if progress is not None:
        progress(1.0, "skin done")
    return V, F


def taubin(V: np.ndarray, F: np.ndarray, steps: int, lam: float = 0.5, mu: float = -0.53) -> np.ndarray:
    """``steps`` pairs of Taubin smoothing (uniform umbrella weights): V (n,3) -> (n,3)."""
    n = len(V)
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    A = sparse.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n)).tocsr()
    A = ((A + A.T) > 0).astype(np.float64)
    deg = np.asarray(A.sum(axis=1)).ravel()
    deg[deg == 0] = 1.0
    W = sparse.diags(1.0 / deg) @ A
    V = V.copy()
    for _ in range(steps):
        for f in (lam, mu):
            V += f * (W @ V - V)
    return V


def signed_volume(V: np.ndarray, F: np.ndarray) -> float:
    """Signed volume (mm^3) of a closed mesh, positive when wound outward."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
