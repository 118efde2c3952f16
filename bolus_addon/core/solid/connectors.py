"""Pegs and holes that make the printed parts of a bolus fit together (seed 6.4.3, Figure 6-17).

Each joint (the planar common face of two neighbouring parts, `parts.split_solid`) gets two
cylinders near the two ends of the joint face: a peg on the joint's first part with its hole in
the second, and one the other way round, both parallel to one axis.  Volume work is manifold3d
(cylinders, union, difference, clipping); placement is 2D work on the joint face as a
``manifold3d.CrossSection`` (its inward offset holds the admissible peg centres).

Sizes from the wall thickness t (mm) at the joint: peg diameter PEG_DIAMETER_FRACTION (40 %) of
t, at least PEG_MIN_DIAMETER (2 mm); hole radius = peg radius + clearance (CLEARANCE, 0.2 mm);
WALL_MIN (1.5 mm) around the hole, so t >= 2 (r + c + 1.5), else the joint stays plain; peg
length 1.5 x its diameter, at least 3 mm, hole depth = length + clearance; the cylinders reach
EMBED (1 mm, `embed_length`) back into the peg's own part.  Axis: the plane normal, else tilted
into the shell's tangent (`joint_axes`, up to MAX_TILT_DEG); `fit_in_wall` centres the hole in
the wall.  Each site is checked with manifold volumes (peg inside its part and adding exactly
its protruding volume, the widened hole inside the other part, clear of earlier connectors);
a failing site is tried aside, shorter, then farther inward, else dropped with a note.

Design notes: docs/design/solid.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import manifold3d as m3

__all__ = [
    "CLEARANCE", "PEG_DIAMETER_FRACTION", "PEG_MIN_DIAMETER", "WALL_MIN", "PEG_LENGTH_FACTOR",
    "PEG_MIN_LENGTH", "EMBED", "SEGMENTS", "MAX_TILT_DEG",
    "Connector", "connector_size", "polygon_area", "plane_frame", "to_plane", "from_plane",
    "section_of_triangles", "inscribed_radius", "cylinder", "place_centres", "embed_length", "fit_in_wall",
    "add_joint_connectors",
    "joint_axes",
]

CLEARANCE = 0.2  #: mm, hole radius - peg radius and hole depth - peg length (a free, not press, fit)
PEG_DIAMETER_FRACTION = 0.4  #: peg diameter / joint thickness
PEG_MIN_DIAMETER = 2.0  #: mm: thinner pegs break off or print as blobs
WALL_MIN = 1.5  #: mm of material around a hole (and beyond its bottom)
PEG_LENGTH_FACTOR = 1.5  #: peg length / peg diameter
PEG_MIN_LENGTH = 3.0  #: mm
EMBED = 1.0  #: mm the peg cylinder reaches back into its own part (the union overlaps, never touches)
SEGMENTS = 32  #: sides of the peg and hole polygons (same angles: the clearance is even all round)
SLACK = 0.5  #: mm: peg centres sit up to this much deeper than the bare minimum when the joint allows
INSIDE_TOL = 1e-4  #: relative volume left outside a part that still counts as inside (round-off)
MAX_TILT_DEG = 60.0  #: largest angle between a peg axis and the joint plane's normal
SHIFTS = (0.5, -0.5)  #: mm: a site that fails where `fit_in_wall` puts it is tried this much either side
MAX_SHIFT = 4.0  #: mm: farthest a site moves across the joint strip to centre its hole in the wall
MARGIN = 0.1  #: mm `fit_in_wall` keeps spare on each side of the wall (the surface is curved)


@dataclass
class Connector:
    """One peg and its hole across a joint."""

    parts: tuple  #: (peg part, hole part)
    centre: np.ndarray  #: (3,) on the joint plane
    axis: np.ndarray  #: (3,) unit, from the peg part into the hole part (the plane normal)
    peg_radius: float
    hole_radius: float  #: peg_radius + clearance
    peg_length: float
    hole_depth: float  #: peg_length + clearance

    def as_dict(self) -> dict:
        return {"parts": [int(p) for p in self.parts], "centre": [float(x) for x in self.centre],
                "axis": [float(x) for x in self.axis], "peg_radius": float(self.peg_radius),
                "hole_radius": float(self.hole_radius), "peg_length": float(self.peg_length),
                "hole_depth": float(self.hole_depth)}


def connector_size(thickness: float, clearance: float = CLEARANCE) -> tuple[float, float, float]:
    """(peg radius, peg length, least joint thickness that holds it) in mm for a joint of
    ``thickness`` mm (module doc)."""
    r = max(0.5 * PEG_MIN_DIAMETER, 0.5 * PEG_DIAMETER_FRACTION * float(thickness))
    length = max(PEG_MIN_LENGTH, PEG_LENGTH_FACTOR * 2.0 * r)
    return r, length, 2.0 * (r + clearance + WALL_MIN)


def polygon_area(radius: float, segments: int = SEGMENTS) -> float:
    """Area (mm^2) of the regular ``segments``-gon of circumradius ``radius`` (a peg's section)."""
    return 0.5 * segments * radius**2 * np.sin(2.0 * np.pi / segments)


def plane_frame(normal, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """(origin (3,), U (2,3) orthonormal rows u, v with u x v = normal) of the plane
    normal . x + offset = 0 (normal (3,) unit)."""
    n = np.asarray(normal, dtype=np.float64)
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return -float(offset) * n, np.stack([u, v])


def to_plane(P, origin, U) -> np.ndarray:
    """Points P (k,3) -> plane coordinates (k,2)."""
    return (np.asarray(P, dtype=np.float64) - origin) @ U.T


def from_plane(Q, origin, U) -> np.ndarray:
    """Plane coordinates Q (k,2) -> points (k,3) on the plane."""
    return origin + np.asarray(Q, dtype=np.float64) @ U


def section_of_triangles(T) -> m3.CrossSection:
    """The region (CrossSection) covered by 2D triangles T (k,3,2) (each made counter-clockwise)."""
    T = np.asarray(T, dtype=np.float64)
    if len(T) == 0:
        return m3.CrossSection()
    e1, e2 = T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]
    cross = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    T = np.where((cross < 0)[:, None, None], T[:, ::-1], T)
    keep = np.abs(cross) > 1e-12
    return m3.CrossSection([np.ascontiguousarray(t) for t in T[keep]], m3.FillRule.NonZero)


def inscribed_radius(section: m3.CrossSection, tol: float = 0.02) -> float:
    """Radius (mm) of the largest circle inside ``section``, to ``tol`` (bisection on the
    inward offset, which is empty exactly when no such circle of that radius fits)."""
    if section.is_empty():
        return 0.0
    x0, y0, x1, y1 = section.bounds()
    lo, hi = 0.0, 0.5 * min(x1 - x0, y1 - y0) + tol
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if section.offset(-mid).is_empty():
            hi = mid
        else:
            lo = mid
    return lo


def _vertices(section: m3.CrossSection) -> np.ndarray:
    polys = section.to_polygons()
    return np.vstack(polys) if polys else np.zeros((0, 2))


def place_centres(section: m3.CrossSection, peg_radius: float, clearance: float,
                  inscribed: float | None = None) -> list[np.ndarray]:
    """Candidate peg centres in the joint face ``section`` (2D), one list per connector:
    [(t,2) array, ...] with 0, 1 or 2 entries, best candidate first.

    The admissible centres are the inward offset of the face by peg radius + clearance +
    WALL_MIN; the first candidates are its two ends (its two vertices farthest apart),
    moved up to SLACK deeper; the next ones step inward along it (2, 4, 8, 16 peg radii
    from the end), for when a hole at the end would leave its part.  One list when the
    two ends are closer than two holes and a wall, none when no centre is admissible."""
    need = peg_radius + clearance + WALL_MIN
    R = inscribed_radius(section) if inscribed is None else inscribed
    feasible = section.offset(-need)
    if feasible.is_empty():
        return []
    P = _vertices(feasible)
    deeper = section.offset(-(need + min(SLACK, 0.5 * max(R - need, 0.0))))
    Q = _vertices(deeper) if not deeper.is_empty() else P
    a = P[np.argmax(np.linalg.norm(P - P.mean(axis=0), axis=1))]
    b = P[np.argmax(np.linalg.norm(P - a, axis=1))]
    out = []
    for end in (a, b):
        d = np.linalg.norm(Q - end, axis=1)
        picks = [int(np.argmin(d))] + [int(np.argmin(np.abs(d - s * peg_radius))) for s in (2, 4, 8, 16)]
        out.append(Q[list(dict.fromkeys(picks))])
    if np.linalg.norm(out[0][0] - out[1][0]) < 2.0 * (peg_radius + clearance) + WALL_MIN:
        core = section.offset(-max(need, 0.9 * R))
        C = _vertices(core) if not core.is_empty() else P
        return [C[np.argmin(np.linalg.norm(C - C.mean(axis=0), axis=1))][None]]
    return out


def cylinder(centre, axis, radius: float, start: float, end: float, segments: int = SEGMENTS) -> m3.Manifold:
    """Cylinder of ``radius`` around the line centre + s axis, s in [start, end] (mm).  The
    polygon's corners sit at the same angles for every call with the same axis."""
    n = np.asarray(axis, dtype=np.float64)
    n = n / np.linalg.norm(n)
    _, U = plane_frame(n, 0.0)
    t = np.asarray(centre, dtype=np.float64) + start * n
    M = np.column_stack([U[0], U[1], n, t])
    return m3.Manifold.cylinder(float(end - start), float(radius), circular_segments=segments).transform(M.tolist())


def joint_axes(normal, shell_normals) -> list[np.ndarray]:
    """Peg axes to try on a joint, best first (all pegs of a joint stay parallel, so the
    parts slide together along the axis).  ``normal`` (3,): the plane's unit normal;
    ``shell_normals`` (k,3): the skin's normals at the peg sites (any sign).

    Where the plane meets the shell obliquely, a peg along the normal runs out through the
    shell's face; along the shell's tangent it stays inside the wall.  So: (1) with two
    sites whose normals differ, the direction tangent at both (s1 x s2); (2) the normal
    projected into the mean tangent plane; (3) the normal itself.  (1) and (2) only while
    they stay within MAX_TILT_DEG of the normal."""
    n = np.asarray(normal, dtype=np.float64)
    S = np.asarray(shell_normals, dtype=np.float64).reshape(-1, 3)
    S = S / np.maximum(np.linalg.norm(S, axis=1, keepdims=True), 1e-300)
    cos_max = np.cos(np.radians(MAX_TILT_DEG))
    axes = []
    if len(S) >= 2:
        a = np.cross(S[0], S[1])
        if np.linalg.norm(a) > np.sin(np.radians(10.0)):
            a /= np.linalg.norm(a)
            a = a if a @ n >= 0 else -a
            if a @ n >= cos_max:
                axes.append(a)
    if len(S):
        sbar = (S * np.where(S @ S[0] < 0, -1.0, 1.0)[:, None]).sum(axis=0)
        if np.linalg.norm(sbar) > 0:
            sbar /= np.linalg.norm(sbar)
            d = n - (n @ sbar) * sbar
            if abs(n @ sbar) >= 0.05 and np.linalg.norm(d) >= cos_max:
                axes.append(d / np.linalg.norm(d))
    axes.append(n)
    out = []
    for a in axes:
        if all(a @ b < np.cos(np.radians(1.0)) for b in out):
            out.append(a)
    return out


def _outside(A: m3.Manifold, B: m3.Manifold) -> float:
    """Volume (mm^3) of A outside B."""
    return float((A - B).volume())


def _overlap(A: m3.Manifold, others: list) -> float:
    """Volume (mm^3) of A inside any of ``others``."""
    return sum(float((A ^ B).volume()) for B in others)


def embed_length(r: float, clearance: float, cos_tilt: float) -> float:
    """How far (mm) peg and hole cylinders reach back behind the joint plane along their axis:
    EMBED, plus what a tilted axis needs for the cylinder's end to clear the plane all round."""
    cos_tilt = min(1.0, max(float(cos_tilt), 1e-3))
    return EMBED + (r + clearance + WALL_MIN) * np.sqrt(1.0 - cos_tilt**2) / cos_tilt


def _local(part: m3.Manifold, centre, half: float) -> m3.Manifold:
    """The part clipped to a cube of half-size ``half`` around ``centre`` (the checks of one
    connector then work on a few hundred triangles instead of the whole part)."""
    box = m3.Manifold.cube((2 * half, 2 * half, 2 * half), True).translate(tuple(np.asarray(centre, float)))
    out = part ^ box
    out.num_tri()  # evaluate now: manifold3d is lazy, the checks would redo the clip each time
    return out


def _try_connector(peg_part, hole_part, centre, axis, nrm, off, r, length, clearance, keep_peg, keep_hole):
    """(peg, hole, anchor, guard) or a reason string.  The plane nrm . x + off = 0 has the
    hole part on its + side; peg_part / hole_part may be clipped around the centre."""
    e = embed_length(r, clearance, float(axis @ nrm))
    peg_side, hole_side = (tuple(-nrm), float(off)), (tuple(nrm), float(-off))
    base = cylinder(centre, axis, r, -e, 0.0).trim_by_plane(*peg_side)
    if _outside(base, peg_part) > INSIDE_TOL * base.volume():
        return "the peg's base is not inside its part"
    guard = cylinder(centre, axis, r + clearance + WALL_MIN, -e,
                     length + clearance + WALL_MIN).trim_by_plane(*hole_side)
    if _outside(guard, hole_part) > INSIDE_TOL * guard.volume():
        return "the hole and its wall would not stay inside the other part"
    anchor = cylinder(centre, axis, r + WALL_MIN, -e, 0.0).trim_by_plane(*peg_side)
    if _overlap(guard, keep_hole) > INSIDE_TOL * guard.volume() or \
            _overlap(anchor, keep_peg) > INSIDE_TOL * anchor.volume():
        return "it would run into another connector"
    peg = cylinder(centre, axis, r, -e, length)
    added = (peg_part + peg).volume() - peg_part.volume()
    if abs(added - polygon_area(r) * length) > INSIDE_TOL * peg.volume() + 1e-6:
        return "the peg would run into its own part"
    return peg, cylinder(centre, axis, r + clearance, -e, length + clearance), anchor, guard


def _lengths(length: float) -> list[float]:
    return list(dict.fromkeys(max(PEG_MIN_LENGTH, f * length) for f in (1.0, 0.75, 0.5)))


def fit_in_wall(axis, normal, s, h0: float, t: float, r: float, clearance: float, length: float):
    """Where across the wall and how long a connector fits, from the local wall alone.

    Locally the shell is a slab 0 <= (x - x_inner) . s <= t (s (3,) unit into the material,
    t the wall thickness), the centre sits at height h0.  Along ``axis`` the hole (with its
    wall, radius r + clearance + WALL_MIN, to depth length + clearance + WALL_MIN) and the
    peg's base drift across the slab by axis . s per mm.  Returns (shift, L, u): the centre
    moved by ``shift`` along u (unit, in the plane) puts that range in the middle of the
    wall with the longest L of `_lengths` that fits (MARGIN to spare each side), or None."""
    axis, normal, s = (np.asarray(v, dtype=np.float64) for v in (axis, normal, s))
    cs = float(axis @ s)
    sn = float(np.sqrt(max(0.0, 1.0 - cs**2)))
    e = embed_length(r, clearance, float(axis @ normal))
    rho = r + clearance + WALL_MIN
    u = s - (s @ normal) * normal
    g = float(np.linalg.norm(u))
    for L in _lengths(length):
        D = L + clearance + WALL_MIN
        lo = min(min(0.0, D * cs) - rho * sn, min(-e * cs, 0.0) - r * sn)
        hi = max(max(0.0, D * cs) + rho * sn, max(-e * cs, 0.0) + r * sn)
        if hi - lo <= t - 2.0 * MARGIN:
            h = 0.5 * (t - (hi - lo)) - lo
            if g < 0.2:  # the plane nearly parallel to the wall: shifting in it does not move across
                return 0.0, L, normal * 0.0
            return (h - h0) / g, L, u / g
    return None


def add_joint_connectors(parts: list, pair: tuple, plane, axis, candidates: list, r: float, length: float,
                         clearance: float = CLEARANCE, ids: set | None = None, keepout: dict | None = None,
                         wall=None):
    """Put pegs and holes on the joint of parts ``pair`` = (i, j), on the plane
    ``plane`` = (normal (3,) unit from i into j, offset).  ``axis`` (3,) unit, axis . normal
    > 0: the direction every peg of the joint points (parallel, so the parts slide together).
    ``candidates``: one (t,3) array of centres on the plane per connector, tried in order;
    ``wall``: None or a callable site (3,) -> (s (3,) unit into the material, height of the
    site above the inner face, wall thickness) used by `fit_in_wall` to move each site
    across the joint strip and choose the length (where the plane meets the shell
    obliquely, a hole centred in the wall at the plane leaves it deeper in); then SHIFTS mm
    either side.  ``parts``: list of ``manifold3d.Manifold``, updated in place.  Connector
    c (0, 1) has its peg on pair[c % 2], its hole in the other.  ``ids`` collects the
    original ids of the cylinders (the faces they leave are connector faces); ``keepout``
    {part: [Manifold]} the space each part's earlier connectors need (holes with their
    walls, peg bases), updated.  Returns (connectors, notes).

    A peg adds exactly polygon_area(r) * length to its part and its hole removes
    polygon_area(r + clearance) * (length + clearance) from the other (the plane passes
    through the axis point and the polygon is centrally symmetric, so a tilted axis
    changes neither)."""
    normal = np.asarray(plane[0], dtype=np.float64)
    offset = float(plane[1])
    axis = np.asarray(axis, dtype=np.float64)
    keepout = {} if keepout is None else keepout
    done, notes = [], []
    e = embed_length(r, clearance, float(axis @ normal))
    for c, cand in enumerate(candidates):
        sgn = 1.0 if c % 2 == 0 else -1.0
        p, h = (pair[0], pair[1]) if c % 2 == 0 else (pair[1], pair[0])
        cand = np.asarray(cand, dtype=np.float64).reshape(-1, 3)
        made, reason = None, "it would sit too close to the other connector"
        for x0 in cand:
            trials = [(x0, L) for L in _lengths(length)]
            if wall is not None:
                s, h0, t = wall(x0)
                fit = fit_in_wall(sgn * axis, sgn * normal, s, h0, t, r, clearance, length)
                if fit is None:
                    reason = f"the wall ({t:.1f} mm) is too thin for it across the joint"
                    continue
                dlt, L, u = fit
                if abs(dlt) > MAX_SHIFT:
                    reason = "it would have to move too far across the joint"
                    continue
                x1 = x0 + dlt * u
                trials = [(x1, L)] + [(x1 + d * u, L) for d in SHIFTS] + [(x1, l) for l in _lengths(length) if l < L]
            half = max(r + clearance + WALL_MIN + MAX_SHIFT + max(SHIFTS), length + clearance + WALL_MIN + e) + 0.5
            P_loc, H_loc = _local(parts[p], x0, half), _local(parts[h], x0, half)
            for x, L in trials:
                if any(np.linalg.norm(x - d.centre) < 2.0 * (r + clearance) + WALL_MIN for d in done):
                    continue
                out = _try_connector(P_loc, H_loc, x, sgn * axis, sgn * normal, sgn * offset, r, L,
                                     clearance, keepout.get(p, []), keepout.get(h, []))
                if isinstance(out, str):
                    reason = out
                    continue
                peg, hole, anchor, guard = out
                parts[p], parts[h] = parts[p] + peg, parts[h] - hole
                keepout.setdefault(p, []).append(anchor)
                keepout.setdefault(h, []).append(guard)
                if ids is not None:
                    for cyl in (peg, hole):
                        ids.update(int(i) for i in np.asarray(cyl.to_mesh64().run_original_id))
                made = Connector((int(p), int(h)), x.copy(), sgn * axis, float(r), float(r + clearance),
                                 float(L), float(L + clearance))
                break
            if made is not None:
                break
        if made is None:
            x = cand[0]
            notes.append(f"connector near ({x[0]:.1f}, {x[1]:.1f}, {x[2]:.1f}) mm left out: {reason}")
        else:
            done.append(made)
    return done, notes
