"""Closed solid print parts of a bolus with planar joints and connectors (seed 6.3-6.4.3,
eqs. 6-38..6-40; issue 11 point 2).

`split_solid` takes the closed solid (a `shell.Shell`'s arrays), the skin region it was
built on and a part label per skin triangle (the area-balanced cut of
`print_segmentation`), and returns the solid cut into closed parts:

1. neighbouring parts: skin labels that share a skin edge;
2. common plane of each pair (6.4.3): a linear support vector machine on the two parts'
   skin vertices, x^T W + b = 0 (eqs. 6-38..6-40), W normalised, pointing from the lower
   label to the higher.  We use ``sklearn.svm.LinearSVC`` (the primal of eq. 6-38 with a
   squared hinge, C = 1e3): the hard-margin plane of eq. 6-38 is its large-C limit, it
   costs O(n) per pass on the tens of thousands of vertices of a face region where
   ``SVC(kernel='linear')`` (the dual, eq. 6-39) grows with n^2, and it still returns a
   plane when a wavy border is not exactly separable.  The coordinates are centred and
   scaled by one factor first (an isotropic scaling keeps the maximum-margin plane), so
   LinearSVC's penalty on the intercept does not bias the plane; vertices on the shared
   border belong to both parts and are left out; classes are balanced.
3. cells: the solid split by every plane (``Manifold.split_by_plane``), each connected
   piece (``decompose``) a cell.  A plane reaches beyond its joint and may cross the shell
   elsewhere, so a cell goes to the part whose skin lies under it (area vote of the
   nearest skin triangles of the cell's inner faces; all its faces if it has none); then
   a group of a part's cells cut off from the part's largest group goes to the part it
   shares most plane face with (a sliver along the rim votes for the skin under its outer
   face, which need not be the part it touches).  Every cell lies in one region of the
   plane arrangement (a sign per plane).  Two cells of different parts in one region (a
   plane crossing a strongly curved shell twice) get an extra separating plane (the same
   SVM on their vertices) as long as that helps, at most MAX_EXTRA_PLANES; what is left
   goes with the larger and is warned about.
4. parts: manifold3d cannot glue pieces back together (the union of two halves of a cut
   keeps the cut as a slit), so each part is cut out of the whole solid once:
   part q = solid ∩ K_q, K_q a union of convex polytopes (the bounding box trimmed by
   planes): one per cell region of q grown over all regions that hold no material and
   one more over each two neighbouring regions of q (so no two polytopes of K_q merely
   touch inside the solid).  The parts are closed by construction and their volumes add
   up to the solid's to round-off.  Separate crumbs of the solid and slivers the planes
   cut off, under CRUMB_MM3 each, are left out with a warning (a slicer drops them too);
   a part that still falls into pieces is warned about.
5. joints: the faces two parts share on one plane (2D CrossSections of their cut faces,
   intersected).  The largest face of each pair gets the connectors (`connectors`: sized
   from the wall thickness at the joint, placed near the two ends of the face, each part
   one peg and one hole), or a note (and a warning) why not.

Faces: the solid's faces keep their ``side`` (manifold3d carries the face ids through the
booleans), faces on a joint plane are SIDE_CUT, peg and hole walls SIDE_CONNECTOR.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

import manifold3d as m3

from . import connectors as conn
from .connectors import Connector
from .errors import BolusError
from .solid import SIDE_CONNECTOR, SIDE_CUT, SIDE_INNER, SIDE_OUTER, from_manifold, to_manifold
from .topology import MeshTopology, check_mesh

__all__ = ["Connector", "Joint", "SolidParts", "skin_neighbours", "svm_plane", "split_solid",
           "SVM_C", "MAX_SVM_POINTS", "MAX_EXTRA_PLANES", "MIN_JOINT_AREA"]

SVM_C = 1e3  #: LinearSVC's C on unit-RMS coordinates: close to the hard margin of eq. 6-38
MAX_SVM_POINTS = 5000  #: per class; larger parts are subsampled (rng)
MAX_EXTRA_PLANES = 4  #: separating planes added for cells of two parts in one arrangement region
MIN_JOINT_AREA = 1.0  #: mm^2: a pair touching on less than this gets no connector and no warning (a corner)
WRONG_SIDE_WARN = 0.15  #: warn when a joint plane leaves over 15 % of the two parts' skin vertices on the wrong side
CRUMB_MM3 = 1.0  #: separate pieces of the solid smaller than this are left out (with a warning)
ON_PLANE_TOL = 1e-6  #: mm: a face with all corners this close to a plane lies on it
MIN_CONTACT_AREA = 1e-3  #: mm^2: cells sharing less plane face than this do not touch
VOLUME_RTOL = 1e-6  #: parts' volumes must add up to the solid's to this relative round-off


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


# ----------------------------------------------------------------------------- planes

def skin_neighbours(skin_F, skin_labels, topo: MeshTopology | None = None) -> list[tuple[int, int, int]]:
    """Pairs of part labels (i < j, shared skin edges) whose triangles share a skin edge,
    for skin_F (m,3) and skin_labels (m,)."""
    topo = MeshTopology(np.zeros((int(np.max(skin_F)) + 1, 3)), skin_F) if topo is None else topo
    lab = np.asarray(skin_labels)
    P = topo.face_adjacency_pairs
    a, b = lab[P[:, 0]], lab[P[:, 1]]
    diff = a != b
    pairs = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)[diff]
    if len(pairs) == 0:
        return []
    keys, counts = np.unique(pairs, axis=0, return_counts=True)
    return [(int(i), int(j), int(c)) for (i, j), c in zip(keys, counts)]


def svm_plane(X0, X1, rng=0, C: float = SVM_C) -> tuple[np.ndarray, float, float]:
    """Common plane of two point sets (eqs. 6-38..6-40): X0 (a,3) labelled -1, X1 (b,3) +1.

    Returns (normal (3,) unit pointing to X1's side, offset, wrong fraction of the points on
    the other side); the plane is normal . x + offset = 0.  LinearSVC on centred,
    isotropically scaled points (module doc); each class subsampled to MAX_SVM_POINTS."""
    from sklearn.svm import LinearSVC

    g = np.random.default_rng(rng)
    X0, X1 = np.asarray(X0, dtype=np.float64), np.asarray(X1, dtype=np.float64)
    if len(X0) == 0 or len(X1) == 0:
        raise BolusError("a common plane needs points of both parts")
    S0 = X0 if len(X0) <= MAX_SVM_POINTS else X0[g.choice(len(X0), MAX_SVM_POINTS, replace=False)]
    S1 = X1 if len(X1) <= MAX_SVM_POINTS else X1[g.choice(len(X1), MAX_SVM_POINTS, replace=False)]
    X = np.vstack([S0, S1])
    y = np.r_[-np.ones(len(S0)), np.ones(len(S1))]
    mu = X.mean(axis=0)
    s = float(np.sqrt(np.mean(np.sum((X - mu) ** 2, axis=1)))) or 1.0
    svm = LinearSVC(C=C, dual=False, class_weight="balanced", intercept_scaling=10.0, max_iter=5000, tol=1e-6)
    import warnings as _w

    with _w.catch_warnings():
        _w.simplefilter("ignore")  # ConvergenceWarning on a barely separable border: the plane is still good
        svm.fit((X - mu) / s, y)
    W = svm.coef_.ravel()
    nw = float(np.linalg.norm(W))
    if not nw > 0 or not np.isfinite(nw):
        raise BolusError("the two parts cannot be told apart by a plane (their skin vertices coincide)")
    normal = W / nw
    offset = (float(svm.intercept_[0]) * s - float(W @ mu)) / nw
    wrong = (np.sum(X0 @ normal + offset > 0) + np.sum(X1 @ normal + offset < 0)) / (len(X0) + len(X1))
    return normal, float(offset), float(wrong)


# ----------------------------------------------------------------------------- manifold helpers

def _tracked(V, F) -> tuple[m3.Manifold, int]:
    """Manifold of the closed solid whose faces remember their index in F (face_id) under a
    reserved original id; BolusError (from `solid.to_manifold`) if it is not closed."""
    rid = int(m3.Manifold.reserve_ids(1))
    m = len(F)
    M = m3.Manifold(m3.Mesh64(vert_properties=np.ascontiguousarray(V, dtype=np.float64),
                              tri_verts=np.ascontiguousarray(F, dtype=np.uint64),
                              face_id=np.arange(m, dtype=np.uint64),
                              run_index=np.array([0, 3 * m], dtype=np.uint64),
                              run_original_id=np.array([rid], dtype=np.uint32)))
    if str(M.status()).split(".")[-1] != "NoError" or M.is_empty():
        to_manifold(V, F, "the solid")  # raises, naming the problem
        raise BolusError("the solid could not be turned into a closed manifold (manifold3d refused it)")
    return M, rid


def _faces(M: m3.Manifold):
    """(V (n,3), F (m,3), original id (m,), face id (m,)) of a Manifold."""
    V, F = from_manifold(M)
    mesh = M.to_mesh64()  # the same mesh again, for the runs' original ids and the face ids
    ri = np.asarray(mesh.run_index, dtype=np.int64) // 3
    ro = np.asarray(mesh.run_original_id, dtype=np.int64)
    oid = np.repeat(ro, np.diff(ri)) if len(ro) else np.zeros(len(F), dtype=np.int64)
    fid = np.asarray(mesh.face_id, dtype=np.int64)
    if len(fid) != len(F):
        fid = np.zeros(len(F), np.int64)
    return V, F, oid, fid


def _ids(M: m3.Manifold) -> set:
    return {int(i) for i in np.asarray(M.to_mesh64().run_original_id)}


def _areas_centroids(V, F):
    A, B, Cc = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cr = np.cross(B - A, Cc - A)
    return 0.5 * np.linalg.norm(cr, axis=1), (A + B + Cc) / 3.0, cr


# ----------------------------------------------------------------------------- cells

def _drop_crumbs(M: m3.Manifold, warnings: list) -> m3.Manifold:
    """The solid without separate pieces under CRUMB_MM3 (a slicer drops them anyway), with a warning."""
    comps = M.decompose()
    if len(comps) < 2:
        return M
    vol = [float(c.volume()) for c in comps]
    keep = [c for c, v in zip(comps, vol) if v >= CRUMB_MM3]
    gone = [(c, v) for c, v in zip(comps, vol) if v < CRUMB_MM3]
    if not gone or not keep:
        return M
    at = np.asarray(gone[0][0].bounding_box()).reshape(2, 3).mean(axis=0)
    warnings.append(f"the solid has {len(gone)} separate crumb(s) under {CRUMB_MM3:g} mm³ "
                    f"({sum(v for _, v in gone):.3g} mm³ in all, e.g. at ({at[0]:.1f}, {at[1]:.1f}, {at[2]:.1f}) mm): "
                    "left out of the parts")
    return m3.Manifold.compose(keep) if len(keep) > 1 else keep[0]


def _cell_sections(cells, planes) -> list[dict]:
    """Per cell {plane: CrossSection of its faces on that plane (plane frame)}."""
    out = []
    for c in cells:
        V, F = from_manifold(c)
        D = V @ planes[:, :3].T + planes[:, 3]
        secs = {}
        for p in range(len(planes)):
            on = np.all(np.abs(D[F, p]) < ON_PLANE_TOL, axis=1)
            if on.any():
                origin, U = conn.plane_frame(planes[p, :3], planes[p, 3])
                secs[p] = conn.section_of_triangles(conn.to_plane(V[F[on]].reshape(-1, 3), origin, U).reshape(-1, 3, 2))
        out.append(secs)
    return out


def _cell_contacts(secs: list[dict]) -> dict:
    """{(a, b): area (mm^2) of the plane faces cells a < b share}."""
    contacts = {}
    for a in range(len(secs)):
        for b in range(a + 1, len(secs)):
            area = sum(float((secs[a][p] ^ secs[b][p]).area()) for p in set(secs[a]) & set(secs[b]))
            if area > MIN_CONTACT_AREA:
                contacts[(a, b)] = area
    return contacts


def _connected_owners(owners: list, vols: list, contacts: dict) -> list:
    """Owners changed so every part's cells hang together: a group of a part's cells cut off
    from its largest group goes to the neighbour it shares the most face with (a sliver a
    plane cuts off along the rim votes for the skin under its outer face, which need not
    be the part it touches)."""
    owners = list(owners)
    adj: dict = {i: [] for i in range(len(owners))}
    for (a, b), area in contacts.items():
        adj[a].append((b, area))
        adj[b].append((a, area))
    for _ in range(len(owners)):
        seen, groups = set(), {}
        for i in range(len(owners)):
            if i in seen:
                continue
            stack, comp = [i], []
            seen.add(i)
            while stack:
                x = stack.pop()
                comp.append(x)
                for y, _ in adj[x]:
                    if y not in seen and owners[y] == owners[i]:
                        seen.add(y)
                        stack.append(y)
            groups.setdefault(owners[i], []).append(comp)
        changed = False
        for q, comps in groups.items():
            comps.sort(key=lambda c: -sum(vols[i] for i in c))
            for comp in comps[1:]:
                shared: dict = {}
                for x in comp:
                    for y, area in adj[x]:
                        if owners[y] != q:
                            shared[owners[y]] = shared.get(owners[y], 0.0) + area
                if shared:
                    new = max(shared, key=shared.get)
                    for x in comp:
                        owners[x] = new
                    changed = True
        if not changed:
            break
    return owners


def _split_cells(cells, owners, normal, offset):
    """Cells (list of Manifold) split by one plane into connected pieces; owners inherited."""
    out, own = [], []
    for c, o in zip(cells, owners):
        for piece in c.split_by_plane(tuple(normal), -offset):
            if piece.is_empty():
                continue
            for comp in piece.decompose():
                if comp.volume() > 0:
                    out.append(comp)
                    own.append(o)
    return out, own


def _cell_owner(cell, rid, side, tree, skin_labels, k):
    V, F, oid, fid = _faces(cell)
    areas, cents, _ = _areas_centroids(V, F)
    inner = (oid == rid) & (side[np.clip(fid, 0, len(side) - 1)] == SIDE_INNER)
    use = inner if areas[inner].sum() > 0 else np.ones(len(F), bool)
    _, nearest = tree.query(cents[use])
    votes = np.bincount(skin_labels[nearest], weights=areas[use], minlength=k)
    return int(np.argmax(votes))


def _signs(cell, planes) -> tuple:
    """Side (+1 / -1) of a cell for every plane: the sign at its vertex farthest from the plane
    (the cell lies on one side of each plane it was split by)."""
    V = np.asarray(cell.to_mesh64().vert_properties, dtype=np.float64)[:, :3]
    D = V @ planes[:, :3].T + planes[:, 3]
    far = D[np.argmax(np.abs(D), axis=0), np.arange(len(planes))]
    return tuple(int(x) for x in np.where(far >= 0, 1, -1))


def _expand(term: dict, false_set: list) -> dict:
    """Greedily drop fixed signs from ``term`` {plane: sign} while it covers no sign vector of
    ``false_set``."""
    term = dict(term)

    def covers_false(t):
        return any(all(f[p] == s for p, s in t.items()) for f in false_set)

    for p in sorted(term):
        trial = {q: s for q, s in term.items() if q != p}
        if not covers_false(trial):
            term = trial
    return term


def _region_terms(owner_of: dict, q: int) -> list[dict]:
    """Convex terms whose union is part q's region (module doc, step 4)."""
    true = [s for s, o in owner_of.items() if o == q]
    false = [s for s, o in owner_of.items() if o != q]
    terms = []
    for s in true:
        terms.append(_expand(dict(enumerate(s)), false))
    for a in range(len(true)):
        for b in range(a + 1, len(true)):
            d = [p for p in range(len(true[a])) if true[a][p] != true[b][p]]
            if len(d) == 1:
                t = {p: s for p, s in enumerate(true[a]) if p != d[0]}
                terms.append(_expand(t, false))
    uniq = []
    for t in terms:
        if t not in uniq:
            uniq.append(t)
    # drop terms contained in another (fewer polytopes, same union)
    keep = [t for t in uniq if not any(u is not t and all(t.get(p) == s for p, s in u.items()) and u != t
                                        for u in uniq)]
    return keep


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

    # 1-2: neighbours and their planes
    report(0.05, "common planes")
    pairs = skin_neighbours(skin_F, lab, skin_topo)
    plane_rows, plane_pairs = [], []
    for i, j, _ in pairs:
        vi = np.unique(skin_F[lab == i])
        vj = np.unique(skin_F[lab == j])
        only_i, only_j = np.setdiff1d(vi, vj), np.setdiff1d(vj, vi)
        n, off, wrong = svm_plane(skin_V[only_i if len(only_i) else vi], skin_V[only_j if len(only_j) else vj], rng)
        if wrong > WRONG_SIDE_WARN:
            warnings.append(f"the joint plane between parts {i} and {j} leaves {100 * wrong:.1f} % of their skin "
                            "on the other part's side: their border is far from straight")
        plane_rows.append(np.r_[n, off])
        plane_pairs.append((i, j))
    planes = np.array(plane_rows, dtype=np.float64).reshape(-1, 4)

    # 3: cells and their owners
    report(0.15, "cells")
    tree = cKDTree(skin_topo.centroids)
    cells, owners = [M], [None]
    for n_off in planes:
        cells, owners = _split_cells(cells, owners, n_off[:3], n_off[3])
    owners = [_cell_owner(c, rid, side, tree, lab, k) for c in cells]
    vols = [float(c.volume()) for c in cells]
    if len(cells) > 1:
        owners = _connected_owners(owners, vols, _cell_contacts(_cell_sections(cells, planes)))
    extra = 0
    while True:
        signs = [_signs(c, planes) for c in cells] if len(planes) else [() for _ in cells]
        regions: dict = {}
        for ci, s in enumerate(signs):
            regions.setdefault(s, []).append(ci)
        conflict = None
        for s, cis in regions.items():
            per = {}
            for ci in cis:
                per[owners[ci]] = per.get(owners[ci], 0.0) + vols[ci]
            if len(per) > 1 and sorted(per.values())[-2] >= CRUMB_MM3:  # slivers are not worth a plane
                conflict = (s, cis, per)
                break
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
        per = {}
        for ci in cis:
            per[owners[ci]] = per.get(owners[ci], 0.0) + vols[ci]
        best = max(per, key=per.get)
        owner_of[s] = best
        for o, v in per.items():
            if o != best and v >= CRUMB_MM3:
                warnings.append(f"{v:.0f} mm³ of part {o}'s material lies on part {best}'s side of every joint "
                                f"plane and goes with part {best} (a plane crosses the shell twice there)")
    if extra:
        warnings.append(f"{extra} extra cutting plane(s) were needed where a joint plane crosses the shell twice")

    # 4: parts
    report(0.4, "parts")
    lo, hi = np.asarray(M.bounding_box()[:3]), np.asarray(M.bounding_box()[3:])
    pad = 0.1 * float(np.linalg.norm(hi - lo)) + 10.0
    box = m3.Manifold.cube(tuple((hi - lo) + 2 * pad)).translate(tuple(lo - pad))
    box_ids = _ids(box)
    half = {}
    plane_of_id = {}
    for p, row in enumerate(planes):
        for s in (1, -1):
            H = box.trim_by_plane(tuple(s * row[:3]), float(-s * row[3]))
            half[(p, s)] = H
            for i in _ids(H) - box_ids:
                plane_of_id[i] = p
    part_M = []
    for q in range(k):
        if q not in owner_of.values():
            warnings.append(f"part {q} got no material: its skin area lies on other parts' side of the joint planes")
            part_M.append(m3.Manifold())
            continue
        terms = _region_terms(owner_of, q)
        polys = []
        for t in terms:
            if not t:
                polys.append(box)
            else:
                hs = [half[(p, s)] for p, s in sorted(t.items())]
                polys.append(hs[0] if len(hs) == 1 else m3.Manifold.batch_boolean(hs, m3.OpType.Intersect))
        K = polys[0] if len(polys) == 1 else m3.Manifold.batch_boolean(polys, m3.OpType.Add)
        part_M.append(M ^ K)
        report(0.4 + 0.3 * (q + 1) / k, f"part {q}")
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
    kept = float(M.volume()) - sum(slivers)
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

    # 5: joints and connectors
    report(0.75, "joints")
    joints = _joints(part_M, planes, plane_of_id)
    conn_ids: set = set()
    keepout: dict = {}
    wall = _wall_probe(V, F, side)
    for J in sorted(joints, key=lambda J: -J.area_mm2):
        if J.note is not None:  # a second face of a pair: the pair's main joint carries the connectors
            continue
        if not connectors:
            J.note = "connectors not asked for"
            continue
        _connect(J, part_M, planes, clearance, conn_ids, keepout, tree, skin_topo.face_normals, wall, warnings)
    report(0.95, "faces")
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
    report(1.0, "done")
    return SolidParts(
        V=np.vstack(Vs) if Vs else np.zeros((0, 3)), F=np.vstack(Fs) if Fs else np.zeros((0, 3), np.int64),
        labels=np.concatenate(labels) if labels else np.zeros(0, np.int64),
        side=np.concatenate(sides) if sides else np.zeros(0, np.int8),
        volumes_mm3=np.array([float(P.volume()) for P in part_M]), joints=sorted(joints, key=lambda J: J.parts),
        warnings=warnings, plain_volumes_mm3=plain, solid_volume_mm3=solid_volume, planes=planes)


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
