"""The common planes of neighbouring print parts and the cells they cut the solid into
(seed 6.4.3, eqs. 6-38..6-40; steps 1-3 and the region terms of step 4 of `parts.split_solid`).

`skin_neighbours`: label pairs sharing a skin edge; `svm_plane`: their plane x^T W + b = 0
by a linear SVM (LinearSVC; why: docs/design/solid.md).  The private helpers split
a manifold3d solid by planes into cells (connected pieces), give each cell its owner part
and its side of every plane, and write a part's region of the plane arrangement as convex
terms {plane: sign}; `_tracked` / `_faces` carry the solid's face ids through the booleans.
"""
from __future__ import annotations

import numpy as np

import manifold3d as m3

from . import connectors as conn
from ..errors import BolusError
from .manifold import SIDE_INNER, from_manifold, to_manifold
from ..mesh.topology import MeshTopology

__all__ = ["skin_neighbours", "svm_plane", "SVM_C", "MAX_SVM_POINTS"]

SVM_C = 1e3  #: LinearSVC's C on unit-RMS coordinates: close to the hard margin of eq. 6-38
MAX_SVM_POINTS = 5000  #: per class; larger parts are subsampled (rng)
CRUMB_MM3 = 1.0  #: separate pieces of the solid smaller than this are left out (with a warning)
ON_PLANE_TOL = 1e-6  #: mm: a face with all corners this close to a plane lies on it
MIN_CONTACT_AREA = 1e-3  #: mm^2: cells sharing less plane face than this do not touch


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
