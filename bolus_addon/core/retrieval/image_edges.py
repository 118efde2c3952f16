"""Edges of a photo by visual entropies (seed 5.1.1, eqs. 5-1..5-4).

Images are numpy arrays: (H,W,3) RGB, (H,W) grey or (H,W,4) RGBA (alpha ignored), uint8
(0..255), uint16 (0..65535) or float in [0,1]; pixel (x, y) is column x, row y (y down).

Pipeline of `edge_mask` (-> (H,W) bool):

1. intensity (eq. 5-2): I = 0.299 R + 0.587 G + 0.114 B, in [0,1], blurred by ``smooth`` (0.7 px);
2. every k x k sliding block ((H-k+1) x (W-k+1), Figure 5-1): its intensities in bins of width
   1 / ``levels`` (32) counted from the block's darkest pixel, p_i = count of bin i / k^2, and
       texture entropy  -sum_i p_i ln p_i        (eq. 5-1)
       edge entropy      sum_i p_i e^(1 - p_i)   (eq. 5-3; empty bins add nothing)
3. E_block = eta_1 * texture + eta_2 * edge (eq. 5-4), eta = (1, 1);
4. edge blocks: the top ``fraction`` (0.1) of the blocks by E_block, at most that many (ties at
   the threshold left out), never a uniform block (E_block = eta_2);
5. edge pixels: a pixel is one when at least (k - 1.5) / k of the blocks that cover it are edge
   blocks (near the image border: of the blocks that exist).

Design notes: docs/design/retrieval.md.
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

from ..errors import BolusError

__all__ = ["LUMA", "SMOOTH", "as_image", "intensity", "block_entropies", "block_entropy", "edge_blocks", "edge_mask"]

LUMA = (0.299, 0.587, 0.114)  #: eq. 5-2 weights of R, G, B
CHUNK = 1_000_000  #: block values held at once by `block_entropies` (k^2 per block; 8 MB per float array)
SMOOTH = 0.7  #: Gaussian blur (px) of the intensity before the entropies (module doc, step 1)


def as_image(image, name: str = "image") -> np.ndarray:
    """An image as float64 in [0,1]: (H,W) grey -> (H,W), (H,W,3) or (H,W,4) -> (H,W,3) (alpha dropped).

    uint8 / uint16 (and other unsigned or signed integer types, scaled by their maximum) or floats in
    [0,1] (values within 1e-6 outside are clipped).  BolusError on anything else: other shapes, fewer than
    2 x 2 pixels, NaN or infinite values, floats outside [0,1], negative integers.
    """
    try:
        a = np.asarray(image)
    except Exception as exc:  # ragged lists and the like
        raise BolusError(f"the {name} is not an image array ({exc})") from None
    if a.dtype == object or a.dtype.kind not in "biuf":
        raise BolusError(f"the {name} is not an image: a numeric (H, W), (H, W, 3) or (H, W, 4) array is needed "
                         f"(got dtype {a.dtype})")
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (3, 4))):
        raise BolusError(f"the {name} must be (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA; got shape {a.shape}")
    if a.shape[0] < 2 or a.shape[1] < 2:
        raise BolusError(f"the {name} is {a.shape[1]} x {a.shape[0]} pixels: at least 2 x 2 are needed to find edges")
    if a.ndim == 3 and a.shape[2] == 4:
        a = a[..., :3]
    if a.dtype.kind == "b":
        return a.astype(np.float64)
    if a.dtype.kind in "iu":
        if a.dtype.kind == "i" and (a < 0).any():
            raise BolusError(f"the {name} has negative pixel values")
        return a.astype(np.float64) / float(np.iinfo(a.dtype).max)
    f = a.astype(np.float64)
    if not np.isfinite(f).all():
        raise BolusError(f"the {name} has NaN or infinite pixel values ({int((~np.isfinite(f)).sum())} of {f.size})")
    lo, hi = float(f.min()), float(f.max())
    if lo < -1e-6 or hi > 1 + 1e-6:
        raise BolusError(f"a float {name} must have values in [0, 1] (got {lo:.4g} .. {hi:.4g}); "
                         "divide 8-bit values by 255")
    return np.clip(f, 0.0, 1.0)


def intensity(rgb) -> np.ndarray:
    """Eq. 5-2: rgb (H,W,3) uint8 or float in [0,1] ((H,W) grey returned as is, (H,W,4): alpha ignored)
    -> (H,W) float64 in [0,1], 0.299 R + 0.587 G + 0.114 B."""
    a = as_image(rgb)
    if a.ndim == 2:
        return a
    out = LUMA[0] * a[..., 0] + LUMA[1] * a[..., 1] + LUMA[2] * a[..., 2]
    return np.clip(out, 0.0, 1.0)


def _check_k_levels(shape, k, levels) -> tuple[int, int]:
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 2:
        raise BolusError(f"the block size k must be an integer >= 2, got {k!r}")
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)) or not 2 <= levels <= 65536:
        raise BolusError(f"levels must be an integer in 2..65536, got {levels!r}")
    H, W = shape[:2]
    if H < k or W < k:
        raise BolusError(f"the image is {W} x {H} pixels, smaller than one {k} x {k} block")
    return int(k), int(levels)


def _box_sum(a: np.ndarray, k: int) -> np.ndarray:
    """Sums of a (H,W) over every k x k window -> (H-k+1, W-k+1), exact for integer a."""
    c = np.zeros((a.shape[0] + 1, a.shape[1] + 1), dtype=np.int64 if a.dtype.kind in "biu" else np.float64)
    np.cumsum(a, axis=0, out=c[1:, 1:])
    np.cumsum(c[1:, 1:], axis=1, out=c[1:, 1:])
    return c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]


def block_entropies(gray, k: int = 3, levels: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Texture (eq. 5-1) and edge (eq. 5-3) entropies of every k x k sliding block.

    gray (H,W) float in [0,1] (or any image `as_image` accepts: RGB goes through eq. 5-2 first).
    Returns (texture (H-k+1, W-k+1), edge (H-k+1, W-k+1)); block [r, c] covers rows r..r+k-1 and
    columns c..c+k-1.  Natural log; a block's intensities fall into bins of width 1 / ``levels``
    counted from the block's darkest pixel (module doc, step 2).  Memory: k^2 values of at most
    CHUNK blocks at a time.
    """
    g = np.asarray(gray)
    g = intensity(g) if not (g.ndim == 2 and g.dtype.kind == "f") else as_image(g, "intensity image")
    k, levels = _check_k_levels(g.shape, k, levels)
    H, W = g.shape
    K = k * k
    Hb, Wb = H - k + 1, W - k + 1
    texture = np.empty((Hb, Wb))
    edge = np.empty((Hb, Wb))
    rows = max(1, CHUNK // (K * Wb))
    ids = np.arange(K)[:, None]
    for r0 in range(0, Hb, rows):
        r1 = min(Hb, r0 + rows)
        V = np.stack([g[r0 + i:r1 + i, j:j + Wb].ravel() for i in range(k) for j in range(k)])  # (K, blocks)
        S = np.sort(np.minimum(((V - V.min(axis=0)) * levels).astype(np.int32), levels - 1), axis=0)
        start = np.ones(S.shape, dtype=bool)
        start[1:] = S[1:] != S[:-1]
        end = np.ones(S.shape, dtype=bool)
        end[:-1] = start[1:]
        first = np.maximum.accumulate(np.where(start, ids, 0), axis=0)
        p = np.where(end, (ids - first + 1) / K, 0.0)  # at each run's last value: its share of the block
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -np.where(end, p * np.log(np.where(end, p, 1.0)), 0.0).sum(axis=0)
        e = np.where(end, p * np.exp(1.0 - p), 0.0).sum(axis=0)
        texture[r0:r1] = t.reshape(r1 - r0, Wb) + 0.0  # no -0.0
        edge[r0:r1] = e.reshape(r1 - r0, Wb)
    return texture, edge


def block_entropy(texture: np.ndarray, edge: np.ndarray, eta=(1.0, 1.0)) -> np.ndarray:
    """Eq. 5-4: E_block = eta_1 * texture + eta_2 * edge, same shape as the inputs."""
    e1, e2 = _check_eta(eta)
    return e1 * np.asarray(texture, dtype=np.float64) + e2 * np.asarray(edge, dtype=np.float64)


def checked_float(value, ok, message: str) -> float:
    """float(value) when ``ok`` holds for it, else BolusError "<message>, got <value>"."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise BolusError(f"{message}, got {value!r}") from None
    if not ok(x):
        raise BolusError(f"{message}, got {value!r}")
    return x


def _check_eta(eta) -> tuple[float, float]:
    try:
        e1, e2 = (float(v) for v in eta)
    except (TypeError, ValueError):
        raise BolusError(f"eta must be two weights (eta_1, eta_2), got {eta!r}") from None
    if not (np.isfinite(e1) and np.isfinite(e2)) or e1 < 0 or e2 < 0 or e1 + e2 <= 0:
        raise BolusError(f"the weights eta must be finite, >= 0 and not both 0, got {eta!r}")
    return e1, e2


def edge_blocks(E: np.ndarray, fraction: float, floor: float) -> np.ndarray:
    """The edge blocks (bool, E's shape): the largest E, at most ``fraction`` of the blocks, above ``floor``.

    Blocks tied at the threshold are all left out (E takes few distinct values: a 3 x 3 block has one of 30
    histograms), unless the top value alone is more than ``fraction`` of the blocks (then it is taken).
    """
    if E.size == 0:
        return np.zeros(E.shape, dtype=bool)
    Er = np.round(E, 9)  # equal histograms summed in another bin order differ in the last bits
    values, counts = np.unique(Er, return_counts=True)
    above = np.cumsum(counts[::-1])[::-1] - counts  # blocks strictly above each value
    limit = fraction * E.size
    j = int(np.argmax(above <= limit))  # the smallest value with at most `limit` blocks above it
    keep = Er > values[j] if above[j] > 0 else Er >= values[-1]
    return keep & (Er > floor + 1e-9 * max(1.0, abs(floor)))


def edge_mask(rgb, k: int = 3, eta=(1.0, 1.0), fraction: float = 0.1, levels: int = 32,
              smooth: float = SMOOTH, return_blocks: bool = False):
    """Edge pixels of an image by visual entropies (eqs. 5-1..5-4, module doc steps 1-5).

    rgb (H,W,3) uint8 or float in [0,1] ((H,W) grey, (H,W,4) RGBA accepted) -> (H,W) bool.
    k: block size (>= 2); eta: (eta_1, eta_2) of eq. 5-4; fraction in (0, 1]: the share of blocks
    ranked as edge blocks; levels: intensity bins of the entropies; smooth: Gaussian blur in pixels
    (>= 0) of the intensity first.  With ``return_blocks`` also the
    (H-k+1, W-k+1) bool edge blocks.  BolusError when the image has no edges (it is uniform).
    """
    fraction = checked_float(fraction, lambda x: 0.0 < x <= 1.0,
                             "fraction must be a number in (0, 1] (the share of blocks that are edge blocks)")
    e1, e2 = _check_eta(eta)
    smooth = checked_float(smooth, lambda x: np.isfinite(x) and x >= 0, "smooth must be a blur radius in pixels >= 0")
    gray = intensity(rgb)
    k, levels = _check_k_levels(gray.shape, k, levels)
    if smooth > 0:
        gray = np.clip(gaussian_filter(gray, smooth, mode="nearest"), 0.0, 1.0)
    texture, edge = block_entropies(gray, k, levels)
    E = e1 * texture + e2 * edge
    blocks = edge_blocks(E, fraction, floor=e2)  # a uniform block: texture 0, edge 1
    if not blocks.any():
        raise BolusError(f"the photo has no edges: its intensity varies by {np.ptp(gray):.3g} of the full range, "
                         f"less than one of {levels} levels within any {k} x {k} block; use a photo of the object "
                         "against a background")
    H, W = gray.shape
    # votes[y, x]: edge blocks covering pixel (x, y); cover: blocks covering it at all
    pad = np.zeros((H + k - 1, W + k - 1), dtype=np.int32)
    pad[k - 1:H, k - 1:W] = blocks
    votes = _box_sum(pad, k)
    pad[:] = 0
    pad[k - 1:H, k - 1:W] = 1
    cover = _box_sum(pad, k)
    mask = votes * k >= (k - 1.5) * cover
    mask &= votes > 0
    if return_blocks:
        return mask, blocks
    return mask
