"""Closed solid print parts of a bolus with planar joints and connectors (seed 6.3-6.4.3).

`split_solid` takes the closed solid (a `shell.Shell`'s V (n,3) mm, F (m,3), side (m,)), the skin
region it was built on and a part label per skin triangle (`print_segmentation`), and returns
the closed parts as `SolidParts`:

1. neighbouring parts: skin labels that share a skin edge;
2. the common plane of each pair, x^T W + b = 0 (eqs. 6-38..6-40): a linear SVM on the two
   parts' skin vertices, W unit, pointing from the lower label to the higher;
3. cells: the solid split by every plane, each cell given to the part whose skin lies under it;
   two parts' cells in one region of the plane arrangement get an extra separating plane;
4. parts: part q = solid ∩ K_q, K_q a union of convex polytopes (the bounding box trimmed by
   planes); crumbs and slivers under CRUMB_MM3 are left out with a warning;
5. joints: the faces two parts share on one plane; the largest of each pair gets `connectors`.

The solid's faces keep their ``side``, faces on a joint plane are SIDE_CUT, peg and hole walls
SIDE_CONNECTOR.  Steps 1-3 and the region terms are in `planes`, step 5 in `joints`.

Design notes: docs/design/solid.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

import manifold3d as m3

from . import connectors as conn
from .connectors import Connector
from ..errors import BolusError
from .manifold import SIDE_CONNECTOR, SIDE_CUT
from .joints import MIN_JOINT_AREA, Joint, _connect, _joints, _wall_probe
from .planes import (
    CRUMB_MM3,
    MAX_SVM_POINTS,
    MIN_CONTACT_AREA,
    ON_PLANE_TOL,
    SVM_C,
    _cell_contacts,
    _cell_owner,
    _cell_sections,
    _connected_owners,
    _drop_crumbs,
    _faces,
    _ids,
    _region_terms,
    _signs,
    _split_cells,
    _tracked,
    skin_neighbours,
    svm_plane,
)
from ..mesh.topology import MeshTopology, check_mesh

__all__ = ["Connector", "Joint", "SolidParts", "skin_neighbours", "svm_plane", "split_solid",
           "SVM_C", "MAX_SVM_POINTS", "MAX_EXTRA_PLANES", "MIN_JOINT_AREA"]

MAX_EXTRA_PLANES = 4  #: separating planes added for cells of two parts in one arrangement region
WRONG_SIDE_WARN = 0.15  #: warn when a joint plane leaves over 15 % of the two parts' skin vertices on the wrong side
VOLUME_RTOL = 1e-6  #: parts' volumes must add up to the solid's to this relative round-off


@dataclass
class SolidParts:
    """Result of `split_solid`: k closed parts in one array pair."""

    V: np.ndarray  #: (n,3) float64 mm
    F: np.ndarray  #: (m,3) int64, each part a closed manifold, outward wound
    labels: np.ndarray  #: (m,) int64 part of each face, 0..k-1
    side: np.ndarray  #: (m,) int8 SIDE_* of each face
    volumes_mm3: np.ndarray  #: (k,) with connectors
    joints: list  #: [Joint]
    warnings: list  #: [str]
    plain_volumes_mm3: np.ndarray | None = None  #: (k,) before connectors (they add up to the solid's)
    solid_volume_mm3: float = float("nan")
    planes: np.ndarray | None = None  #: (p,4) rows (normal, offset) of every cutting plane (extra ones last)

    @property
    def part_count(self) -> int:
        return len(self.volumes_mm3)

    def part(self, q: int) -> tuple[np.ndarray, np.ndarray]:
        """(V, F) of part q alone (compacted)."""
        Fq = self.F[self.labels == q]
        used, inv = np.unique(Fq.ravel(), return_inverse=True)
        return self.V[used], inv.reshape(-1, 3)


# ----------------------------------------------------------------------------- main

def _check_input(V, F, side, skin_V, skin_F, skin_labels, clearance):
    V, F = check_mesh(V, F, "the solid", nondegenerate=False)
    side = np.asarray(side)
    if side.shape != (len(F),):
        raise BolusError(f"the solid's face sides must be one per triangle ({len(F)}), got shape {side.shape}")
    skin_V, skin_F = check_mesh(skin_V, skin_F, "the skin region", nondegenerate=False)
    lab = np.asarray(skin_labels)
    if lab.shape != (len(skin_F),):
        raise BolusError(f"the skin part labels must be one per skin triangle ({len(skin_F)}), got shape {lab.shape}")
    if not np.issubdtype(lab.dtype, np.integer):
        if not np.all(np.isfinite(lab)) or np.any(lab != np.round(lab)):
            raise BolusError("the skin part labels must be whole numbers")
    lab = lab.astype(np.int64)
    if lab.min() < 0:
        raise BolusError(f"the skin part labels must be 0 or more, got {int(lab.min())}")
    k = int(lab.max()) + 1
    missing = sorted(set(range(k)) - set(np.unique(lab).tolist()))
    if missing:
        raise BolusError(f"the skin part labels skip part(s) {missing}: number the parts 0..{k - 1}")
    if not (np.isfinite(clearance) and 0 <= clearance < 2.0):
        raise BolusError(f"the connector clearance must lie in [0, 2) mm, got {clearance}")
    return V, F, side.astype(np.int8), skin_V, skin_F, lab, k


def split_solid(V, F, side, skin_V, skin_F, skin_labels, *, clearance: float = conn.CLEARANCE,
                connectors: bool = True, rng=0, progress=None) -> SolidParts:
    """Cut the closed solid V (n,3) mm, F (m,3), side (m,) SIDE_* into closed parts, one per
    skin label, separated by the SVM planes of neighbouring parts (eqs. 6-38..6-40), with a
    peg and a hole per joint end (``connectors``; clearance mm).

    skin_V (ns,3), skin_F (ms,3): the skin region the solid was built on; skin_labels (ms,)
    int 0..k-1 part per skin triangle (`print_segmentation`).  Returns `SolidParts`.
    BolusError on a solid that is not closed or on inconsistent labels; warnings name
    parts that fell apart, joints left plain and planes that leave much skin on the wrong side."""
    report = progress or (lambda f, t: None)
    V, F, side, skin_V, skin_F, lab, k = _check_input(V, F, side, skin_V, skin_F, skin_labels, clearance)
    report(0.0, "solid")
    M, rid = _tracked(V, F)
    solid_volume = float(M.volume())
    if not solid_volume > 0:
        raise BolusError("the solid has no volume (is it wound inside out?)")
    warnings: list[str] = []
    M = _drop_crumbs(M, warnings)
    skin_topo = MeshTopology(skin_V, skin_F)
    report(0.05, "common planes")
    planes = _common_planes(skin_V, skin_F, lab, skin_topo, rng, warnings)
    report(0.15, "cells")
    tree = cKDTree(skin_topo.centroids)
    cells, owners, vols = _owned_cells(M, planes, rid, side, tree, lab, k)
    planes, owner_of = _separate_regions(cells, owners, vols, planes, rng, warnings)
    report(0.4, "parts")
    part_M, plane_of_id = _cut_parts(M, planes, owner_of, k, report, warnings)
    plain = _tidy_parts(part_M, float(M.volume()), warnings)
    report(0.75, "joints")
    joints = _joints(part_M, planes, plane_of_id)
    conn_ids = _place_connectors(joints, part_M, planes, (V, F, side), clearance, connectors, tree,
                                 skin_topo.face_normals, warnings)
    report(0.95, "faces")
    Vs, Fs, labels, sides = _part_faces(part_M, rid, side, conn_ids)
    report(1.0, "done")
    return SolidParts(V=Vs, F=Fs, labels=labels, side=sides, volumes_mm3=np.array([float(P.volume()) for P in part_M]),
                      joints=sorted(joints, key=lambda J: J.parts), warnings=warnings, plain_volumes_mm3=plain,
                      solid_volume_mm3=solid_volume, planes=planes)


def _common_planes(skin_V, skin_F, lab, skin_topo, rng, warnings) -> np.ndarray:
    """Steps 1-2: the SVM plane (eqs. 6-38..6-40) of each pair of neighbouring parts, fitted on
    the skin vertices each part does not share with the other.  Returns planes (p,4) rows
    (unit normal from the lower label to the higher, offset); warns when a plane leaves over
    WRONG_SIDE_WARN of the two parts' skin vertices on the wrong side."""
    plane_rows = []
    for i, j, _ in skin_neighbours(skin_F, lab, skin_topo):
        vi = np.unique(skin_F[lab == i])
        vj = np.unique(skin_F[lab == j])
        only_i, only_j = np.setdiff1d(vi, vj), np.setdiff1d(vj, vi)
        n, off, wrong = svm_plane(skin_V[only_i if len(only_i) else vi], skin_V[only_j if len(only_j) else vj], rng)
        if wrong > WRONG_SIDE_WARN:
            warnings.append(f"the joint plane between parts {i} and {j} leaves {100 * wrong:.1f} % of their skin "
                            "on the other part's side: their border is far from straight")
        plane_rows.append(np.r_[n, off])
    return np.array(plane_rows, dtype=np.float64).reshape(-1, 4)


def _owned_cells(M, planes, rid, side, tree, lab, k) -> tuple[list, list, list]:
    """Step 3, first half: the solid M split by every plane (p,4) into cells, each given to the
    part whose skin lies under it (area vote over the skin KD-tree `tree`), then groups cut off
    from their part's largest group given to the part they share most plane face with.
    Returns (cells [Manifold], owners [int], volumes [float mm^3])."""
    cells, owners = [M], [None]
    for n_off in planes:
        cells, owners = _split_cells(cells, owners, n_off[:3], n_off[3])
    owners = [_cell_owner(c, rid, side, tree, lab, k) for c in cells]
    vols = [float(c.volume()) for c in cells]
    if len(cells) > 1:
        owners = _connected_owners(owners, vols, _cell_contacts(_cell_sections(cells, planes)))
    return cells, owners, vols


def _owner_volumes(cis, owners, vols) -> dict:
    """{owner: volume mm^3} of the cells cis (in the order the owners first appear)."""
    per = {}
    for ci in cis:
        per[owners[ci]] = per.get(owners[ci], 0.0) + vols[ci]
    return per


def _regions(cells, planes) -> dict:
    """{sign tuple (one ±1 per plane): [cell index]}: the cells of each region of the plane arrangement."""
    signs = [_signs(c, planes) for c in cells] if len(planes) else [() for _ in cells]
    regions: dict = {}
    for ci, s in enumerate(signs):
        regions.setdefault(s, []).append(ci)
    return regions


def _region_conflict(regions, owners, vols):
    """The first region holding at least CRUMB_MM3 of two parts' cells, as (signs, cells,
    {owner: volume}), or None (slivers are not worth a plane)."""
    for s, cis in regions.items():
        per = _owner_volumes(cis, owners, vols)
        if len(per) > 1 and sorted(per.values())[-2] >= CRUMB_MM3:
            return s, cis, per
    return None


def _separate_regions(cells, owners, vols, planes, rng, warnings) -> tuple[np.ndarray, dict]:
    """Step 3, second half: while a region of the arrangement holds two parts' cells, an extra
    SVM plane between the two largest (at most MAX_EXTRA_PLANES, only while it separates them
    to within 1 %); then each region goes to the part of most volume in it, and what other
    parts had there is warned about.  Returns (planes (p',4) with the extra ones last, {region signs: owner})."""
    extra = 0
    while True:
        regions = _regions(cells, planes)
        conflict = _region_conflict(regions, owners, vols)
        if conflict is None or extra >= MAX_EXTRA_PLANES:
            break
        s, cis, per = conflict
        top = sorted(per, key=per.get, reverse=True)[:2]
        pts = [np.vstack([np.asarray(cells[ci].to_mesh64().vert_properties)[:, :3] for ci in cis
                          if owners[ci] == o]) for o in top]
        n, off, wrong = svm_plane(pts[0], pts[1], rng)
        if wrong > 0.01:
            break  # the two parts' pieces in this region cannot be told apart by a plane
        planes = np.vstack([planes, np.r_[n, off]])
        cells, owners = _split_cells(cells, owners, n, off)
        vols = [float(c.volume()) for c in cells]
        extra += 1
    owner_of: dict = {}
    for s, cis in regions.items():
        per = _owner_volumes(cis, owners, vols)
        best = max(per, key=per.get)
        owner_of[s] = best
        for o, v in per.items():
            if o != best and v >= CRUMB_MM3:
                warnings.append(f"{v:.0f} mm³ of part {o}'s material lies on part {best}'s side of every joint "
                                f"plane and goes with part {best} (a plane crosses the shell twice there)")
    if extra:
        warnings.append(f"{extra} extra cutting plane(s) were needed where a joint plane crosses the shell twice")
    return planes, owner_of


def _half_spaces(M, planes) -> tuple:
    """The bounding box of M (padded by 10 % of its diagonal + 10 mm) and its halves by every
    plane (p,4): (box, {(plane, ±1): half box}, {face id of a cut face: plane index})."""
    lo, hi = np.asarray(M.bounding_box()[:3]), np.asarray(M.bounding_box()[3:])
    pad = 0.1 * float(np.linalg.norm(hi - lo)) + 10.0
    box = m3.Manifold.cube(tuple((hi - lo) + 2 * pad)).translate(tuple(lo - pad))
    box_ids = _ids(box)
    half, plane_of_id = {}, {}
    for p, row in enumerate(planes):
        for s in (1, -1):
            H = box.trim_by_plane(tuple(s * row[:3]), float(-s * row[3]))
            half[(p, s)] = H
            for i in _ids(H) - box_ids:
                plane_of_id[i] = p
    return box, half, plane_of_id


def _cut_parts(M, planes, owner_of, k, report, warnings) -> tuple[list, dict]:
    """Step 4: each part q = M ∩ K_q, K_q the union of the convex polytopes of its region terms
    (`_region_terms`: the box trimmed by half-spaces).  A part that got no region is empty and
    warned about.  Returns ([Manifold] k parts, {face id: plane index})."""
    box, half, plane_of_id = _half_spaces(M, planes)
    part_M = []
    for q in range(k):
        if q not in owner_of.values():
            warnings.append(f"part {q} got no material: its skin area lies on other parts' side of the joint planes")
            part_M.append(m3.Manifold())
            continue
        polys = []
        for t in _region_terms(owner_of, q):
            if not t:
                polys.append(box)
            else:
                hs = [half[(p, s)] for p, s in sorted(t.items())]
                polys.append(hs[0] if len(hs) == 1 else m3.Manifold.batch_boolean(hs, m3.OpType.Intersect))
        K = polys[0] if len(polys) == 1 else m3.Manifold.batch_boolean(polys, m3.OpType.Add)
        part_M.append(M ^ K)
        report(0.4 + 0.3 * (q + 1) / k, f"part {q}")
    # evaluated here, while the last part's polytopes are still held: manifold3d flattens only the
    # boolean nodes nothing else holds, so this decides the parts' triangulation
    for P in part_M:
        P.is_empty()
    return part_M, plane_of_id


def _tidy_parts(part_M, solid_volume, warnings) -> np.ndarray:
    """Step 4, end: slivers under CRUMB_MM3 dropped from the parts (in place), warnings for them,
    for volumes that do not add up to the solid's (VOLUME_RTOL) and for parts in several pieces.
    Returns the plain volumes (k,) mm^3."""
    slivers = []
    for q, P in enumerate(part_M):
        pieces = P.decompose() if not P.is_empty() else []
        small = [c for c in pieces if c.volume() < CRUMB_MM3]
        if small and len(small) < len(pieces):
            big = [c for c in pieces if c.volume() >= CRUMB_MM3]
            part_M[q] = m3.Manifold.compose(big) if len(big) > 1 else big[0]
            slivers += [float(c.volume()) for c in small]
    if slivers:
        warnings.append(f"{len(slivers)} sliver(s) under {CRUMB_MM3:g} mm³ that the joint planes cut off "
                        f"({sum(slivers):.3g} mm³ in all) are left out of the parts")
    plain = np.array([float(P.volume()) for P in part_M])
    kept = solid_volume - sum(slivers)
    if abs(plain.sum() - kept) > VOLUME_RTOL * kept + 1e-6:
        warnings.append(f"the parts' volumes add up to {plain.sum():.1f} mm³, the solid's is {kept:.1f} mm³")
    for q, P in enumerate(part_M):
        if P.is_empty():
            continue
        pieces = sorted((float(c.volume()) for c in P.decompose()), reverse=True)
        if len(pieces) > 1:
            warnings.append(f"part {q} falls into {len(pieces)} pieces ("
                            + ", ".join(f"{v:.0f}" for v in pieces) + " mm³): print them separately or choose "
                            "another number of parts")
    return plain


def _place_connectors(joints, part_M, planes, solid, clearance, connectors, tree, skin_normals, warnings) -> set:
    """Step 5: the main joint of each pair (largest face first) gets its pegs and holes
    (`joints._connect`, parts changed in place) or a note why not.  solid: (V, F, side) of the
    whole solid (wall thickness probe).  Returns the manifold ids of the connectors' faces."""
    conn_ids: set = set()
    keepout: dict = {}
    wall = _wall_probe(*solid)
    for J in sorted(joints, key=lambda J: -J.area_mm2):
        if J.note is not None:  # a second face of a pair: the pair's main joint carries the connectors
            continue
        if not connectors:
            J.note = "connectors not asked for"
            continue
        _connect(J, part_M, planes, clearance, conn_ids, keepout, tree, skin_normals, wall, warnings)
    return conn_ids


def _part_faces(part_M, rid, side, conn_ids) -> tuple:
    """The parts' faces in one array pair: V (n,3), F (m,3), part label (m,) and SIDE_* (m,) of
    each face (the solid's own faces keep their side, cut faces SIDE_CUT, connectors' SIDE_CONNECTOR)."""
    Vs, Fs, labels, sides = [], [], [], []
    base = 0
    for q, P in enumerate(part_M):
        if P.is_empty():
            continue
        Vq, Fq, oid, fid = _faces(P)
        sd = np.full(len(Fq), SIDE_CUT, dtype=np.int8)
        own = oid == rid
        sd[own] = side[np.clip(fid[own], 0, len(side) - 1)]
        sd[np.isin(oid, list(conn_ids))] = SIDE_CONNECTOR
        Vs.append(Vq)
        Fs.append(Fq + base)
        base += len(Vq)
        labels.append(np.full(len(Fq), q, dtype=np.int64))
        sides.append(sd)
    return (np.vstack(Vs) if Vs else np.zeros((0, 3)), np.vstack(Fs) if Fs else np.zeros((0, 3), np.int64),
            np.concatenate(labels) if labels else np.zeros(0, np.int64),
            np.concatenate(sides) if sides else np.zeros(0, np.int8))
