"""Where a piece's label goes: the point inside the flat piece where a text block fits best.

`label_place` takes the piece (UV (n,2) mm, F (m,3)), its cut loops [(k,2)] mm (outer loop
first, counter-clockwise; holes clockwise) and the text block's width x height (mm), and
returns the block's centre (2,) mm and the scale (<= 1) it is drawn at: candidates are grid
points and triangle centroids inside the outline, scored by the free room left and right,
above and below them, the one nearest the outer loop's centroid among the best taken.
Used by `drawing.pattern_drawing`.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .polygon_offset import winding_numbers

__all__ = ["label_place"]

#: a label never shrinks below this share of its size to fit a small piece
LABEL_MIN_SCALE = 0.4
#: label candidates: a LABEL_GRID x LABEL_GRID grid over the piece, and at most this many centroids
LABEL_GRID, LABEL_CENTROIDS = 40, 2000
#: the outline is sampled this finely (a share of its length) to measure the room around a label
OUTLINE_SAMPLES = 5000
#: label candidates kept: this many farthest from the outline and as many near the centre and roomy
LABEL_KEEP = 60
#: a label fills at most this share of the free room around it
LABEL_FILL = 0.9


def _centroid(P: np.ndarray) -> np.ndarray:
    """Area centroid (2,) of the closed polygon P (k,2) (its mean for a polygon without area)."""
    X = P - P.mean(axis=0)
    cr = X[:, 0] * np.roll(X[:, 1], -1) - np.roll(X[:, 0], -1) * X[:, 1]
    a = cr.sum() / 2
    if abs(a) <= 1e-12:
        return P.mean(axis=0)
    return P.mean(axis=0) + ((X + np.roll(X, -1, axis=0)) * cr[:, None]).sum(0) / (6 * a)


def _label_candidates(UV, F, A, B, centre):
    """Points (c,2) inside the piece where a label may go (grid points and triangle centroids,
    the most roomy and the nearest the centre kept), with their distances to the centre (c,)."""
    lo, hi = A.min(axis=0), A.max(axis=0)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], LABEL_GRID + 2)[1:-1],
                         np.linspace(lo[1], hi[1], LABEL_GRID + 2)[1:-1])
    grid_pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    grid_pts = grid_pts[winding_numbers(grid_pts, A, B) == 1]
    cand = np.concatenate([UV[F].mean(axis=1)[:: max(1, len(F) // LABEL_CENTROIDS)], grid_pts])
    length = np.linalg.norm(B - A, axis=1)
    step = max(length.sum() / OUTLINE_SAMPLES, 1e-6)
    k = np.maximum(1, np.ceil(length / step).astype(np.int64))
    seg = np.repeat(np.arange(len(A)), k)
    t = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) / np.repeat(k, k)
    dist = cKDTree(A[seg] + t[:, None] * (B - A)[seg]).query(cand)[0]
    off = np.linalg.norm(cand - centre, axis=1)
    pick = np.unique(np.concatenate([np.argsort(-dist)[:LABEL_KEEP], np.argsort(off - 3 * dist)[:LABEL_KEEP]]))
    return cand[pick], off[pick]


def _free_room(cand, A, B, axis: int) -> np.ndarray:
    """(c,) free length through each candidate (c,2) along ``axis``, centred on it, inside the outline A -> B."""
    o = 1 - axis
    lo_, hi_ = np.minimum(A[:, o], B[:, o]), np.maximum(A[:, o], B[:, o])
    q = cand[:, None, :]
    hit = (lo_ <= q[..., o]) & (hi_ > q[..., o])
    with np.errstate(divide="ignore", invalid="ignore"):
        x = A[:, axis] + (q[..., o] - A[:, o]) / (B[:, o] - A[:, o]) * (B[:, axis] - A[:, axis])
    rel = np.where(hit, x - q[..., axis], np.nan)
    before = np.nanmin(np.where(rel < 0, -rel, np.inf), axis=1)
    after = np.nanmin(np.where(rel > 0, rel, np.inf), axis=1)
    return 2 * np.minimum(before, after)


def label_place(UV: np.ndarray, F: np.ndarray, loops: list[np.ndarray], text_w: float, text_h: float,
                obstacles: list[np.ndarray] = ()):
    """Where to put a text block of text_w x text_h mm on the island: ``(point (2,), scale)``.

    Among the candidates where the text fits best (scale 1 if it fits, else shrunk to
    the room left and right, above and below the point, never below `LABEL_MIN_SCALE`)
    the one nearest the outer loop's centroid is taken.  ``obstacles``: clockwise loops
    (k,2) the text keeps out of, like holes (the marks' numbers).
    """
    A = np.concatenate(list(loops) + list(obstacles))
    B = np.concatenate([np.roll(L, -1, axis=0) for L in list(loops) + list(obstacles)])
    cand, off = _label_candidates(UV, F, A, B, _centroid(loops[0]))
    if len(obstacles):
        free = winding_numbers(cand, A, B) == 1
        if not free.any():
            return label_place(UV, F, loops, text_w, text_h)
        cand, off = cand[free], off[free]
    fit = np.minimum(1.0, np.minimum(LABEL_FILL * _free_room(cand, A, B, 0) / max(text_w, 1e-9),
                                     LABEL_FILL * _free_room(cand, A, B, 1) / max(text_h, 1e-9)))
    best = np.flatnonzero(fit >= fit.max() * (1 - 1e-9))
    i = best[np.argmin(off[best])]
    return cand[i], float(np.clip(fit[i], LABEL_MIN_SCALE, 1.0))
