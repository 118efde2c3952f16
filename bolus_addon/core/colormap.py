"""Perceptual colour map for vertex colours (viridis, sampled at 17 stops).

`scalar_to_linear_rgba(values, vmax)` maps values in [0, vmax] to viridis and returns
*linear* RGBA (k,4) float32, since Blender's FLOAT_COLOR attributes are scene-linear:
storing sRGB numbers would show washed-out colours.
"""
from __future__ import annotations

import numpy as np

__all__ = ["VIRIDIS_SRGB", "scalar_to_linear_rgba", "categorical_linear_rgba", "diverging_linear_rgba", "outside_linear_rgba", "srgb_to_linear", "robust_max"]

#: matplotlib's viridis at t = 0, 1/16, ..., 1 (sRGB)
VIRIDIS_SRGB = np.array(
    [
        (0.2670, 0.0049, 0.3294),
        (0.2823, 0.0950, 0.4173),
        (0.2788, 0.1755, 0.4834),
        (0.2590, 0.2515, 0.5247),
        (0.2297, 0.3224, 0.5457),
        (0.1994, 0.3876, 0.5546),
        (0.1727, 0.4488, 0.5579),
        (0.1490, 0.5081, 0.5573),
        (0.1276, 0.5669, 0.5506),
        (0.1206, 0.6258, 0.5335),
        (0.1579, 0.6838, 0.5017),
        (0.2461, 0.7389, 0.4520),
        (0.3692, 0.7889, 0.3829),
        (0.5160, 0.8312, 0.2943),
        (0.6785, 0.8637, 0.1895),
        (0.8456, 0.8873, 0.0997),
        (0.9932, 0.9062, 0.1439),
    ]
)


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB transfer function, inverse."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def robust_max(values: np.ndarray, pct: float = 98.0) -> float:
    """The pct-th percentile of the positive values (1.0 when there are none)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[v > 0]
    return float(np.percentile(v, pct)) if v.size else 1.0


def scalar_to_linear_rgba(values: np.ndarray, vmax: float | None = None) -> np.ndarray:
    """values (k,) -> linear RGBA (k,4) float32 through viridis on [0, vmax].

    vmax defaults to `robust_max(values)` so that a few spikes do not wash out the rest.
    """
    v = np.asarray(values, dtype=np.float64)
    vmax = robust_max(v) if vmax is None else float(vmax)
    t = np.clip(v / vmax, 0.0, 1.0) if vmax > 0 else np.zeros_like(v)
    x = t * (len(VIRIDIS_SRGB) - 1)
    i = np.minimum(np.floor(x).astype(np.int64), len(VIRIDIS_SRGB) - 2)
    w = (x - i)[:, None]
    srgb = VIRIDIS_SRGB[i] * (1 - w) + VIRIDIS_SRGB[i + 1] * w
    out = np.ones((len(v), 4), dtype=np.float32)
    out[:, :3] = srgb_to_linear(srgb)
    return out


#: Okabe-Ito colour-blind-safe palette (sRGB), for patch labels
OKABE_ITO_SRGB = np.array(
    [
        (0.902, 0.624, 0.000),
        (0.337, 0.706, 0.914),
        (0.000, 0.620, 0.451),
        (0.941, 0.894, 0.259),
        (0.000, 0.447, 0.698),
        (0.835, 0.369, 0.000),
        (0.800, 0.475, 0.655),
        (0.600, 0.600, 0.600),
    ]
)


#: sRGB grey for everything outside the region
OUTSIDE_SRGB = (0.6, 0.6, 0.6)


def outside_linear_rgba() -> np.ndarray:
    """The linear RGBA (4,) float32 of `OUTSIDE_SRGB`."""
    return np.array([*srgb_to_linear(np.array(OUTSIDE_SRGB)), 1.0], dtype=np.float32)


def categorical_linear_rgba(labels: np.ndarray, outside=OUTSIDE_SRGB) -> np.ndarray:
    """Integer labels (k,) -> linear RGBA (k,4) float32; negative labels get ``outside`` (sRGB).

    Colours cycle through the 8 Okabe-Ito colours, darkened on each further cycle.
    """
    labels = np.asarray(labels, dtype=np.int64)
    n = len(OKABE_ITO_SRGB)
    lab = np.maximum(labels, 0)
    srgb = OKABE_ITO_SRGB[lab % n] * (0.75 ** (lab // n))[:, None]
    srgb[labels < 0] = outside
    out = np.ones((len(labels), 4), dtype=np.float32)
    out[:, :3] = srgb_to_linear(srgb)
    return out


def diverging_linear_rgba(values: np.ndarray, vmax: float) -> np.ndarray:
    """Signed values (k,) -> linear RGBA (k,4): blue (-vmax, shrunk) - white (0) - red (+vmax, stretched).

    sRGB end colours (0.23, 0.30, 0.75) and (0.71, 0.02, 0.15) of Moreland's cool-warm map.
    """
    t = np.clip(np.asarray(values, dtype=np.float64) / float(vmax), -1.0, 1.0)[:, None]
    white = np.array([0.97, 0.97, 0.97])
    cold = np.array([0.23, 0.30, 0.75])
    warm = np.array([0.71, 0.02, 0.15])
    srgb = np.where(t < 0, white + (cold - white) * (-t), white + (warm - white) * t)
    out = np.ones((len(t), 4), dtype=np.float32)
    out[:, :3] = srgb_to_linear(srgb)
    return out
