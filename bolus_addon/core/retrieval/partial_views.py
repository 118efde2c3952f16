"""Partial silhouettes for the view matcher: library views cut as a frame cuts a photo, and a photo's
silhouette without a foreign-coloured part (an occluder).

* `cut_images(images)`: every canonical view image (k, g, g) cut by half-planes from CUT_DIRECTIONS
  directions (evenly over the full turn: the descriptors do not know where "up" is in the photo, so the
  cut must be tried from every side), each removing the share s of CUT_SHARES of the region's mass,
  and each cut re-made canonical (centroid in the middle, farthest pixel on the inscribed circle) by a
  separable bilinear resampling (two matrix products) -> (k * CUT_DIRECTIONS * len(CUT_SHARES), g, g);
* `cut_descriptors(images)`: their Zernike magnitudes (float16: the cache holds many of them);
* `occluder_variants(image, mask)`: the silhouette with each foreign-coloured part replaced by its
  best guess: the part's pixels inside the convex hull of the rest (the object it hides) are kept,
  those outside it (the occluder jutting out of the outline) dropped.  A part is foreign when its
  chromaticity (r, g) / (r + g + b) lies more than OCCLUDER_CHROMA from the silhouette's median:
  shading changes brightness, not chromaticity, so the lit and shaded sides of one material stay one
  part.  Parts thinner than an opening of OCCLUDER_OPEN of the diagonal (the colour-mixed rim of a
  blurred outline) or under OCCLUDER_MIN of the silhouette are not taken.

Design notes: docs/design/retrieval.md.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError

from ..errors import BolusError
from . import shape_descriptors as sd

__all__ = ["CUT_DIRECTIONS", "CUT_SHARES", "OCCLUDER_CHROMA", "cut_images", "cut_descriptors",
           "occluder_variants", "convex_hull_mask"]

CUT_DIRECTIONS = 16  #: half-plane directions over the full turn (22.5 degrees apart)
CUT_SHARES = (0.1, 0.2, 0.3, 0.4)  #: shares of the region a cut removes
OCCLUDER_CHROMA = 0.04  #: chromaticity distance from the silhouette's median that makes a pixel foreign
OCCLUDER_OPEN = 0.01  #: opening radius of the foreign pixels, share of the diagonal (>= 2 px)
OCCLUDER_MIN = 0.03  #: a foreign part's smallest share of the silhouette
CHUNK = 8  #: views cut at once (bounds the memory: CHUNK x cuts x g x g floats)


def _interp_matrices(pos: np.ndarray, g: int) -> np.ndarray:
    """(n, g, g): row i of matrix k interpolates (linearly, zero outside) a line of g samples at the source
    position pos[k, i] (pixel index units)."""
    n = len(pos)
    f0 = np.floor(pos)
    frac = pos - f0
    i0 = f0.astype(np.int64) + 1  # one padding column on each side takes what falls outside
    A = np.zeros((n, g, g + 2))
    k, r = np.arange(n)[:, None], np.arange(g)[None, :]
    A[k, r, np.clip(i0, 0, g + 1)] = 1.0 - frac  # the two columns differ but in the padding
    A[k, r, np.clip(i0 + 1, 0, g + 1)] = frac
    return A[:, :, 1:-1]


def _cut_chunk(W: np.ndarray, T: np.ndarray, Ts: np.ndarray, order: np.ndarray, g: int) -> np.ndarray:
    """The canonical cut images (len(W) * directions * shares, g, g) of flattened images W (k, g*g)."""
    c = np.arange(g) + 0.5 - g / 2.0
    yy, xx = (a.ravel() for a in np.meshgrid(c, c, indexing="ij"))
    shares = np.asarray(CUT_SHARES)
    cum = np.cumsum(W[:, order], axis=2)  # (k, directions, g*g): the mass behind each threshold
    idx = np.minimum(np.stack([(cum < s * cum[..., -1:]).sum(axis=2) for s in shares], axis=2), g * g - 1)
    thr = Ts[np.arange(len(T))[None, :, None], idx]  # (k, directions, shares)
    H = (W[:, None, None, :] * (T[None, :, None, :] > thr[..., None])).reshape(-1, g * g)
    m = np.maximum(H.sum(axis=1), 1e-12)
    cy, cx = H @ yy / m, H @ xx / m
    d2 = (yy[None] - cy[:, None]) ** 2 + (xx[None] - cx[:, None]) ** 2
    R = np.sqrt(np.where(H > 0.5, d2, 0.0).max(axis=1)) + 0.5
    u = (np.arange(g) + 0.5) / g * 2.0 - 1.0
    Ay = _interp_matrices(cy[:, None] + g / 2.0 - 0.5 + R[:, None] * u, g)
    Ax = _interp_matrices(cx[:, None] + g / 2.0 - 0.5 + R[:, None] * u, g)
    return Ay @ H.reshape(-1, g, g) @ Ax.transpose(0, 2, 1)


def cut_images(images) -> np.ndarray:
    """(k * CUT_DIRECTIONS * len(CUT_SHARES), g, g) canonical images of the cuts of canonical images
    (k, g, g) (`shape_descriptors.canonical`): view-major, then direction, then share."""
    imgs = np.asarray(images, dtype=np.float64)
    imgs = imgs[None] if imgs.ndim == 2 else imgs
    if imgs.ndim != 3 or imgs.shape[1] != imgs.shape[2]:
        raise BolusError(f"cut_images needs square images (k, g, g), got shape {imgs.shape}")
    g = imgs.shape[-1]
    c = np.arange(g) + 0.5 - g / 2.0
    yy, xx = np.meshgrid(c, c, indexing="ij")
    a = 2.0 * np.pi * np.arange(CUT_DIRECTIONS) / CUT_DIRECTIONS
    T = np.cos(a)[:, None] * xx.ravel() + np.sin(a)[:, None] * yy.ravel()  # (directions, g*g)
    order = np.argsort(T, axis=1, kind="stable")
    Ts = np.take_along_axis(T, order, axis=1)
    W = imgs.reshape(len(imgs), -1)
    parts = [_cut_chunk(W[i:i + CHUNK], T, Ts, order, g) for i in range(0, len(W), CHUNK)]
    return np.concatenate(parts) if parts else np.zeros((0, g, g))


def cut_descriptors(images) -> np.ndarray:
    """(k * CUT_DIRECTIONS * len(CUT_SHARES), ZERNIKE_COUNT) float16 Zernike magnitudes of `cut_images`."""
    return sd.zernike(cut_images(images)).astype(np.float16)


def convex_hull_mask(mask: np.ndarray) -> np.ndarray:
    """(H,W) bool: the pixels whose centres lie in the convex hull of the centres of mask's pixels."""
    m = np.asarray(mask, dtype=bool)
    ys, xs = np.nonzero(m)
    if xs.size < 3:
        return m.copy()
    try:
        eq = ConvexHull(np.column_stack([xs, ys]).astype(np.float64)).equations
    except QhullError:  # all on one line: the hull is the mask
        return m.copy()
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = (np.column_stack([xx.ravel(), yy.ravel()]) @ eq[:, :2].T + eq[:, 2] <= 0.5).all(axis=1)
    out = np.zeros_like(m)
    out[y0:y1, x0:x1] = inside.reshape(yy.shape)
    return out


def occluder_variants(image, mask) -> list[np.ndarray]:
    """Silhouettes (H,W) bool of ``mask`` with each foreign-coloured part of it (module doc) replaced by the
    part's pixels inside the convex hull of the rest; image (H,W,3) float in [0,1] at the mask's size."""
    img = np.asarray(image, dtype=np.float64)
    m = np.asarray(mask, dtype=bool)
    if img.ndim != 3 or img.shape[:2] != m.shape or img.shape[2] != 3:
        raise BolusError(f"occluder_variants needs an (H,W,3) image of the mask's size {m.shape}, got {img.shape}")
    if not m.any():
        return []
    smooth = ndimage.gaussian_filter(img, (1.0, 1.0, 0.0))
    chroma = smooth[..., :2] / (smooth.sum(axis=2, keepdims=True) + 1e-6)
    foreign = m & (np.linalg.norm(chroma - np.median(chroma[m], axis=0), axis=2) > OCCLUDER_CHROMA)
    r = max(2.0, OCCLUDER_OPEN * float(np.hypot(*m.shape)))
    k = int(np.ceil(r))
    y, x = np.mgrid[-k:k + 1, -k:k + 1]
    foreign = ndimage.binary_opening(foreign, structure=x * x + y * y <= r * r)
    lab, count = ndimage.label(foreign)
    out = []
    for part in range(1, count + 1):
        p = lab == part
        if p.sum() < OCCLUDER_MIN * m.sum():
            continue
        rest_lab, n = ndimage.label(m & ~p, structure=np.ones((3, 3)))
        if n == 0:
            continue
        rest = rest_lab == 1 + int(np.argmax(np.bincount(rest_lab.ravel())[1:]))
        out.append(rest | (p & convex_hull_mask(rest)))
    return out
