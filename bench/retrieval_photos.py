"""Query photos as a clinic takes them, for bench/retrieval_bench.py: each render (RGBA, the object on a
transparent film, in two lights) made into one photo per kind (``KINDS``):

* ``clean``: light A over its plain background;
* ``light``: light B (another studio light and object colour) over a vertical gradient background;
* ``noise``: clean + gaussian noise (sigma NOISE per channel);
* ``blur``: clean blurred (gaussian, BLUR px);
* ``cropped``: clean moved so that about CROPPED of the object's pixels leave the frame;
* ``phone``: light A scaled into a 9:16 portrait frame (PHONE px) on another plain background, with
  mild noise (a phone's aspect and framing);
* ``occlusion``: clean with a grey rectangle over about 15 % of the object.
"""
from __future__ import annotations

import zlib

import numpy as np
from scipy import ndimage

KINDS = ("clean", "light", "noise", "blur", "cropped", "phone", "occlusion")
NOISE = 0.05  #: sigma of the 'noise' photos, [0, 1] units per channel
BLUR = 2.0  #: px, the 'blur' photos' gaussian
CROPPED = 0.2  #: share of the object's pixels out of the frame in the 'cropped' photos
PHONE = (270, 480)  #: width, height of the 'phone' photos
PHONE_BACKGROUND = (0.86, 0.86, 0.82)
GRADIENT = ((0.95, 0.90, 0.78), (0.55, 0.50, 0.45))  #: the 'light' photos' background, top to bottom


def composite(rgba: np.ndarray, background) -> np.ndarray:
    """(H,W,3) uint8: rgba (H,W,4) float in [0,1] (straight alpha) over background: an sRGB colour (3,) or an
    (H,W,3) float image."""
    a = rgba[..., 3:4]
    bg = np.broadcast_to(np.asarray(background, float), rgba[..., :3].shape)
    return np.clip(np.rint(255 * (rgba[..., :3] * a + bg * (1 - a))), 0, 255).astype(np.uint8)


def gradient(shape, top, bottom) -> np.ndarray:
    """(H,W,3) float: a vertical gradient from ``top`` to ``bottom``, a little darker towards the corners."""
    H, W = shape[:2]
    t = np.linspace(0.0, 1.0, H)[:, None, None]
    g = (1 - t) * np.asarray(top, float) + t * np.asarray(bottom, float)
    yy, xx = np.mgrid[0:H, 0:W]
    r = np.hypot((xx - W / 2) / W, (yy - H / 2) / H)[..., None]
    return np.clip(g * (1 - 0.25 * r ** 2) * np.ones((1, W, 1)), 0, 1)


def add_noise(rgb: np.ndarray, sigma: float, rng) -> np.ndarray:
    """(H,W,3) uint8 with gaussian noise of ``sigma`` (in [0,1] units) per channel, clipped."""
    rng = np.random.default_rng(rng)
    noisy = np.asarray(rgb, float) + rng.normal(0.0, 255.0 * sigma, np.shape(rgb))
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def blur(rgb: np.ndarray, sigma: float = BLUR) -> np.ndarray:
    return np.clip(np.rint(ndimage.gaussian_filter(np.asarray(rgb, float), (sigma, sigma, 0))), 0, 255).astype(np.uint8)


def shift_out(rgba: np.ndarray, share: float, rng) -> tuple[np.ndarray, float]:
    """rgba moved towards a random side until about ``share`` of its object's pixels (alpha > 0.5) leave the
    frame -> (moved rgba, the share that left)."""
    g = np.random.default_rng(rng)
    m = rgba[..., 3] > 0.5
    total = float(m.sum())
    axis, sign = int(g.integers(2)), (-1 if g.random() < 0.5 else 1)
    counts = m.sum(axis=1 - axis)  # object pixels per row (axis 0) or column (axis 1)
    past = np.cumsum(counts[::-1] if sign > 0 else counts)  # pixels out of the frame after a move of k + 1
    move = int(np.searchsorted(past, share * total)) + 1
    n = len(counts)
    out = np.zeros_like(rgba)
    src = [slice(None)] * 2
    dst = [slice(None)] * 2
    src[axis], dst[axis] = (slice(0, n - move), slice(move, n)) if sign > 0 else (slice(move, n), slice(0, n - move))
    out[tuple(dst)] = rgba[tuple(src)]
    return out, 1.0 - float((out[..., 3] > 0.5).sum()) / total


def phone_frame(rgba: np.ndarray, size=PHONE) -> np.ndarray:
    """rgba scaled to the portrait frame's width and centred in it (transparent round it)."""
    W, H = size
    f = W / rgba.shape[1]
    small = ndimage.zoom(rgba, (f, f, 1), order=1)
    out = np.zeros((H, W, 4))
    h, w = min(H, small.shape[0]), min(W, small.shape[1])
    y0 = (H - h) // 2 + int(0.08 * H)  # a little below the middle, as a hand holds a phone
    out[y0:y0 + h, :w] = small[:h, :w]
    return np.clip(out, 0, 1)


def photos_of(render: dict, occlude, object_mask, kinds=KINDS, rng=0) -> list[dict]:
    """One query per kind of a render {class, view, rgba, rgba_light, background, ...}; ``occlude`` and
    ``object_mask`` are the bench's."""
    g = np.random.default_rng([int(rng), zlib.crc32(f"{render['class']} / {render['view']}".encode())])
    clean = composite(render["rgba"], render["background"])
    out = []
    for kind in kinds:
        extra, bg = {}, render["background"]
        if kind == "clean":
            rgb = clean
        elif kind == "light":
            bg = gradient(render["rgba"].shape, *GRADIENT)
            rgb = composite(render["rgba_light"], bg)
            bg = tuple(bg.reshape(-1, 3).mean(axis=0))
        elif kind == "noise":
            rgb = add_noise(clean, NOISE, g)
        elif kind == "blur":
            rgb = blur(clean)
        elif kind == "cropped":
            moved, left = shift_out(render["rgba"], CROPPED, g)
            rgb, extra["cropped_share"] = composite(moved, bg), left
        elif kind == "phone":
            bg = PHONE_BACKGROUND
            rgb = add_noise(composite(phone_frame(render["rgba"]), bg), 0.02, g)
        elif kind == "occlusion":
            rgb, extra["occluded_share"] = occlude(clean, object_mask(clean, bg), 0.15, g)
        else:
            raise ValueError(f"unknown kind {kind!r}")
        out.append({"id": f"{render['class']} / {render['view']} / {kind}", "class": render["class"],
                    "view": render["view"], "condition": kind, "rgb": rgb, "background": bg,
                    "light": render["light"], "path": render.get("path", "-"), **extra})
    return out
