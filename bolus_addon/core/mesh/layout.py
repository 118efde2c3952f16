"""Laying flat islands out on the sheet: side by side, no overlap, a gap in mm.

`orient_island` turns an island (rigidly, no mirroring) so that its minimum-area
bounding rectangle is axis-aligned with the long side along x (rotating calipers:
the optimal rectangle has a side on an edge of the convex hull, so only the hull
edge directions are tried).  `pack_islands` orients every island and places the
bounding boxes on shelves ("first fit, decreasing height"): islands sorted by height,
each put into the first row with room left, rows stacked upwards from the origin.
Only rotations and translations are applied, so every distance is kept.

`plate_layout` lays 3D print parts on the build plate the same way: each part turned
to its build direction, its footprint (x, y) packed by `pack_transforms` (so the part
also turns about +Z, which keeps its build direction), lifted to rest on z = 0.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ..errors import BolusError

__all__ = ["orient_island", "pack_islands", "pack_transforms", "plate_layout", "centre_on_plate", "rotate"]


def _as_island(UV, what="an island") -> np.ndarray:
    UV = np.asarray(UV, dtype=np.float64)
    if UV.ndim != 2 or UV.shape[1] != 2:
        raise BolusError(f"{what} must be an (n, 2) array of positions, got shape {UV.shape}")
    if len(UV) == 0:
        raise BolusError(f"{what} has no vertices")
    if not np.all(np.isfinite(UV)):
        raise BolusError(f"{what} has non-finite (NaN or infinite) coordinates")
    return UV


def rotate(UV: np.ndarray, angle: float) -> np.ndarray:
    """UV (n,2) turned counter-clockwise by ``angle`` (radians) about the origin -> (n,2)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.asarray(UV, dtype=np.float64) @ np.array([[c, s], [-s, c]])


def _hull_points(UV: np.ndarray) -> np.ndarray | None:
    """Convex hull vertices (h,2), or None when the points are (nearly) collinear."""
    if len(UV) < 3:
        return None
    try:
        hull = ConvexHull(UV)
    except QhullError:
        return None
    return UV[hull.vertices]


def orient_island(UV) -> tuple[np.ndarray, float]:
    """Rotate UV (n,2) so its minimum-area bounding rectangle is axis-aligned, long side along x.

    Returns ``(UV_rotated (n,2), angle)``: ``UV_rotated == rotate(UV, angle)``, a
    counter-clockwise rotation about the origin by ``angle`` in (-pi, pi] radians.
    Among equally good rectangles the smallest turn is taken; points on a line are laid
    along x.
    """
    UV = _as_island(UV)
    H = _hull_points(UV)
    if H is None:  # a point or a segment: lay its main direction along x
        X = UV - UV.mean(axis=0)
        if not np.any(X):
            return UV.copy(), 0.0
        direction = np.linalg.svd(X, full_matrices=False)[2][0]
        theta = np.arctan2(direction[1], direction[0])
        candidates = np.array([(theta + np.pi / 4) % (np.pi / 2) - np.pi / 4])
    else:
        E = np.roll(H, -1, axis=0) - H
        theta = np.arctan2(E[:, 1], E[:, 0])
        # a rectangle repeats every quarter turn: keep hull directions in [-pi/4, pi/4)
        candidates = np.unique((theta + np.pi / 4) % (np.pi / 2) - np.pi / 4)
        H = H - H.mean(axis=0)
        c, s = np.cos(-candidates), np.sin(-candidates)
        x = H[None, :, 0] * c[:, None] - H[None, :, 1] * s[:, None]  # (c, h)
        y = H[None, :, 0] * s[:, None] + H[None, :, 1] * c[:, None]
        area = np.ptp(x, axis=1) * np.ptp(y, axis=1)
        best = area <= area.min() * (1 + 1e-9) + 1e-300
        candidates = candidates[best]
        candidates = candidates[[np.argmin(np.abs(candidates))]]
    angle = -float(candidates[0])
    out = rotate(UV, angle)
    if np.ptp(out[:, 1]) > np.ptp(out[:, 0]) * (1 + 1e-12):
        angle = angle + np.pi / 2 if angle <= 0 else angle - np.pi / 2
        out = rotate(UV, angle)
    return out, angle


def _plan(islands, gap_mm, max_row_width_mm):
    """Oriented islands, their bbox minima (k,2) and the placed bbox corners (k,2)."""
    if gap_mm is None or not np.isfinite(gap_mm) or gap_mm < 0:
        raise BolusError(f"the gap between islands must be a finite length >= 0 mm, got {gap_mm}")
    if max_row_width_mm is not None and (not np.isfinite(max_row_width_mm) or max_row_width_mm <= 0):
        raise BolusError(f"the row width must be a positive length in mm, got {max_row_width_mm}")
    oriented = [orient_island(_as_island(UV, f"island {i}")) for i, UV in enumerate(islands)]
    if not oriented:
        return [], np.zeros((0, 2)), np.zeros((0, 2))
    lo = np.array([o[0].min(axis=0) for o in oriented])
    size = np.array([o[0].max(axis=0) for o in oriented]) - lo
    w, h = size[:, 0], size[:, 1]
    row_width = max(1.5 * np.sqrt(np.sum(w * h)), w.max()) if max_row_width_mm is None else float(max_row_width_mm)
    row_width = max(row_width, w.max())
    order = np.lexsort((np.arange(len(h)), -h))  # tallest first, ties in input order
    rows = []  # [x of the next island, y of the row, height of the row]
    corner = np.zeros((len(h), 2))
    for i in order:
        for row in rows:
            if row[0] + w[i] <= row_width * (1 + 1e-12):
                break
        else:
            y = rows[-1][1] + rows[-1][2] + gap_mm if rows else 0.0
            row = [0.0, y, h[i]]
            rows.append(row)
        corner[i] = row[0], row[1]
        row[0] += w[i] + gap_mm
    return oriented, lo, corner


def pack_islands(islands, gap_mm: float = 10.0, max_row_width_mm: float | None = None) -> list[np.ndarray]:
    """Orient and place islands [(n_i,2)] on rows -> moved islands [(n_i,2)], input order.

    Bounding boxes are at least ``gap_mm`` apart; the lowest and leftmost coordinates
    are 0 (origin at the bottom-left), all are >= 0.  The row width is
    ``max_row_width_mm`` or about 1.5 sqrt(sum of bounding-box areas), never less than
    the widest island.  Each island moves rigidly (rotation and translation).
    """
    oriented, lo, corner = _plan(islands, gap_mm, max_row_width_mm)
    return [(o[0] - lo[i]) + corner[i] for i, o in enumerate(oriented)]


def pack_transforms(islands, gap_mm: float = 10.0,
                    max_row_width_mm: float | None = None) -> list[tuple[float, np.ndarray]]:
    """The rigid motions of `pack_islands`: per island ``(angle, t (2,))``.

    ``rotate(UV, angle) + t`` equals the packed island up to float rounding, so the same
    motion can be applied to anything drawn on the island.
    """
    oriented, lo, corner = _plan(islands, gap_mm, max_row_width_mm)
    return [(o[1], corner[i] - lo[i]) for i, o in enumerate(oriented)]


def plate_layout(parts, rotations, gap_mm: float = 10.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Lay print parts side by side on the plate: per part ``(R (3,3), t (3,))``.

    parts [(n_i,3)] vertices in mm; rotations [(3,3)] each taking the part's build
    direction to +Z.  The placed part is ``V_i @ R.T + t``: R is the given rotation
    followed by a turn about +Z (the packing of the footprints, `pack_transforms`, with
    bounding boxes ``gap_mm`` apart), and t rests the part on z = 0.
    """
    parts = [np.asarray(V, dtype=np.float64) for V in parts]
    rotations = [np.asarray(R, dtype=np.float64) for R in rotations]
    if len(parts) != len(rotations):
        raise BolusError(f"{len(parts)} parts but {len(rotations)} rotations")
    for i, (V, R) in enumerate(zip(parts, rotations)):
        if V.ndim != 2 or V.shape[1] != 3:
            raise BolusError(f"part {i} must be an (n, 3) array of positions, got shape {V.shape}")
        _as_island(V[:, :2], f"part {i}")  # non-empty and finite
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) <= 0:
            raise BolusError(f"the rotation of part {i} is not a proper 3x3 rotation")
    turned = [V @ R.T for V, R in zip(parts, rotations)]
    out = []
    for W, R, (angle, t2) in zip(turned, rotations, pack_transforms([W[:, :2] for W in turned], gap_mm)):
        c, s = np.cos(angle), np.sin(angle)
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # rotate(UV, angle) as a 3D turn about +Z
        out.append((Rz @ R, np.array([t2[0], t2[1], -W[:, 2].min()])))
    return out


def centre_on_plate(W) -> np.ndarray:
    """The shift (3,) that puts the points W (n,3) at the origin of the plate: the centre of
    their (x, y) bounding box on the origin and their lowest point on z = 0 (as a slicer
    expects an STL); zeros for no points."""
    W = np.asarray(W, dtype=np.float64)
    if W.ndim != 2 or W.shape[1] != 3:
        raise BolusError(f"points must be an (n, 3) array, got shape {W.shape}")
    if len(W) == 0:
        return np.zeros(3)
    if not np.isfinite(W).all():
        raise BolusError("the part has non-finite (NaN or infinite) coordinates")
    lo, hi = W.min(axis=0), W.max(axis=0)
    return np.array([-(lo[0] + hi[0]) / 2.0, -(lo[1] + hi[1]) / 2.0, -lo[2]])
