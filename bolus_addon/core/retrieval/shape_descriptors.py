"""Shape descriptors of a silhouette, invariant to scale, translation, in-plane rotation and mirroring.

1. `canonical(mask)`: the region resampled into a (GRID, GRID) float image: its centroid in the middle,
   its farthest pixel on the inscribed circle (scale and translation gone); the mask is blurred first
   by half the step when it is shrunk (no aliasing);
2. `zernike(images)`: |A_nm| of the Zernike moments of that image in the unit disc, n <= ORDER,
   0 <= m <= n, n - m even (36 values for ORDER 10): the magnitudes do not change when the image turns
   (A_nm is multiplied by e^(-i m phi)) or is mirrored (A_nm -> its conjugate);
3. `fourier(images)`: the centroid-distance signature r(theta), in BINS angular bins the farthest
   pixel of the region, empty bins interpolated; |FFT_k| / |FFT_0| for k = 1..HARMONICS: a turn
   shifts r(theta) circularly, a mirror reverses it; neither changes the magnitudes;
4. `describe(masks)`: (k, D) rows [zernike | fourier] (D = ZERNIKE_COUNT + HARMONICS).

`GROUPS` names the two column groups; the matcher scales each by its mean library distance.
Design notes: docs/design/retrieval.md.
"""
from __future__ import annotations

from functools import lru_cache
from math import factorial

import numpy as np
from scipy import ndimage

from ..errors import BolusError

__all__ = ["GRID", "ORDER", "BINS", "HARMONICS", "ZERNIKE_COUNT", "GROUPS", "canonical", "zernike", "fourier",
           "describe", "zernike_indices"]

GRID = 64  #: the canonical image's side in pixels
ORDER = 10  #: the highest Zernike order n
BINS = 64  #: angular bins of the centroid-distance signature
HARMONICS = 15  #: Fourier magnitudes kept (k = 1..HARMONICS)


def zernike_indices(order: int = ORDER) -> list[tuple[int, int]]:
    """(n, m) of the Zernike moments kept: n <= order, 0 <= m <= n, n - m even."""
    return [(n, m) for n in range(order + 1) for m in range(n + 1) if (n - m) % 2 == 0]


ZERNIKE_COUNT = len(zernike_indices())
GROUPS = {"zernike": slice(0, ZERNIKE_COUNT), "fourier": slice(ZERNIKE_COUNT, ZERNIKE_COUNT + HARMONICS)}


@lru_cache(maxsize=4)
def _basis(grid: int, order: int) -> np.ndarray:
    """(grid*grid, count) complex: conj(V_nm) * (n + 1) / pi * pixel area, 0 outside the unit disc."""
    c = (np.arange(grid) + 0.5) / grid * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)
    rho, theta = np.hypot(x, y).ravel(), np.arctan2(y, x).ravel()
    inside = rho <= 1.0
    area = (2.0 / grid) ** 2
    cols = []
    for n, m in zernike_indices(order):
        R = np.zeros_like(rho)
        for s in range((n - m) // 2 + 1):
            coef = (-1) ** s * factorial(n - s) / (factorial(s) * factorial((n + m) // 2 - s)
                                                   * factorial((n - m) // 2 - s))
            R += coef * rho ** (n - 2 * s)
        cols.append(np.where(inside, R * np.exp(-1j * m * theta), 0.0) * (n + 1) / np.pi * area)
    return np.column_stack(cols)


def canonical(mask, grid: int = GRID) -> np.ndarray:
    """(grid, grid) float in [0,1]: the region of mask (H,W) bool centred on its centroid and scaled so its
    farthest pixel (its outer corner) touches the inscribed circle.  BolusError on an empty mask."""
    m = np.asarray(mask, dtype=bool)
    ys, xs = np.nonzero(m)
    if xs.size == 0:
        raise BolusError("the silhouette is empty")
    cy, cx = ys.mean(), xs.mean()
    R = float(np.sqrt(((ys - cy) ** 2 + (xs - cx) ** 2).max())) + 0.75
    step = R / (grid / 2.0)  # source pixels per canonical pixel
    src = m.astype(np.float32)
    if step > 1.0:
        src = ndimage.gaussian_filter(src, 0.5 * step)
    c = (np.arange(grid) + 0.5) / grid * 2.0 - 1.0
    rr, cc = np.meshgrid(c, c, indexing="ij")
    return ndimage.map_coordinates(src, [cy + R * rr, cx + R * cc], order=1, mode="constant", cval=0.0)


def zernike(images: np.ndarray, order: int = ORDER) -> np.ndarray:
    """(k, ZERNIKE_COUNT) |A_nm| of canonical images (k, g, g) (or one (g, g))."""
    imgs = np.asarray(images, dtype=np.float64)
    imgs = imgs[None] if imgs.ndim == 2 else imgs
    g = imgs.shape[-1]
    return np.abs(imgs.reshape(len(imgs), -1) @ _basis(g, order))


def fourier(images: np.ndarray, bins: int = BINS, harmonics: int = HARMONICS) -> np.ndarray:
    """(k, harmonics) |FFT_k| / |FFT_0| of the centroid-distance signature of canonical images (k, g, g)."""
    imgs = np.asarray(images, dtype=np.float64)
    imgs = imgs[None] if imgs.ndim == 2 else imgs
    k, g = len(imgs), imgs.shape[-1]
    c = np.arange(g) + 0.5 - g / 2.0
    x, y = np.meshgrid(c, -c)
    r = np.hypot(x, y).ravel() + 0.5
    b = ((np.arctan2(y, x).ravel() + np.pi) / (2 * np.pi) * bins).astype(np.int64) % bins
    sig = np.zeros(k * bins)
    view, pix = np.nonzero(imgs.reshape(k, -1) > 0.5)
    np.maximum.at(sig, view * bins + b[pix], r[pix])
    sig = sig.reshape(k, bins)
    t = np.arange(bins)
    for v in np.flatnonzero((sig == 0).any(axis=1) & (sig > 0).any(axis=1)):  # empty bins: interpolated
        full = sig[v] > 0
        sig[v, ~full] = np.interp(t[~full], t[full], sig[v, full], period=bins)
    spec = np.abs(np.fft.rfft(sig, axis=1))
    return spec[:, 1:harmonics + 1] / np.maximum(spec[:, :1], 1e-12)


def describe(masks) -> np.ndarray:
    """(k, D) float32 descriptor rows [zernike | fourier] of silhouettes (k, H, W) bool (empty ones: NaN)."""
    masks = np.asarray(masks, dtype=bool)
    masks = masks[None] if masks.ndim == 2 else masks
    imgs = np.zeros((len(masks), GRID, GRID))
    empty = ~masks.reshape(len(masks), -1).any(axis=1)
    for i in np.flatnonzero(~empty):
        imgs[i] = canonical(masks[i])
    out = np.hstack([zernike(imgs), fourier(imgs)]).astype(np.float32)
    out[empty] = np.nan
    return out
