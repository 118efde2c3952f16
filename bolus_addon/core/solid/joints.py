"""Joints of solid print parts: the faces two parts share on one plane and their connectors
(seed 6.4.3; step 5 of `parts.split_solid`).

`Joint`: normal . x + offset = 0 from parts[0] into parts[1], its area, wall thickness and
`connectors.Connector`s.  `_joints` intersects the parts' cut faces per plane (2D
CrossSections); `_connect` sizes the connectors from the wall thickness (`_wall_probe`)
and places a peg and a hole near the two ends of the largest face of each pair, or notes
why not.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

import manifold3d as m3

from . import connectors as conn
from .manifold import SIDE_INNER, SIDE_OUTER
from .planes import MIN_CONTACT_AREA, _areas_centroids, _faces

__all__ = ["Joint", "MIN_JOINT_AREA"]

MIN_JOINT_AREA = 1.0  #: mm^2: a pair touching on less than this gets no connector and no warning (a corner)


@dataclass
class Joint:
    """The planar common face of two parts: normal . x + offset = 0."""

    parts: tuple  #: (i, j), i < j
    normal: np.ndarray  #: (3,) unit, from parts[0] into parts[1]
    offset: float
    area_mm2: float
    connectors: list = field(default_factory=list)  #: [Connector]
    note: str | None = None  #: why it has fewer than two connectors (None: it has two); a pair's smaller faces on
    #: other planes say "a second, ... face" and carry none
    thickness_mm: float = float("nan")  #: wall thickness at the joint (median over the joint face's edge;
    #: without inner/outer faces: the diameter of the largest circle inside the joint face)
    plane: int = -1  #: index of its plane among `SolidParts.planes`

    def as_dict(self) -> dict:
        return {"parts": [int(p) for p in self.parts], "normal": [float(x) for x in self.normal],
                "offset": float(self.offset), "area_mm2": float(self.area_mm2),
                "thickness_mm": float(self.thickness_mm), "note": self.note,
                "connectors": [c.as_dict() for c in self.connectors]}


def _cut_sections(P: m3.Manifold, plane_of_id: dict, planes):
    """{plane: (CrossSection of the part's faces on it in the plane frame, mean outward normal)}."""
    V, F, oid, _ = _faces(P)
    out = {}
    pid = np.array([plane_of_id.get(int(i), -1) for i in oid], dtype=np.int64) if len(oid) else np.zeros(0, np.int64)
    for p in np.unique(pid[pid >= 0]):
        sel = pid == p
        origin, U = conn.plane_frame(planes[p, :3], planes[p, 3])
        T = conn.to_plane(V[F[sel]].reshape(-1, 3), origin, U).reshape(-1, 3, 2)
        _, _, cr = _areas_centroids(V, F[sel])
        out[int(p)] = (conn.section_of_triangles(T), cr.sum(axis=0))
    return out


def _joints(part_M, planes, plane_of_id) -> list[Joint]:
    secs = [(_cut_sections(P, plane_of_id, planes) if not P.is_empty() else {}) for P in part_M]
    joints = []
    for a in range(len(part_M)):
        for b in range(a + 1, len(part_M)):
            for p in sorted(set(secs[a]) & set(secs[b])):
                inter = secs[a][p][0] ^ secs[b][p][0]
                area = float(inter.area())
                if area < MIN_CONTACT_AREA:
                    continue
                sgn = 1.0 if secs[a][p][1] @ planes[p, :3] > 0 else -1.0  # a's outward normal points to b
                J = Joint((a, b), sgn * planes[p, :3].copy(), float(sgn * planes[p, 3]), area, plane=int(p))
                J._section = inter
                joints.append(J)
    for J in joints:  # a pair touching on several planes: its largest face carries the connectors
        main = max((K for K in joints if K.parts == J.parts), key=lambda K: K.area_mm2)
        if J is main and J.area_mm2 < MIN_JOINT_AREA:
            J.note = f"the parts touch on only {J.area_mm2:.2g} mm² here: no connector"
            J.__dict__.pop("_section", None)
        elif J is not main:
            J.note = (f"a second, {J.area_mm2:.0f} mm² face of parts {J.parts[0]} and {J.parts[1]} on another plane: "
                      "their main joint carries the connectors")
            J.__dict__.pop("_section", None)
    return joints


def _wall_probe(V, F, side):
    """Callable x (3,) -> (s (3,) unit into the material, height of x above the inner face,
    wall thickness), from the solid's nearest inner and outer faces; None when the solid
    has no inner or outer faces."""
    areas, cents, cr = _areas_centroids(V, F)
    inner, outer = (side == SIDE_INNER) & (areas > 0), (side == SIDE_OUTER) & (areas > 0)
    if not inner.any() or not outer.any():
        return None
    Cin, Nin = cents[inner], -cr[inner] / (2.0 * areas[inner])[:, None]  # inner faces face the skin
    Cout = cents[outer]
    tin, tout = cKDTree(Cin), cKDTree(Cout)

    def wall(x):
        x = np.asarray(x, dtype=np.float64)
        i = tin.query(x)[1]
        o = tout.query(x)[1]
        s = Nin[i]
        return s, float((x - Cin[i]) @ s), float((Cout[o] - Cin[i]) @ s)

    return wall


def _connect(J: Joint, part_M, planes, clearance, conn_ids, keepout, skin_tree, skin_normals, wall, warnings):
    p = J.plane
    section = J.__dict__.pop("_section")
    origin, U = conn.plane_frame(planes[p, :3], planes[p, 3])
    R = conn.inscribed_radius(section)
    if wall is not None:
        B = conn._vertices(section)
        B = B[:: max(1, len(B) // 200)]
        J.thickness_mm = float(np.median([wall(x)[2] for x in conn.from_plane(B, origin, U)]))
    else:
        J.thickness_mm = 2.0 * R
    r, length, need = conn.connector_size(J.thickness_mm, clearance)
    i, j = J.parts
    if J.thickness_mm < need:
        J.note = (f"too thin for a peg: the wall at the joint is {J.thickness_mm:.1f} mm thick, a {2 * r:.1f} mm peg "
                  f"with {clearance:g} mm clearance and {conn.WALL_MIN:g} mm walls needs {need:.1f} mm")
    elif R < r + clearance + conn.WALL_MIN:
        J.note = (f"too small for a peg: the joint face is {2 * R:.1f} mm across at its widest, a {2 * r:.1f} mm peg "
                  f"with {clearance:g} mm clearance and {conn.WALL_MIN:g} mm walls needs {need:.1f} mm")
    if J.note is not None:
        warnings.append(f"joint between parts {i} and {j} left plain: {J.note}")
        return
    C2 = conn.place_centres(section, r, clearance, inscribed=R)
    C3 = [conn.from_plane(c, origin, U) for c in C2]
    sites = np.array([c[0] for c in C3]).reshape(-1, 3)
    _, near = skin_tree.query(sites) if len(sites) else (None, np.zeros(0, np.int64))
    best = None
    axes = conn.joint_axes(J.normal, skin_normals[near])
    for axis in axes[-1:] + axes[:-1]:  # the plane normal first: pegs square to the joint face
        trial_parts, trial_keep, trial_ids = list(part_M), {q: list(v) for q, v in keepout.items()}, set()
        made, notes = conn.add_joint_connectors(trial_parts, J.parts, (J.normal, J.offset), axis, C3, r, length,
                                                clearance, trial_ids, trial_keep, wall)
        if best is None or len(made) > len(best[0]):
            best = (made, notes, trial_parts, trial_keep, trial_ids)
        if len(made) == len(C3):
            break
    made, notes, trial_parts, trial_keep, trial_ids = best
    part_M[:] = trial_parts
    keepout.clear()
    keepout.update(trial_keep)
    conn_ids.update(trial_ids)
    J.connectors = made
    if len(C2) == 1:
        notes.insert(0, "one connector only: the joint is too short for two")
    if notes:
        J.note = "; ".join(notes)
        warnings.append(f"joint between parts {i} and {j}: {J.note}")
