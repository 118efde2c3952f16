"""The object's silhouette in a photo: the seed's front end (5.1) made robust, for the view matcher.

`photo_silhouette(rgb)` -> `Silhouette` (mask (H,W) bool at the working size, and what was found):

1. checks: at least MIN_SIDE (64) pixels each way, not uniform (all white, all black or blank:
   intensity range under MIN_RANGE); photos longer than WORK_SIDE are block-averaged down first;
2. background: a quadratic colour surface per channel (a gradient and a vignette) fitted to the frame of
   the photo (2 % wide): first the frame pixels near its median colour, then refitted twice without
   those more than 3 robust deviations off (an object that touches the border); D = the largest
   channel difference from that surface, after a BLUR px blur;
3. threshold: Otsu's threshold t of D gives the seeds (D > t), grown (hysteresis) through the pixels
   with D > max(LOW * t, noise floor), the floor 4 robust deviations of D on the frame: the shaded
   side of an object close to the background joins the lit side it touches;
4. the seed's front end: entropy edges (eqs. 5-1..5-4) and the spectral contour (eqs. 5-5..5-7,
   `image_contour.contour_pixels`); the object cluster's edge pixels within CLOSE of the grown region
   are added (they close an outline where the colour difference alone fades);
5. closing by CLOSE (1.5 % of the diagonal), hole filling (but for holes of at least HOLE_MIN of the
   region that look like the background: a ring's opening), the largest 8-connected blob, its
   outermost pixel layer trimmed to where D is half its local step (the low threshold grows a pixel too far);
6. refusals: a blob under MIN_AREA of the photo (no object) or over MAX_AREA (no background left);
   ``cut``: the share of its outline on the photo's edge (the object partly out of the frame).

Design notes: docs/design/retrieval.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..errors import BolusError
from .image_edges import as_image
from .image_contour import contour_pixels

__all__ = ["MIN_SIDE", "WORK_SIDE", "Silhouette", "photo_silhouette", "otsu", "background_distance"]

MIN_SIDE = 64  #: px: smaller photos are refused
WORK_SIDE = 480  #: px: longer photos are block-averaged down to at most this (the descriptors need no more)
MIN_RANGE = 0.03  #: intensity range (0..1) under which a photo counts as uniform
FRAME = 0.02  #: width of the background frame, share of the shorter side (>= 2 px)
LOW = 0.15  #: the growing threshold, share of Otsu's
FLOOR_MADS = 4.0  #: the noise floor, robust deviations of D on the frame
BLUR = 0.6  #: px, the gaussian blur of the photo before D (noise; wider blurs grow a halo round the object)
CLOSE = 0.015  #: closing radius, share of the diagonal (>= 2 px)
MIN_AREA, MAX_AREA = 0.002, 0.97  #: the blob's share of the photo
HOLE_MIN = 0.01  #: holes at least this share of the region that look like the background stay open


@dataclass
class Silhouette:
    """mask (H,W) bool the object at the working size; scale: working px per photo px; threshold: Otsu's t;
    contour_points: the seed front end's contour pixels (0 when it found none)."""

    mask: np.ndarray
    scale: float
    threshold: float
    contour_points: int
    cut: float = 0.0  #: share of the outline on the photo's edge (the object partly out of the frame)
    image: np.ndarray | None = None  #: (H,W,3) float the photo at the working size (the mask's)


def otsu(values: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold of values (n,) (the split of their histogram with the largest between-class variance)."""
    v = np.asarray(values, dtype=np.float64).ravel()
    lo, hi = float(v.min()), float(v.max())
    if not hi > lo:
        return hi
    hist, edges = np.histogram(v, bins=bins, range=(lo, hi))
    mids = (edges[:-1] + edges[1:]) / 2
    w0 = np.cumsum(hist)
    w1 = w0[-1] - w0
    s0 = np.cumsum(hist * mids)
    with np.errstate(divide="ignore", invalid="ignore"):
        between = w0 * w1 * (s0 / w0 - (s0[-1] - s0) / w1) ** 2
    between[~np.isfinite(between)] = -1.0
    return float(edges[int(np.argmax(between)) + 1])


def _shrink(img: np.ndarray) -> tuple[np.ndarray, float]:
    H, W = img.shape[:2]
    f = int(np.ceil(max(H, W) / WORK_SIDE))
    if f <= 1:
        return img, 1.0
    h, w = H // f, W // f
    return img[:h * f, :w * f].reshape(h, f, w, f, -1).mean(axis=(1, 3)), 1.0 / f


def background_distance(img: np.ndarray) -> tuple[np.ndarray, float]:
    """(D (H,W): the largest channel difference from the background surface, the noise floor) of img (H,W,3)."""
    H, W = img.shape[:2]
    b = max(2, int(round(FRAME * min(H, W))))
    frame = np.zeros((H, W), dtype=bool)
    frame[:b], frame[-b:], frame[:, :b], frame[:, -b:] = True, True, True, True
    ys, xs = np.nonzero(frame)
    def terms(x, y):  # a quadratic surface: a gradient and a vignette
        return [np.ones_like(x), x, y, x * x, y * y, x * y]

    A = np.column_stack(terms(xs / W - 0.5, ys / H - 0.5))
    C = img[ys, xs]
    res = np.abs(C - np.median(C, axis=0)).max(axis=1)  # first: the frame's typical colour (an object in
    use = np.ones(len(xs), dtype=bool)                 # less than half of the frame does not move it)
    for _ in range(3):
        mad = 1.4826 * float(np.median(np.abs(res[use] - np.median(res[use])))) + 1e-3
        use = res <= np.median(res[use]) + 3.0 * mad + 0.01
        coef, *_ = np.linalg.lstsq(A[use], C[use], rcond=None)
        res = np.abs(C - A @ coef).max(axis=1)
    yy, xx = np.mgrid[0:H, 0:W]
    plane = np.stack(terms(xx / W - 0.5, yy / H - 0.5), axis=-1) @ coef
    smooth = ndimage.gaussian_filter(img, (BLUR, BLUR, 0.0))
    D = np.abs(smooth - plane).max(axis=2)
    d = D[frame][use]
    floor = float(np.median(d)) + FLOOR_MADS * 1.4826 * float(np.median(np.abs(d - np.median(d)))) + 0.01
    return D, floor


def _front_end_edges(img: np.ndarray, rng) -> tuple[np.ndarray, int]:
    """The object cluster's edge pixels (H,W) bool of the seed's 5.1 front end and its contour size."""
    try:
        c = contour_pixels(img, rng=rng)
    except BolusError:
        return np.zeros(img.shape[:2], dtype=bool), 0
    m = np.zeros(img.shape[:2], dtype=bool)
    p = c.object_points.astype(np.int64)
    m[p[:, 1], p[:, 0]] = True
    return m, len(c.points)


def _disc(r: float) -> np.ndarray:
    k = int(np.ceil(r))
    y, x = np.mgrid[-k:k + 1, -k:k + 1]
    return x * x + y * y <= r * r


def _fill_holes(region: np.ndarray, D: np.ndarray, low: float) -> np.ndarray:
    """region with its holes filled, but for the holes of at least HOLE_MIN of the region's area that look
    like the background (mean D under ``low``): the opening of a ring stays open."""
    filled = ndimage.binary_fill_holes(region)
    lab, count = ndimage.label(filled & ~region)
    if count == 0:
        return filled
    idx = np.arange(1, count + 1)
    area = ndimage.sum_labels(np.ones_like(D), lab, idx)
    mean = ndimage.mean(D, lab, idx)
    keep = idx[(area >= HOLE_MIN * filled.sum()) & (mean < low)]
    return filled & ~np.isin(lab, keep)


def _trim(mask: np.ndarray, D: np.ndarray) -> np.ndarray:
    """mask without the pixels of its outermost layer whose D is under half of the largest D of their 3 x 3
    neighbourhood: the outline put where the blurred step is half way (the low threshold grows one pixel too
    far; a dim side several pixels wide loses one pixel at most)."""
    band = mask & ~ndimage.binary_erosion(mask)
    return mask & ~(band & (D < 0.5 * ndimage.maximum_filter(D, size=3)))


def photo_silhouette(rgb, rng=0, use_front_end: bool = True) -> Silhouette:
    """The object's silhouette in a photo (module doc, steps 1-6); BolusError when there is none."""
    img = as_image(rgb, "photo")
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    H, W = img.shape[:2]
    if min(H, W) < MIN_SIDE:
        raise BolusError(f"the photo is {W} x {H} pixels: at least {MIN_SIDE} x {MIN_SIDE} are needed to see a shape")
    gray = img @ np.array([0.299, 0.587, 0.114])
    if float(np.ptp(gray)) < MIN_RANGE:
        tone = "white" if gray.mean() > 0.9 else "black" if gray.mean() < 0.1 else "one colour"
        raise BolusError(f"the photo is all {tone} (its brightness varies by {np.ptp(gray):.3f}): no object to find")
    img, scale = _shrink(img)
    D, floor = background_distance(img)
    t = otsu(D)
    if t <= floor:
        raise BolusError("no object stands out from the background of the photo: photograph the object against "
                         "a plain background, filling a good part of the frame")
    grown = ndimage.binary_propagation(D > t, mask=D > max(LOW * t, floor))
    r = max(2.0, CLOSE * float(np.hypot(*D.shape)))
    edges, npts = _front_end_edges(img, rng) if use_front_end else (np.zeros_like(grown), 0)
    near = ndimage.binary_dilation(grown, structure=_disc(r))
    region = grown | (edges & near)
    pad = int(np.ceil(r)) + 1
    region = np.pad(region, pad)
    region = ndimage.binary_closing(region, structure=_disc(r))[pad:-pad, pad:-pad]
    region = _fill_holes(region, D, max(LOW * t, floor))
    lab, count = ndimage.label(region, structure=np.ones((3, 3)))
    if count == 0:
        raise BolusError("no object found in the photo")
    sizes = np.bincount(lab.ravel())[1:]
    mask = _trim(lab == 1 + int(np.argmax(sizes)), D)
    share = float(mask.mean())
    if share < MIN_AREA or mask.sum() < 64:
        raise BolusError(f"no object found in the photo: the largest region that differs from the background covers "
                         f"{100 * share:.2f} % of it")
    if share > MAX_AREA:
        raise BolusError(f"the object fills {100 * share:.0f} % of the photo: leave some background round it")
    outline = mask & ~ndimage.binary_erosion(mask)
    edge = int(outline[0].sum() + outline[-1].sum() + outline[1:-1, 0].sum() + outline[1:-1, -1].sum())
    return Silhouette(mask, scale, t, npts, edge / max(1, int(outline.sum())), img)
