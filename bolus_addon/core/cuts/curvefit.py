"""Least-squares cut curves in a plane (seed 4.1.2, eqs. 4-6..4-9 and 6-37).

The border nodes of two patches are projected on a plane Gamma (`project_to_plane`,
eqs. 4-6..4-9) and expressed in in-plane axes (`plane_axes`); a low-order curve is
fitted to them (eq. 6-37): y = f(x), a line or a parabola, for an open border
(`fit_open_curve`), an elliptic Fourier curve for a closed one (`fit_closed_curve`,
order 1 is an ellipse).  `signed_distance_closed` gives the signed distance of points
to a closed curve, whose zero set is the exact curve (the level set that
`levelset_cut` cuts the triangles along).  A higher-order curve is taken only when it
clearly fits better than the mesh's own zig-zag explains.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..errors import BolusError

__all__ = ["project_to_plane", "plane_axes", "fit_open_curve", "fit_closed_curve", "closed_curve_points",
           "signed_distance_closed", "dist_to_polygon"]

CLEARLY_BETTER = 0.7  #: a higher-order curve must lower the RMS residual to <= 70 % to be taken
NOISE_FRACTION = 0.25  #: RMS below this fraction of the mean border edge is mesh zig-zag, not shape
MAX_FOURIER = 3  #: highest elliptic Fourier order tried (order 3 already follows a kidney shape)
PARAM_CORRECTIONS = 4  #: closed fits: rounds of moving each node's parameter to its nearest curve point
PARAM_SAMPLES = 1440  #: curve samples for the parameter correction (a quarter degree apart)
CURVE_SAMPLES = 512  #: samples of a closed curve as a polygon (RMS distance, simplicity test)
NEWTON_SAMPLES = 2048  #: samples for the start of the nearest-point search of the signed distance
NEWTON_STEPS = 8  #: Newton steps on (c(s) - q).c'(s) = 0 (quadratic convergence from a sample spacing away)
POLYGON_CHUNK = 4096  #: points per block in the point-to-polygon distance (bounds the memory)


def _require_finite(X: np.ndarray, what: str) -> None:
    bad = ~np.isfinite(X).reshape(len(X), -1).all(axis=1)
    if bad.any():
        raise BolusError(f"{what}: point {int(np.argmax(bad))} has a non-finite (NaN or infinite) coordinate")


def project_to_plane(P: np.ndarray, normal: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Orthogonal projection of points on a plane (eqs. 4-6..4-9).

    Parameters
    ----------
    P : (k,3) points.  normal : (3,) plane normal (any length > 0).  origin : (3,) a point of the plane.

    Returns
    -------
    (k,3) the projected points, p - ((p - origin).d) d with d = normal / |normal|.
    Raises `BolusError` for a zero or non-finite normal or non-finite points.
    """
    d = np.asarray(normal, dtype=np.float64)
    nd = np.linalg.norm(d)
    if not np.isfinite(nd) or nd == 0.0:
        raise BolusError(f"the plane normal must be a finite non-zero vector, got {d.tolist()}")
    P = np.asarray(P, dtype=np.float64)
    _require_finite(P, "project_to_plane")
    d = d / nd
    return P - np.outer((P - origin) @ d, d)


def plane_axes(Pg: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """In-plane axes of projected points.

    Parameters
    ----------
    Pg : (k,3) points on the plane with unit normal d (3,).

    Returns
    -------
    (origin (3,), e1 (3,), e2 (3,)): their centroid, the principal in-plane direction
    e1 and e2 = d x e1.
    """
    c = Pg.mean(axis=0)
    X = Pg - c
    X = X - np.outer(X @ d, d)
    _, _, Vt = np.linalg.svd(X, full_matrices=False)
    e1 = Vt[0] - np.dot(Vt[0], d) * d
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    return c, e1, e2


def fit_open_curve(x: np.ndarray, y: np.ndarray, noise: float) -> tuple[np.ndarray, int, float]:
    """Least-squares y = f(x), linear or quadratic (eq. 6-37).

    Parameters
    ----------
    x, y : (k,) in-plane coordinates of the border nodes (k >= 2), mm.
    noise : the mean border edge, mm: an RMS residual under NOISE_FRACTION of it is zig-zag.

    Returns
    -------
    (coef, order, rms): coefficients highest power first (as numpy.polyval), 1 or 2,
    and the RMS residual in mm.  The quadratic is taken only when the line's RMS is
    above the zig-zag and the parabola lowers it to CLEARLY_BETTER or less.
    Raises `BolusError` for fewer than 2 points, non-finite values, or points that all
    have the same x (coincident nodes: no line through them).
    """
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    _require_finite(np.stack([x, y], 1), "fit_open_curve")
    if len(x) < 2:
        raise BolusError("a border needs at least 2 points to fit a cut line")
    if np.ptp(x) == 0.0:
        raise BolusError(f"the {len(x)} border points to fit coincide along the border (all at x = {x[0]:.3g})")
    fits = []
    for order in (1, 2):
        if len(x) <= order:
            break
        coef = np.polyfit(x, y, order)
        rms = float(np.sqrt(np.mean((np.polyval(coef, x) - y) ** 2)))
        fits.append((coef, order, rms))
    best = fits[0]
    if len(fits) > 1 and best[2] > NOISE_FRACTION * noise and fits[1][2] <= CLEARLY_BETTER * best[2]:
        best = fits[1]
    return best


def _fourier_design(s: np.ndarray, K: int) -> np.ndarray:
    """Design matrix (k, 2K+1) [1, cos s, sin s, ..., cos Ks, sin Ks]."""
    cols = [np.ones_like(s)]
    for k in range(1, K + 1):
        cols += [np.cos(k * s), np.sin(k * s)]
    return np.stack(cols, axis=1)


def closed_curve_points(coef: np.ndarray, samples: int = CURVE_SAMPLES) -> np.ndarray:
    """Points (samples,2) of the elliptic Fourier curve with coefficients coef (2K+1, 2)."""
    K = (len(coef) - 1) // 2
    s = np.linspace(0.0, 2 * np.pi, samples, endpoint=False)
    return _fourier_design(s, K) @ coef


def _is_simple(poly: np.ndarray) -> bool:
    """True if the closed polygon (k,2) does not cross itself (all segment pairs, vectorised)."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    k = len(poly)

    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    A, B = a[:, None, :], b[:, None, :]
    C, D = a[None, :, :], b[None, :, :]
    o1, o2 = orient(A, B, C), orient(A, B, D)
    o3, o4 = orient(C, D, A), orient(C, D, B)
    cross = (o1 * o2 < 0) & (o3 * o4 < 0)
    i, j = np.triu_indices(k, 2)
    ok = ~((i == 0) & (j == k - 1))
    return not cross[i[ok], j[ok]].any()


def _fit_fourier(xy: np.ndarray, s: np.ndarray, K: int) -> np.ndarray:
    """Coefficients (2K+1,2) of order K fitted with parameter correction (orthogonal distance fitting)."""
    sk = s.copy()
    for _ in range(PARAM_CORRECTIONS + 1):
        coef, *_ = np.linalg.lstsq(_fourier_design(sk, K), xy, rcond=None)
        # parameter correction: move each node's parameter to its nearest curve point
        dense = closed_curve_points(coef, PARAM_SAMPLES)
        nearest = cKDTree(dense).query(xy)[1]
        sk = 2 * np.pi * nearest / float(PARAM_SAMPLES)
    return coef


def fit_closed_curve(xy: np.ndarray, noise: float) -> tuple[np.ndarray, int, float]:
    """Least-squares closed curve through an ordered loop (eq. 6-37).

    Parameters
    ----------
    xy : (k,2) in-plane points along the loop, mm (k >= 6).
    noise : the mean border edge, mm (see `fit_open_curve`).

    Returns
    -------
    (coef, K, rms): elliptic Fourier coefficients (2K+1,2) of order K (1 = an ellipse)
    and the RMS distance of the nodes from the curve, mm.  The parameter starts as the
    arc-length angle of the nodes; orders 2..MAX_FOURIER only when they clearly fit
    better and stay a simple curve.  Raises `BolusError` for fewer than 6 points,
    non-finite values, or a loop whose points (nearly) coincide.
    """
    xy = np.asarray(xy, dtype=np.float64)
    _require_finite(xy, "fit_closed_curve")
    closed = np.vstack([xy, xy[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    if len(xy) >= 6 and not (seg > 0).sum() >= 3:
        raise BolusError(f"the {len(xy)} points of a closed border coincide: no curve to fit")
    s = 2 * np.pi * np.r_[0.0, np.cumsum(seg)[:-1]] / max(seg.sum(), 1e-300)
    best = None
    for K in range(1, MAX_FOURIER + 1):
        if len(xy) < 2 * (2 * K + 1):
            break
        coef = _fit_fourier(xy, s, K)
        curve = closed_curve_points(coef)
        rms = float(np.sqrt(np.mean(dist_to_polygon(xy, curve) ** 2)))
        if best is None:
            best = (coef, K, rms)
            continue
        if best[2] > NOISE_FRACTION * noise and rms <= CLEARLY_BETTER * best[2] and _is_simple(curve):
            best = (coef, K, rms)
        else:
            break
    if best is None:
        raise BolusError("a closed border needs at least 6 points to fit a cut curve")
    return best


def dist_to_polygon(q: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance (k,) of points q (k,2) to the closed polygon poly (s,2)."""
    a = poly
    ab = np.roll(poly, -1, axis=0) - a
    ll = np.maximum((ab**2).sum(axis=1), 1e-300)
    out = np.empty(len(q))
    for s in range(0, len(q), POLYGON_CHUNK):
        p = q[s : s + POLYGON_CHUNK, None, :]
        t = np.clip(((p - a) * ab).sum(axis=2) / ll, 0.0, 1.0)
        d = p - (a + t[..., None] * ab)
        out[s : s + POLYGON_CHUNK] = np.sqrt((d**2).sum(axis=2).min(axis=1))
    return out


def _fourier_derivs(coef: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Curve point, first and second derivative (each (k,2)) at parameters s (k,)."""
    K = (len(coef) - 1) // 2
    c = np.tile(coef[0], (len(s), 1))
    d1 = np.zeros((len(s), 2))
    d2 = np.zeros((len(s), 2))
    for k in range(1, K + 1):
        a, b = coef[2 * k - 1], coef[2 * k]
        cs, sn = np.cos(k * s)[:, None], np.sin(k * s)[:, None]
        c += a * cs + b * sn
        d1 += k * (-a * sn + b * cs)
        d2 += -k * k * (a * cs + b * sn)
    return c, d1, d2


def signed_distance_closed(q: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """Signed distance to a closed Fourier curve, negative inside.

    Parameters
    ----------
    q : (k,2) points.  coef : (2K+1,2) curve coefficients (`fit_closed_curve`).

    Returns
    -------
    (k,) signed distances.  The nearest curve point is found on NEWTON_SAMPLES samples
    and refined by Newton's method on (c(s) - q) . c'(s) = 0, so the zero set is the
    exact curve, not a polygon of it; the sign is that of (q - c(s)) . outward normal.
    Raises `BolusError` for non-finite points or coefficients.
    """
    q = np.asarray(q, dtype=np.float64)
    _require_finite(q, "signed_distance_closed")
    _require_finite(np.asarray(coef, dtype=np.float64), "signed_distance_closed (curve coefficients)")
    grid_s = np.linspace(0.0, 2 * np.pi, NEWTON_SAMPLES, endpoint=False)
    dense = closed_curve_points(coef, NEWTON_SAMPLES)
    x, y = dense[:, 0], dense[:, 1]
    ccw = (x * np.roll(y, -1) - np.roll(x, -1) * y).sum() > 0
    s = grid_s[cKDTree(dense).query(q)[1]]
    h = 2 * np.pi / NEWTON_SAMPLES
    for _ in range(NEWTON_STEPS):
        c, d1, d2 = _fourier_derivs(coef, s)
        r = c - q
        g = (r * d1).sum(1)
        dg = (d1 * d1).sum(1) + (r * d2).sum(1)
        step = np.where(dg > 0, -g / np.where(dg > 0, dg, 1.0), 0.0)
        s = s + np.clip(step, -h, h)
    c, d1, _ = _fourier_derivs(coef, s)
    out_normal = np.stack([d1[:, 1], -d1[:, 0]], 1) * (1.0 if ccw else -1.0)
    r = q - c
    return np.sign((r * out_normal).sum(1)) * np.linalg.norm(r, axis=1)
