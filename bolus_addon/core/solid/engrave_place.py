"""Where a line of text fits on the outer face of a solid (core/engrave.py places, bends and cuts it).

A spot is used only when the text's box plus a margin lies entirely on the outer face
(no rim, cut or connector face under it, the face tilted at most ``MAX_TILT_DEG`` from n0)
and the wall under the letters is at least twice the depth (ray casts); otherwise the
solid comes back unchanged with a note giving the figures.  The x stretch of the letters
on a curved face is at most 1 / cos(tilt) (the outline is projected along n0).

Placement.  Spots are points sampled every SPOT_SPACING_MM on the outer face.  A label goes to
the spot farthest from the rim / cut / connector faces (then the nearest to the middle), a marker
to the spot farthest towards the patient's left ("L") or right ("R") that still has room; up to
MAX_TRIES spots, spread over the face, are tried.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .engrave_surface import SPOT_SPACING_MM, _Surface, _thin_out, _unit
from .manifold import SIDE_NAMES, SIDE_OUTER, ray_thickness

#: steepest tilt of the outer face under the text against the normal at its centre (degrees)
MAX_TILT_DEG = 40.0
#: margin around the text's box that must lie on the outer face: max(MARGIN_MM, MARGIN_REL * height)
MARGIN_MM, MARGIN_REL = 1.0, 0.2
#: the wall under the letters must be at least this many times the depth
WALL_FACTOR = 2.0
#: spots tried per text and orientation
MAX_TRIES = 12


@dataclass
class _Spot:
    p: np.ndarray       # (3,) centre of the text on the surface
    r: np.ndarray       # (3,) text x axis
    u: np.ndarray       # (3,) text y axis (up)
    n: np.ndarray       # (3,) outward normal at p
    height: float       # cap height, mm
    centre: np.ndarray  # (2,) centre of the text's box in text units x height
    footprint: np.ndarray  # (s,3) surface points under the box and margin
    reach: float        # how far above / below the tangent plane the face was looked for


class _NoFit(Exception):
    pass


def _text_box(text):
    """(lo, hi) (2,) of the outlines of ``text`` (a `TextOutline`), at cap height 1."""
    P = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in text.polygons])
    return P.min(axis=0), P.max(axis=0)


def _fit(surf: _Surface, p, n0, up, text, height, depth, taken=()):
    """Place ``text`` at p with up ``up`` (unit, normal to n0) clear of the footprints ``taken``
    of text placed before: a `_Spot`, or raise _NoFit(note)."""
    r = np.cross(up, n0)
    lo, hi = _text_box(text)
    lo, hi = lo * height, hi * height
    margin = max(MARGIN_MM, MARGIN_REL * height)
    half = 0.5 * (hi - lo) + margin
    size = f"{hi[0] - lo[0]:.1f} x {hi[1] - lo[1]:.1f} mm with a {margin:.1f} mm margin"
    # the box and its margin, sampled every `step` mm in the tangent plane, seen along n0
    step = min(0.5, height / 8.0)
    xs = np.linspace(-half[0], half[0], int(np.ceil(2 * half[0] / step)) + 1)
    ys = np.linspace(-half[1], half[1], int(np.ceil(2 * half[1] / step)) + 1)
    gx, gy = (g.ravel() for g in np.meshgrid(xs, ys, indexing="ij"))
    reach = float(np.hypot(*half)) + 2.0  # the face tilts at most MAX_TILT_DEG < 45 degrees
    face, X, bary = surf.project(p, n0, p + gx[:, None] * r + gy[:, None] * up, reach)
    problem = _coverage_problem(surf, face, n0)
    if problem is None:
        # heights along n0 must run on without a jump (else a fold or an overhang hides the face)
        H = ((X - p) @ n0).reshape(len(xs), len(ys))
        jump = max(np.abs(np.diff(H, axis=0)).max(initial=0.0), np.abs(np.diff(H, axis=1)).max(initial=0.0))
        if jump > step * np.tan(np.radians(MAX_TILT_DEG)) * 1.5 + 0.05:
            problem = f"the face under it is partly hidden by a fold or an overhang (a step of {jump:.1f} mm)"
        elif len(taken) and np.min(cKDTree(np.concatenate(taken)).query(X)[0]) < step:
            problem = "it would overlap text placed before"
    if problem is not None:
        raise _NoFit(f"the text's box ({size}) does not fit: {problem}")
    inner = (np.abs(gx) <= half[0] - margin + 1e-9) & (np.abs(gy) <= half[1] - margin + 1e-9)
    _check_wall(surf, face[inner], bary[inner], X[inner], depth)
    return _Spot(p=p, r=r, u=up, n=n0, height=height, centre=0.5 * (lo + hi), footprint=X, reach=reach)


def _coverage_problem(surf: _Surface, face, n0):
    """None when every sample (faces (k,), -1 for none) lies on the outer face tilted at most
    MAX_TILT_DEG from n0, else what is wrong (shares of the samples)."""
    hit = face >= 0
    fside = np.where(hit, surf.side[np.maximum(face, 0)], -1)
    tilt_ok = np.where(hit, surf.fn[np.maximum(face, 0)] @ n0, -1.0) >= np.cos(np.radians(MAX_TILT_DEG))
    if np.all(hit & (fside == SIDE_OUTER) & tilt_ok):
        return None
    off = 100.0 * np.mean(~hit | (fside != SIDE_OUTER))
    steep = 100.0 * np.mean(hit & (fside == SIDE_OUTER) & ~tilt_ok)
    parts = []
    if off > 0:
        named = sorted({SIDE_NAMES.get(int(x), str(x)) for x in np.unique(fside[hit & (fside != SIDE_OUTER)])})
        where = " or ".join(["past its edge"] * bool(np.any(~hit)) + [f"over {x} faces" for x in named])
        parts.append(f"{_percent(off)} of it lies off the outer face ({where})")
    if steep > 0:
        parts.append(f"{_percent(steep)} of it lies where the face tilts more than {MAX_TILT_DEG:.0f} degrees")
    return "; ".join(parts)


def _check_wall(surf: _Surface, face, bary, X, depth):
    """Raise _NoFit when the wall under the surface points X (k,3) (on faces / bary) is thinner than
    WALL_FACTOR x depth (ray casts inward along the smooth normal, at most 400 of them)."""
    pick = np.arange(0, len(X), max(1, len(X) // 400))
    N, _ = surf.normal_at(face[pick], bary[pick])
    wall = ray_thickness(surf.V, surf.F, X[pick], -N, max_mm=WALL_FACTOR * depth * 4)
    if len(wall) and wall.min() < WALL_FACTOR * depth:
        i = int(np.argmin(wall))
        raise _NoFit(f"the wall under the text is only {wall[i]:.2f} mm thick at ({_xyz(X[pick][i])}) mm "
                     f"(at least {WALL_FACTOR:g} x the depth = {WALL_FACTOR * depth:.2f} mm is needed)")


def _percent(x) -> str:
    return f"{x:.0f} %" if x >= 1 else "under 1 %"


def _xyz(v) -> str:
    return ", ".join(f"{float(x):.1f}" for x in v)


def _candidates(surf: _Surface, order_key, spread):
    """Up to MAX_TRIES spots (indices into surf.spots), best (smallest key) first, at least
    ``spread`` mm apart."""
    alive = np.isfinite(order_key)
    chosen = []
    while alive.any() and len(chosen) < MAX_TRIES:
        i = int(np.argmin(np.where(alive, order_key, np.inf)))
        chosen.append(i)
        alive &= np.linalg.norm(surf.spots - surf.spots[i], axis=1) >= spread
    return chosen


def _clearance(surf: _Surface, taken):
    """Distance (s,) of each spot to the rim / cut / connector faces and to text placed before."""
    pts = np.concatenate([surf.bounds] + [t[_thin_out(t, SPOT_SPACING_MM)] for t in taken])
    if len(pts) == 0:
        return np.full(len(surf.spots), np.inf)
    return cKDTree(pts).query(surf.spots)[0]


def _roomiest_first(surf: _Surface, clearance):
    """Order key (s,) of the spots with ``clearance`` (s,): the farthest from the rim / cut faces
    (and text placed before) first, in 0.5 mm steps, then the nearest to the middle of the outer face."""
    mid = np.linalg.norm(surf.spots - surf.spots.mean(axis=0), axis=1) if len(surf.spots) else np.zeros(0)
    if not np.isfinite(clearance).any():  # no rim at all
        return mid
    return -np.floor(clearance / 0.5) + 1e-6 * mid


def _default_up(surf: _Surface, n0):
    """The solid's longest extent projected on the tangent plane (turned to +z when it has a z
    part), or the next axis when the longest one is along n0."""
    for a in surf.axes:
        t = a - (a @ n0) * n0
        if np.linalg.norm(t) > 0.3:
            t = _unit(t)
            k = 2 if abs(t[2]) > 1e-6 else int(np.argmax(np.abs(t)))
            return t if t[k] > 0 else -t
    return _unit(np.cross(n0, [1.0, 0.0, 0.0] if abs(n0[0]) < 0.9 else [0.0, 1.0, 0.0]))


def _place(surf, text, height, depth, key, clearance, up_of, taken):
    """The first spot (of up to MAX_TRIES in the order of ``key`` (s,), with ``clearance`` (s,) from
    `_clearance`) where ``text`` fits: a `_Spot`, or raise _NoFit naming what was in the way at the
    best spot."""
    lo, hi = _text_box(text)
    margin = max(MARGIN_MM, MARGIN_REL * height)
    need = 0.5 * (hi[1] - lo[1]) * height + margin  # half the height of the box: less cannot fit
    key = np.where(clearance >= need, key, np.inf)
    # spots at least half the text's width apart: a long label tries the whole face, not one hump
    cand = _candidates(surf, key, spread=max(2.0, height, 0.5 * (hi[0] - lo[0]) * height))
    if not cand:
        best = float(clearance.max(initial=0.0))
        raise _NoFit(f"no spot on the outer face is {need:.1f} mm from the rim / cut faces "
                     f"(the roomiest has {best:.1f} mm), too small for {height:g} mm letters")
    first_note = None
    for i in cand:
        N, _ = surf.normal_at(surf.spot_face[i:i + 1], surf.spot_bary[i:i + 1])
        n0, p = N[0], surf.spots[i]
        up = up_of(p, n0)
        try:
            return _fit(surf, p, n0, up, text, height, depth, taken)
        except _NoFit as e:
            if first_note is None:
                first_note = f"at ({_xyz(p)}) mm, {clearance[i]:.1f} mm from the rim / cut faces, {e}"
    raise _NoFit(first_note + f" (and at {len(cand) - 1} other spots)" * (len(cand) > 1))

