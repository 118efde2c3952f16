"""Engraved text on a bolus solid: the label, the part numbers and the L / R markers (issue 11 point 1).

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

A spot is used only when the text's box plus a margin lies entirely on the outer face
(no rim, cut or connector face under it, the face tilted at most ``MAX_TILT_DEG`` from n0)
and the wall under the letters is at least twice the depth (ray casts); otherwise the
solid comes back unchanged with a note giving the figures.  The x stretch of the letters
on a curved face is at most 1 / cos(tilt) (the outline is projected along n0).

Placement.  Spots are points sampled every SPOT_SPACING_MM on the outer face.  A label goes to
the spot farthest from the rim / cut / connector faces (then the nearest to the middle), a marker
to the spot farthest towards the patient's left ("L") or right ("R") that still has room; up to
MAX_TRIES spots, spread over the face, are tried.  `engrave_labels` tries LABEL_HEIGHTS and,
for the label, the text turned along the direction the face is longest in around the spot.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

import manifold3d as m3

from .errors import BolusError
from .solid import SIDE_CONNECTOR, SIDE_CUT, SIDE_NAMES, SIDE_OUTER, SIDE_RIM, ray_thickness, to_manifold
from .topology import check_mesh, submesh

__all__ = ["TextOutline", "engrave_text", "engrave_labels", "strings_needed"]

#: how far the cutting prism rises above the surface (mm; at least the depth)
LIFT_MM = 0.5
#: steepest tilt of the outer face under the text against the normal at its centre (degrees)
MAX_TILT_DEG = 40.0
#: margin around the text's box that must lie on the outer face: max(MARGIN_MM, MARGIN_REL * height)
MARGIN_MM, MARGIN_REL = 1.0, 0.2
#: the wall under the letters must be at least this many times the depth
WALL_FACTOR = 2.0
#: letter heights (cap height, mm) tried by `engrave_labels`, largest first
LABEL_HEIGHTS = (6.0, 5.0, 4.0)
#: spots tried per text and orientation
MAX_TRIES = 12
#: spacing of the points sampled on the faces to find spots (mm)
SPOT_SPACING_MM = 1.0
#: sides that bound the outer face: the text keeps its distance from them
_BOUNDING_SIDES = (SIDE_RIM, SIDE_CUT, SIDE_CONNECTOR)


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


# ---------------------------------------------------------------- the outer face seen from outside

def _sample_faces(V, F, faces, spacing):
    """Points on the triangles ``faces`` at about ``spacing`` (barycentric grids): (points (s,3),
    face (s,), bary (s,3))."""
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    T = V[F[faces]]
    longest = np.max(np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2), axis=1)
    nsub = np.clip(np.ceil(longest / spacing), 1, 64).astype(np.int64)
    pts, fs, bs = [], [], []
    for n in np.unique(nsub):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = (i + j) <= n
        b = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], axis=1) / n
        b = np.r_[b, [[1 / 3, 1 / 3, 1 / 3]]]
        sel = np.nonzero(nsub == n)[0]
        P = np.einsum("kj,fjd->fkd", b, T[sel]).reshape(-1, 3)
        pts.append(P)
        fs.append(np.repeat(faces[sel], len(b)))
        bs.append(np.tile(b, (len(sel), 1)))
    return np.concatenate(pts), np.concatenate(fs), np.concatenate(bs)


def _thin_out(P, h):
    """Indices (sorted) of one point of P (k,3) per cube of side h."""
    if len(P) == 0:
        return np.zeros(0, dtype=np.int64)
    key = np.floor((P - P.min(axis=0)) / h).astype(np.int64)
    dims = key.max(axis=0) + 1
    flat = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
    return np.sort(np.unique(flat, return_index=True)[1])


def _locate_2d(Q, T):
    """All (point, triangle, barycentrics) with point Q[i] (k,2) inside triangle T[t] (c,3,2)
    (closed, edge-on triangles skipped), through a uniform grid of cells."""
    lo, hi = T.min(axis=1), T.max(axis=1)
    cell = max(float(np.median(np.max(hi - lo, axis=1))), 1e-6)
    qlo = Q.min(axis=0) - cell
    qhi = Q.max(axis=0) + cell
    keep = np.nonzero(np.all(hi >= qlo, axis=1) & np.all(lo <= qhi, axis=1))[0]
    empty = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
    if len(keep) == 0 or len(Q) == 0:
        return empty
    ncell = np.ceil((qhi - qlo) / cell).astype(np.int64) + 1
    i0 = np.clip(np.floor((lo[keep] - qlo) / cell).astype(np.int64), 0, ncell - 1)
    i1 = np.clip(np.floor((hi[keep] - qlo) / cell).astype(np.int64), 0, ncell - 1)
    span = i1 - i0 + 1
    cnt = span[:, 0] * span[:, 1]
    tri = np.repeat(keep, cnt)
    local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    w = np.repeat(span[:, 0], cnt)
    cid = (np.repeat(i0[:, 0], cnt) + local % w) * ncell[1] + np.repeat(i0[:, 1], cnt) + local // w
    order = np.argsort(cid, kind="stable")
    cid, tri = cid[order], tri[order]
    qc = np.clip(np.floor((Q - qlo) / cell).astype(np.int64), 0, ncell - 1)
    qid = qc[:, 0] * ncell[1] + qc[:, 1]
    a = np.searchsorted(cid, qid, "left")
    n = np.searchsorted(cid, qid, "right") - a
    qi = np.repeat(np.arange(len(Q)), n)
    ti = tri[np.repeat(a, n) + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)]
    A = T[ti, 0]
    e1, e2, q = T[ti, 1] - A, T[ti, 2] - A, Q[qi] - A
    den = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]
    scale = np.maximum(np.abs(e1).max(axis=1), np.abs(e2).max(axis=1)) ** 2
    ok = np.abs(den) > 1e-12 * scale
    den = np.where(ok, den, 1.0)
    b1 = (q[:, 0] * e2[:, 1] - e2[:, 0] * q[:, 1]) / den
    b2 = (e1[:, 0] * q[:, 1] - q[:, 0] * e1[:, 1]) / den
    b0 = 1.0 - b1 - b2
    eps = 1e-9
    inside = ok & (b0 >= -eps) & (b1 >= -eps) & (b2 >= -eps)
    return qi[inside], ti[inside], np.stack([b0, b1, b2], axis=1)[inside]


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-300, n, 1.0)


class _Surface:
    """A closed solid V, F with face classes ``side``: its outer face seen from outside."""

    def __init__(self, V, F, side, what="the solid"):
        self.V, self.F, self.side, self.what = V, F, side, what
        T = V[F]
        cr = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
        self.fn = _unit(cr)
        outer = np.nonzero(side == SIDE_OUTER)[0]
        vn = np.zeros_like(V)
        np.add.at(vn, F[outer].ravel(), np.repeat(cr[outer], 3, axis=0))
        self.vn = _unit(vn)
        spots, face, bary = _sample_faces(V, F, outer, SPOT_SPACING_MM)
        keep = _thin_out(spots, SPOT_SPACING_MM)
        self.spots, self.spot_face, self.spot_bary = spots[keep], face[keep], bary[keep]
        self.spot_tree = cKDTree(self.spots)
        bounds = _sample_faces(V, F, np.nonzero(np.isin(side, _BOUNDING_SIDES))[0], SPOT_SPACING_MM)[0]
        self.bounds = bounds[_thin_out(bounds, SPOT_SPACING_MM)]
        self.M, self.sid = _tracked_manifold(V, F, what)
        self.centroids = T.mean(axis=1)
        self.ctree = cKDTree(self.centroids)
        self.frad = float(np.linalg.norm(T - self.centroids[:, None], axis=2).max())
        Vc = V - V.mean(axis=0)
        self.axes = np.linalg.svd(Vc, full_matrices=False)[2] if len(V) >= 3 else np.eye(3)

    def normal_at(self, face, bary):
        """Smooth normal N (k,3) at points (face, bary) and c = N . n_face (k,) (> 0)."""
        N = _unit(np.einsum("kj,kjd->kd", bary, self.vn[self.F[face]]))
        N = np.where(np.linalg.norm(N, axis=1, keepdims=True) > 0.5, N, self.fn[face])
        c = np.einsum("kd,kd->k", N, self.fn[face])
        return N, c

    def project(self, p, n0, Q, reach):
        """The first face facing n0 met coming from outside along n0 through each point Q (k,3) of
        the plane through p normal to n0, within ``reach`` mm above / below it: face (k,) (-1: none),
        the hit X (k,3), barycentrics (k,3)."""
        k = len(Q)
        face = np.full(k, -1, dtype=np.int64)
        X = np.full((k, 3), np.nan)
        bary = np.zeros((k, 3))
        r = _unit(np.cross(n0, [1.0, 0.0, 0.0] if abs(n0[0]) < 0.9 else [0.0, 1.0, 0.0]))
        u = np.cross(n0, r)
        B = np.stack([r, u], axis=1)
        if k == 0:
            return face, X, bary
        rho = float(np.linalg.norm(Q - p, axis=1).max())
        near = np.asarray(self.ctree.query_ball_point(p, np.hypot(rho, reach) + self.frad), dtype=np.int64)
        # faces seen from outside along n0 (a fold over the spot shows up as a jump in height)
        near = near[(np.abs((self.centroids[near] - p) @ n0) <= reach + self.frad) & (self.fn[near] @ n0 > 0)]
        if len(near) == 0:
            return face, X, bary
        T = self.V[self.F[near]] - p
        qi, ti, b = _locate_2d((Q - p) @ B, T @ B)
        if len(qi) == 0:
            return face, X, bary
        ti = near[ti]
        Xh = np.einsum("kj,kjd->kd", b, self.V[self.F[ti]])
        hh = (Xh - p) @ n0
        order = np.lexsort((-hh, qi))
        first = order[np.r_[True, qi[order][1:] != qi[order][:-1]]]
        face[qi[first]] = ti[first]
        X[qi[first]] = Xh[first]
        bary[qi[first]] = b[first]
        return face, X, bary


def _tracked_manifold(V, F, what):
    """The solid as a Manifold whose faces remember their index in F through booleans:
    (Manifold, its run's original id)."""
    sid = int(m3.Manifold.reserve_ids(1))
    m = len(F)
    mesh = m3.Mesh64(vert_properties=np.array(V, dtype=np.float64, order="C"),
                     tri_verts=np.array(F, dtype=np.uint64, order="C"),
                     run_index=np.array([0, 3 * m], dtype=np.uint64),
                     run_original_id=np.array([sid], dtype=np.uint32),
                     face_id=np.arange(m, dtype=np.uint64))
    M = m3.Manifold(mesh)
    if str(M.status()).split(".")[-1] != "NoError":
        to_manifold(V, F, what)  # raises the named problem
        raise BolusError(f"{what} could not be read as a closed solid ({M.status()})")
    return M, sid


# ---------------------------------------------------------------- placing one line of text

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


def _text_box(text: TextOutline):
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
    wall = ray_thickness(surf.V, surf.F, X[pick], -N, max_mm=WALL_FACTOR * depth * 4, manifold=surf.M)
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
