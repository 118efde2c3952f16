"""A closed solid's exact sections at the CT's slice planes (manifold3d), and decimal strings.

The solid (V (n,3) LPS mm, F (m,3), outward) is moved into the slice frame (x along the rows,
y along the columns, z = position along the slice normal), so that every slice is the plane
z = its position; `Manifold.slice` gives the section there as polygons (outer boundaries and
holes: a planning system reads nested contours even-odd).  Each polygon's points are put back
into LPS with z exactly the slice's position, so they lie on the slice's plane to rounding.
Pieces that touch along a face (a bolus split into print parts, reassembled in place) come out
of the slice as polygons side by side, or one with slits of no width between them (rounding):
each section is closed by `SLIT_MM` (offset out by half of it, then in, corners mitred up to
`MITER_LIMIT`), which merges them, fills the slits and moves nothing wider; a polygon still narrower than that on
average (twice its area over its perimeter) is left out.
"""
from __future__ import annotations

import manifold3d as m3
import numpy as np

from ..solid.manifold import to_manifold
from .series import CTVolume

__all__ = ["slice_sections", "decimal_strings", "MIN_POINTS", "SLIT_MM", "DS_DECIMALS"]

#: a contour needs at least this many points
MIN_POINTS = 3
#: mm: a polygon whose mean width (2 area / perimeter) is below this is a slit between touching
#: pieces (measured on a split chest bolus: 1e-6 mm; the parts' peg clearance rings are 0.2 mm)
SLIT_MM = 0.01
#: miters up to this many offsets long: out and back in, a corner of 0.12 degree or more comes back
#: where it was (Clipper's default of 2 squares such a corner off and adds a vertex there)
MITER_LIMIT = 1000.0
#: decimals of a coordinate in mm: 1e-6 mm, and at most 16 characters below 1e8 mm
DS_DECIMALS = 6


def slice_sections(vol: CTVolume, V: np.ndarray, F: np.ndarray, what: str = "the solid",
                   progress=None) -> list[list[np.ndarray]]:
    """For each slice k of ``vol`` the section's polygons, each (p,3) LPS mm with p >= 3 (a
    slice the solid does not reach has none)."""
    A = vol.to_slice_frame()
    Vs = np.asarray(V, dtype=np.float64) @ A[:3, :3].T + A[:3, 3]
    M = to_manifold(Vs, F, what)
    lo, hi = Vs[:, 2].min(), Vs[:, 2].max()
    d0 = vol.positions[0]
    out = []
    for k, z in enumerate(vol.positions):
        polys = []
        if lo <= z <= hi:
            cs = M.slice(float(z))
            cs = (cs.offset(0.5 * SLIT_MM, m3.JoinType.Miter, MITER_LIMIT)
                  .offset(-0.5 * SLIT_MM, m3.JoinType.Miter, MITER_LIMIT))
            for poly in cs.to_polygons():
                xy = np.asarray(poly, dtype=np.float64)
                if len(xy) < MIN_POINTS or _mean_width(xy) < SLIT_MM:
                    continue
                P = (vol.origin + xy[:, :1] * vol.row_cos + xy[:, 1:2] * vol.col_cos
                     + (float(z) - d0) * vol.normal)
                polys.append(P)
        out.append(polys)
        if progress is not None and k % 16 == 0:
            progress((k + 1) / len(vol.positions), "sections at the CT slices")
    return out


def _mean_width(xy: np.ndarray) -> float:
    """2 |area| / perimeter of the closed polygon xy (p,2) (mm): its width where it is a strip."""
    x, y = xy[:, 0], xy[:, 1]
    area = 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))
    perimeter = float(np.linalg.norm(xy - np.roll(xy, -1, axis=0), axis=1).sum())
    return 2.0 * area / perimeter if perimeter > 0 else 0.0


def decimal_strings(values: np.ndarray, decimals: int = DS_DECIMALS) -> list[str]:
    """DICOM decimal strings (DS, <= 16 characters) of ``values`` (mm) at ``decimals`` places,
    trailing zeros dropped."""
    vals = np.asarray(values, dtype=np.float64).ravel()
    if vals.size and np.abs(vals).max() >= 10.0 ** (14 - decimals):
        raise ValueError("a coordinate too large for a 16-character decimal string")
    out = []
    for v in vals:
        s = f"{v:.{decimals}f}".rstrip("0").rstrip(".")
        out.append("0" if s in ("-0", "") else s)
    return out
