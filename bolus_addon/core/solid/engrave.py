"""Engraved text on a bolus solid: the label, the part numbers and the L / R markers.

Method.  A line of text (2D outlines at cap height 1, `TextOutline`) is placed in the tangent
plane of the solid's outer face at a spot p (smooth normal n0) with the letters' up u; the text's
x axis is r = u x n0, so (r, u, n0) is right-handed and the text reads left to right seen from
outside (not mirrored).  Its cross-section (manifold3d ``CrossSection``) is extruded from
-depth to +lift, refined to short edges (``refine_to_length``) and every vertex (x, y, z) is
carried onto the surface: S(x, y) is the first face met coming from outside along n0 through
p + x r + y u, N the vertex normals interpolated there, and the vertex goes to
S + z N / (N . n_f) (n_f that face's normal).  So the floor of every letter lies exactly ``depth``
below each face under it, measured along the face normal: the text bends with the surface
(on a convex face the floor's chords lie a little deeper, on a concave one shallower by
(edge length)^2 / (8 R), about 1e-4 mm).  The bent prism is subtracted with manifold3d's
boolean difference (no hand-written boolean); faces keep the side class they came from (face
ids tracked through the boolean) and the walls and floors of the letters get SIDE_OUTER.

Where a text fits (room on the outer face, tilt, the wall under it, the order spots are tried
in): engrave_place.py; the outer face seen from outside (spots, the projection S): engrave_surface.py.
`engrave_labels` tries LABEL_HEIGHTS and, for the label, the text turned along the direction the
face is longest in around the spot.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import manifold3d as m3

from .engrave_place import (
    MARGIN_MM,
    MARGIN_REL,
    MAX_TILT_DEG,
    MAX_TRIES,
    WALL_FACTOR,
    _clearance,
    _default_up,
    _NoFit,
    _place,
    _roomiest_first,
    _Spot,
    _text_box,
)
from .engrave_surface import SPOT_SPACING_MM, _Surface, _unit
from ..errors import BolusError
from .manifold import SIDE_OUTER
from ..mesh.topology import check_mesh, submesh

__all__ = ["TextOutline", "engrave_text", "engrave_labels", "strings_needed",
           # re-exported from engrave_place / engrave_surface
           "MAX_TILT_DEG", "MARGIN_MM", "MARGIN_REL", "WALL_FACTOR", "MAX_TRIES", "SPOT_SPACING_MM"]

#: how far the cutting prism rises above the surface (mm; at least the depth)
LIFT_MM = 0.5
#: letter heights (cap height, mm) tried by `engrave_labels`, largest first
LABEL_HEIGHTS = (6.0, 5.0, 4.0)


@dataclass
class TextOutline:
    """One line of text in 2D: x along the text, y up, baseline y = 0, cap height 1.0.

    polygons: closed outlines (k,2) float, outer ones counter-clockwise and holes clockwise
    (filled even-odd, so the orientation does not matter); width: advance width at cap height 1."""
    polygons: list
    width: float


def strings_needed(label: str, part_count: int | None = None) -> list[str]:
    """The strings `engrave_labels` engraves for ``label``: [] without a label; else the label
    (``"<label> <i>"`` for each part i = 0..part_count-1 when ``part_count`` is given, i as in
    the part objects' names ``<name>_part_<i>``) and the markers "L" and "R"."""
    label = (label or "").strip()
    if not label:
        return []
    if part_count is None:
        return [label, "L", "R"]
    return [f"{label} {i}" for i in range(int(part_count))] + ["L", "R"]


# ---------------------------------------------------------------- cutting

def _bent_prism(surf: _Surface, spot: _Spot, text: TextOutline, depth: float):
    """The letters as a solid from ``depth`` below the surface to LIFT above it, bent along the
    surface (module docstring): a Manifold and its expected volume below the surface."""
    h = spot.height
    polys = [np.asarray(p, dtype=np.float64).reshape(-1, 2) * h - spot.centre for p in text.polygons]
    cs = m3.CrossSection([np.ascontiguousarray(p) for p in polys if len(p) >= 3], m3.FillRule.EvenOdd)
    if cs.is_empty():
        raise _NoFit("the text has no area")
    lift = max(LIFT_MM, depth)
    refine = min(0.4, h / 15.0)
    prism = m3.Manifold.extrude(cs, depth + lift).refine_to_length(refine)
    mesh = prism.to_mesh64()
    P = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    Q = spot.p + P[:, :1] * spot.r + P[:, 1:2] * spot.u
    face, X, bary = surf.project(spot.p, spot.n, Q, reach=spot.reach)  # as in _fit: the same faces
    ok = face >= 0
    ok[ok] = surf.side[face[ok]] == SIDE_OUTER
    if not ok.all():
        raise _NoFit(f"{int(np.sum(~ok))} points of the letters fall off the outer face")
    N, c = surf.normal_at(face, bary)
    out = X + ((P[:, 2] - depth) / np.maximum(c, 0.2))[:, None] * N
    # (manifold3d wants writable arrays: its own mesh arrays are read-only views)
    bent = m3.Manifold(m3.Mesh64(vert_properties=np.array(out, dtype=np.float64, order="C"),
                                 tri_verts=np.array(mesh.tri_verts, dtype=np.uint64, order="C"),
                                 merge_from_vert=np.array(mesh.merge_from_vert, dtype=np.uint64),
                                 merge_to_vert=np.array(mesh.merge_to_vert, dtype=np.uint64)))
    if str(bent.status()).split(".")[-1] != "NoError":
        raise _NoFit(f"the bent letters are not a valid solid ({bent.status()})")
    return bent, cs.area() * depth


def _subtract(surf: _Surface, prisms, expected):
    """surf's solid minus the prisms: (V, F, side), or raise _NoFit when the result is not the
    expected one (the volume removed off by a factor of two, or the topology changed)."""
    cut = prisms[0] if len(prisms) == 1 else m3.Manifold.batch_boolean(prisms, m3.OpType.Add)
    R = surf.M - cut
    if str(R.status()).split(".")[-1] != "NoError" or R.is_empty():
        raise _NoFit(f"the boolean difference failed ({R.status()})")
    removed = surf.M.volume() - R.volume()
    if not (0.5 * expected <= removed <= 1.8 * expected) or R.genus() != surf.M.genus():
        raise _NoFit(f"the engraving came out wrong (removed {removed:.1f} mm3 instead of about "
                     f"{expected:.1f} mm3, genus {R.genus()} instead of {surf.M.genus()})")
    mesh = R.to_mesh64()
    V = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3].copy()
    F = np.asarray(mesh.tri_verts, dtype=np.int64).reshape(-1, 3).copy()
    fid = np.asarray(mesh.face_id, dtype=np.int64)
    run = np.asarray(mesh.run_index, dtype=np.int64) // 3
    rid = np.asarray(mesh.run_original_id, dtype=np.int64)
    from_solid = np.repeat(rid == surf.sid, np.diff(run))
    side = np.where(from_solid, surf.side[np.clip(fid, 0, len(surf.side) - 1)], SIDE_OUTER).astype(surf.side.dtype)
    return V, F, side


# ---------------------------------------------------------------- public

def _check_solid(V, F, side):
    V, F = check_mesh(V, F, "the solid", nondegenerate=False)
    side = np.asarray(side)
    if side.shape != (len(F),):
        raise BolusError(f"the solid has {len(F)} triangles but {side.shape} side classes")
    return V, F, side


def _check_text(text, what):
    if not getattr(text, "polygons", None) or not hasattr(text, "width"):  # any TextOutline-like object
        raise BolusError(f"{what}: no text outline to engrave")
    for p in text.polygons:
        p = np.asarray(p, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 2 or not np.isfinite(p).all():
            raise BolusError(f"{what}: a text outline is not a finite (k, 2) polygon")


def _direction(v, what):
    v = np.asarray(v, dtype=np.float64).reshape(-1)
    if v.shape != (3,) or not np.isfinite(v).all() or np.linalg.norm(v) < 1e-9:
        raise BolusError(f"{what} must be a finite non-zero 3-vector, got {v}")
    return v / np.linalg.norm(v)


def _projected(v, n0, fallback):
    t = v - (v @ n0) * n0
    return _unit(t) if np.linalg.norm(t) > 0.3 else fallback


def engrave_text(V, F, side, text: TextOutline, *, height_mm=6.0, depth_mm=0.6, at=None, up=None, progress=None):
    """Engrave one line of text ``depth_mm`` deep into the outer face of a closed solid.

    V (n,3) mm, F (m,3), side (m,) SIDE_* of each face; text: `TextOutline`; height_mm: cap height;
    at (3,): place it at the spot of the outer face nearest this point where it fits (None: the
    spot farthest from the rim / cut / connector faces); up (3,): the letters' up direction
    (projected on the surface; None: the solid's longest extent, see `_default_up`).
    Returns (V', F', side', note): the engraved closed solid with the letters' faces SIDE_OUTER and
    note None; or the solid unchanged and a note saying why the text could not be placed.
    """
    V, F, side = _check_solid(V, F, side)
    _check_text(text, "engrave_text")
    if not (0 < height_mm <= 1000) or not (0 < depth_mm <= 50):
        raise BolusError(f"engrave_text: height {height_mm} mm and depth {depth_mm} mm must be positive")
    at = None if at is None else np.asarray(at, dtype=np.float64).reshape(-1)
    if at is not None and (at.shape != (3,) or not np.isfinite(at).all()):
        raise BolusError(f"engrave_text: at must be a finite 3D point, got {at}")
    up = None if up is None else _direction(up, "engrave_text: up")
    progress = progress or (lambda f, t: None)
    progress(0.0, "engraving: finding a spot")
    surf = _Surface(V, F, side)
    clearance = _clearance(surf, [])
    key = _roomiest_first(surf, clearance) if at is None else np.linalg.norm(surf.spots - at, axis=1)

    def up_of(p, n0):
        fallback = _default_up(surf, n0)
        return fallback if up is None else _projected(up, n0, fallback)

    try:
        spot = _place(surf, text, float(height_mm), float(depth_mm), key, clearance, up_of, [])
        progress(0.4, "engraving: bending the letters")
        prism, expected = _bent_prism(surf, spot, text, float(depth_mm))
        progress(0.7, "engraving: boolean difference")
        out = _subtract(surf, [prism], expected)
    except _NoFit as e:
        progress(1.0, "engraving: not placed")
        return V, F, side, f"not engraved: {e}"
    progress(1.0, "engraving: done")
    return (*out, None)


def engrave_labels(V, F, side, outlines: dict, label: str, left, *, part_labels=None, depth_mm=0.6,
                   up=None, return_labels=False, progress=None):
    """The bolus's own marks: ``label`` (``"<label> <i>"`` on each part i when ``part_labels`` (m,)
    is given, on the part's own outer face) and "L" / "R" at the patient's left / right ends
    (``left`` (3,): unit vector to the patient's left; only on the parts that hold those ends),
    each ``depth_mm`` deep, letters tried at LABEL_HEIGHTS mm.  Text reads left to right for a
    viewer facing the outer face with the patient's left on his right: up = n x left at the
    spot (the solid's longest extent where the face looks to the left or right), or ``up``.
    outlines: {string: TextOutline} for every string of `strings_needed`.  Nothing when the label
    is empty.  Returns (V', F', side', warnings) -- with ``return_labels`` (V', F', side',
    part_labels', warnings), the part of each new face -- warnings naming what was not placed
    and why (those parts are left as they were).  progress(fraction, text): once per part."""
    V, F, side = _check_solid(V, F, side)
    label = (label or "").strip()
    parts = np.zeros(len(F), dtype=np.int64) if part_labels is None else np.asarray(part_labels, dtype=np.int64)
    if parts.shape != (len(F),) or (len(parts) and parts.min() < 0):
        raise BolusError(f"engrave_labels: part_labels must give a part >= 0 for each of the {len(F)} triangles")
    if not label:
        return (V, F, side, parts, []) if return_labels else (V, F, side, [])
    left = _direction(left, "engrave_labels: left")
    up = None if up is None else _direction(up, "engrave_labels: up")
    k = int(parts.max()) + 1 if len(parts) else 0
    needed = strings_needed(label, None if part_labels is None else k)
    for s in needed:
        if s not in outlines:
            raise BolusError(f"engrave_labels: no text outline was given for '{s}'")
        _check_text(outlines[s], f"the outline of '{s}'")
    surfs = {}
    for i in range(k):
        Fl, vid = submesh(F, parts == i)
        if len(Fl):
            what = f"part {i}" if part_labels is not None else "the solid"
            surfs[i] = _Surface(V[vid], Fl, side[parts == i], what=what)
    ends = _marker_parts(surfs, left)
    warnings, pieces = [], []
    progress = progress or (lambda f, t: None)
    for i in range(k):
        progress(i / max(k, 1), f"engraving part {i + 1} of {k}" if part_labels is not None else "engraving")
        surf = surfs.get(i)
        if surf is None:
            continue
        name = label if part_labels is None else f"{label} {i}"
        items = [(name, "label")] + [(m, m) for m, j in ends.items() if j == i]
        Vi, Fi, si, notes = _engrave_part(surf, outlines, items, left, up, float(depth_mm))
        warnings += [n if part_labels is None else f"part {i}: {n}" for n in notes]
        pieces.append((Vi, Fi, si, i))
    progress(1.0, "engraving done")
    offs = np.cumsum([0] + [len(p[0]) for p in pieces])
    V2 = np.concatenate([p[0] for p in pieces]) if pieces else V
    F2 = np.concatenate([p[1] + o for p, o in zip(pieces, offs)]) if pieces else F
    s2 = np.concatenate([p[2] for p in pieces]) if pieces else side
    l2 = np.concatenate([np.full(len(p[1]), p[3], dtype=np.int64) for p in pieces]) if pieces else parts
    return (V2, F2, s2, l2, warnings) if return_labels else (V2, F2, s2, warnings)


def _label_up(surf: _Surface, text, height, left, up, turn):
    """up_of(p, n0) for `_place`: ``up`` projected, else n0 x left (reads left to right for a viewer
    facing the face with the patient's left on his right), else `_default_up`; with ``turn`` the
    text runs along the direction the outer face is longest in around p, still towards the left."""
    lo, hi = _text_box(text)
    radius = 0.5 * (hi[0] - lo[0]) * height + max(MARGIN_MM, MARGIN_REL * height)

    def up_of(p, n0):
        fallback = _default_up(surf, n0)
        u = _projected(up if up is not None else np.cross(n0, left), n0, fallback)
        if turn:
            x = _projected(_local_long_axis(surf, p, n0, radius), n0, np.cross(u, n0))
            x = x if x @ left >= 0 else -x
            u = np.cross(n0, x)
        return u
    return up_of


def _local_long_axis(surf: _Surface, p, n0, radius):
    """(3,) the direction in which the outer face around p (within ``radius``) extends most
    (principal axis of its spots in the tangent plane)."""
    near = surf.spots[surf.spot_tree.query_ball_point(p, radius)]
    if len(near) < 3:
        return surf.axes[0]
    D = near - near.mean(axis=0)
    D = D - np.outer(D @ n0, n0)
    return np.linalg.eigh(D.T @ D)[1][:, -1]


def _marker_parts(surfs, left):
    """{"L": part holding the outer-face point farthest to the patient's left, "R": ... right}."""
    best = {}
    for i, s in surfs.items():
        if len(s.spots) == 0:
            continue
        a = s.spots @ left
        for m, v in (("L", a.max()), ("R", -a.min())):
            if m not in best or v > best[m][0]:
                best[m] = (v, i)
    return {m: i for m, (v, i) in best.items()}


def _engrave_part(surf: _Surface, outlines, items, left, up, depth):
    """Place every (string, kind) of ``items`` on one part and cut them: (V, F, side, notes)."""
    taken, placed, notes = [], [], []
    for s, kind in items:
        text = outlines[s]
        clearance = _clearance(surf, taken)
        if kind == "label":
            key0 = _roomiest_first(surf, clearance)
        else:
            a = surf.spots @ left
            key0 = -a if kind == "L" else a
        spot, note = None, None
        for height in LABEL_HEIGHTS:
            for turn in (False, True) if kind == "label" else (False,):
                try:
                    spot = _place(surf, text, height, depth, key0, clearance,
                                  _label_up(surf, text, height, left, up, turn), taken)
                    prism, vol = _bent_prism(surf, spot, text, depth)
                    break
                except _NoFit as e:
                    spot, note = None, note or str(e)
            if spot is not None:
                break
        if spot is None:
            also = "also tried " + " and ".join(f"{h:g}" for h in LABEL_HEIGHTS[1:]) + " mm letters"
            also += " and the text turned along the face" if kind == "label" else ""
            notes.append(f"'{s}' not engraved: {note} ({also})")
            continue
        taken.append(spot.footprint)
        placed.append((s, prism, vol))
    if not placed:
        return surf.V, surf.F, surf.side, notes
    try:
        return (*_subtract(surf, [p for _, p, _ in placed], sum(v for _, _, v in placed)), notes)
    except _NoFit:  # find the text that spoils it: keep the others
        good = []
        for s, prism, vol in placed:
            try:
                _subtract(surf, [prism], vol)
                good.append((prism, vol))
            except _NoFit as e:
                notes.append(f"'{s}' not engraved: {e}")
        try:
            if good:
                return (*_subtract(surf, [p for p, _ in good], sum(v for _, v in good)), notes)
        except _NoFit as e:
            notes.append(f"nothing engraved: {e}")
        return surf.V, surf.F, surf.side, notes
