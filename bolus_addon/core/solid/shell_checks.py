"""The bolus shell checked and cleaned: hole cutters, thickness, collisions with the rest of the body, border ears, crumbs, topology warnings."""
from __future__ import annotations

import manifold3d as m3
import numpy as np

from ..mesh.topology import as_mesh_arrays
from .manifold import SIDE_INNER, from_manifold, ray_thickness, to_manifold, weld_short_edges

#: skin of the rest of the body deeper than this (or one voxel) inside the shell is a collision
COLLISION_TOL_MM = 1.0


#: pieces of the solid below this fraction of the largest one's volume are dropped (crumbs)
KEEP_PIECE_FRACTION = 0.02


# ---------------------------------------------------------------------------- holes
def _hole_cutter(skin, loop, below, above, radius):
    """Cutter of one hole: its loop triangulated in the best-fit plane (the membrane), swept
    from -below to +above along each loop vertex's channel direction (the mean of the skin's
    vertex normals within ``radius``: the border normals themselves converge at a rolled-in
    edge such as the lips), as a union of convex hulls (valid wherever the directions meet).
    Returns (Manifold, area of the membrane mm^2, perimeter mm)."""
    P = skin.V[loop]
    near = skin.vtree.query_ball_point(P, radius)
    N = np.array([skin.vn[ix].sum(axis=0) for ix in near])
    N /= np.maximum(np.linalg.norm(N, axis=1), 1e-12)[:, None]
    c = P.mean(axis=0)
    n = N.mean(axis=0)
    if np.linalg.norm(n) < 1e-9:
        n = np.linalg.svd(P - c)[2][2]
    n /= np.linalg.norm(n)
    a = np.cross(n, [1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.cross(n, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    xy = np.stack([(P - c) @ a, (P - c) @ b], axis=1)
    area2 = float(np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]))
    idx = np.arange(len(loop))
    if area2 < 0:
        xy, idx = xy[::-1], idx[::-1]
    tris = np.asarray(m3.triangulate([np.ascontiguousarray(xy)]), dtype=np.int64).reshape(-1, 3)
    tris = idx[tris]
    lo = P - below * N
    hi = P + above * N
    hulls = [m3.Manifold.hull_points(np.concatenate([lo[t], hi[t]]).tolist()) for t in tris]
    cutter = m3.Manifold.batch_boolean(hulls, m3.OpType.Add) if hulls else m3.Manifold()
    T = P[tris]
    area = 0.0
    if len(tris):
        area = float(0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1).sum())
    perim = float(np.linalg.norm(P - np.roll(P, -1, axis=0), axis=1).sum())
    return cutter, area, perim


# ---------------------------------------------------------------------------- checks
def _vertex_normals(V, F):
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    vn = np.zeros_like(V)
    for j in range(3):
        np.add.at(vn, F[:, j], fn)
    ln = np.linalg.norm(vn, axis=1)
    ln[ln == 0] = 1.0
    return vn / ln[:, None]


def _measure_thickness(skin, M, V, F, side, t, c, res, max_rays=1500):
    """SPEC thickness: rays from inner-face points (vertices and triangle centroids) along the
    inner face's normal (into the material) to the outer face, on points farther than t from the
    rim.
    Returns (thicknesses of the rays that exit through the outer face, counts {"rays",
    "outer", "skin": met the inner face again across a valley or cavity the bolus fills (beside
    the nose, a nostril pocket), "wall": left through the rim or a hole channel, "none": no hit
    (an origin in a crease whose normal points out of the material)}, spot of the minimum)."""
    inner = side == SIDE_INNER
    if not inner.any():
        return np.zeros(0), {"rays": 0, "outer": 0, "skin": 0, "wall": 0, "none": 0}, None
    Fi = F[inner]
    vn = _vertex_normals(V, Fi)  # outward normal of the inner face points into the body
    verts = np.unique(Fi)
    verts = verts[np.linalg.norm(vn[verts], axis=1) > 0.5]  # a crease's faces can cancel: no normal there
    # the inner face's points: its vertices with their normals and its triangles' centroids with
    # theirs (where coplanar triangles were merged, a face of the skin has vertices only at its
    # corners, near the rim on a coarse skin)
    fn = np.cross(V[Fi[:, 1]] - V[Fi[:, 0]], V[Fi[:, 2]] - V[Fi[:, 0]])
    big = np.linalg.norm(fn, axis=1) > 1e-12
    P = np.concatenate([V[verts], V[Fi[big]].mean(axis=1)])
    N = np.concatenate([vn[verts], fn[big] / np.linalg.norm(fn[big], axis=1)[:, None]])
    if len(P) == 0:
        return np.zeros(0), {"rays": 0, "outer": 0, "skin": 0, "wall": 0, "none": 0}, None
    # bounded: a point beyond t reads inf, and the tree stops early (unbounded, the query of a
    # 757k-triangle shell's inner vertices against a long rim took seconds)
    drim, _ = skin.rim_tree.query(P, workers=2, distance_upper_bound=t)
    cand = np.nonzero(~np.isfinite(drim))[0]
    if len(cand) == 0:
        cand = np.nonzero(drim >= np.max(drim) * 0.5)[0]
    if len(cand) > max_rays:
        cand = cand[np.linspace(0, len(cand) - 1, max_rays).round().astype(int)]
    O = P[cand]
    D = -N[cand]
    L = 5.0 * t + 2 * res  # along the normal a filled valley is up to 4 t thick
    dist, pts = ray_thickness(V, F, O, D, L, min_mm=1e-3, return_points=True)
    hit = np.isfinite(dist)
    outer = np.zeros(len(dist), dtype=bool)
    again = np.zeros(len(dist), dtype=bool)
    if hit.any():
        a, b, _ = skin.terms(pts[hit], t, c, 3 * res)
        tol = max(res, 0.05 * t)
        outer[np.nonzero(hit)[0]] = np.abs(b) < tol
        again[np.nonzero(hit)[0]] = (np.abs(a) < tol) & (np.abs(b) >= tol)
    th = dist[outer]
    spot = O[outer][np.argmin(th)] if len(th) else None
    counts = {"rays": len(dist), "outer": int(outer.sum()), "skin": int(again.sum()),
              "wall": int(np.sum(hit & ~outer & ~again)), "none": int(np.sum(~hit))}
    return th, counts, spot


def _inside(M, P, reach):
    """(k,) bool: points P (k,3) inside the closed Manifold M (odd number of crossings along
    at least two of three skew rays of length ``reach``)."""
    dirs = np.array([[0.5773, 0.5774, 0.5775], [-0.6, 0.48, 0.64], [0.36, -0.8, 0.48]])
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    votes = np.zeros(len(P), dtype=int)
    for d in dirs:
        for i, p in enumerate(P):
            votes[i] += len(M.ray_cast(tuple(p), tuple(p + reach * d))) % 2
    return votes >= 2


def _collision(skin, others, t, c, res, M):
    """Points of the rest of the skin (vertices, edge midpoints, centroids) deeper than
    COLLISION_TOL_MM (or one voxel) inside the shell's field (a fold of the skin just beyond the
    region's border dips into the rim zone by a fraction of a millimetre: not a collision) and
    inside the finished solid M (the hole channels are cut out of it): (count, deepest depth mm,
    spot (3,)) or (0, 0, None)."""
    V2, F2 = as_mesh_arrays(*others)
    pts = [V2]
    if len(F2):
        A, B, C = V2[F2[:, 0]], V2[F2[:, 1]], V2[F2[:, 2]]
        pts += [(A + B + C) / 3, (A + B) / 2, (B + C) / 2, (C + A) / 2]
    P = np.concatenate(pts)
    lo = skin.V.min(axis=0) - t - res
    hi = skin.V.max(axis=0) + t + res
    P = P[np.all((P >= lo) & (P <= hi), axis=1)]
    if len(P) == 0:
        return 0, 0.0, None
    d0, _ = skin.cent_tree.query(P, k=1, distance_upper_bound=t + skin.tri_rmax + res, workers=2)
    P = P[np.isfinite(d0)]
    if len(P) == 0:
        return 0, 0.0, None
    f = skin.field(P, t, c, 3 * res)
    tol = max(res, COLLISION_TOL_MM)
    cand = np.nonzero(f > tol)[0]
    if len(cand) == 0:
        return 0, 0.0, None
    cand = cand[np.argsort(-f[cand])][:200]  # the deepest ones
    reach = 2.0 * float(np.linalg.norm(skin.V.max(axis=0) - skin.V.min(axis=0))) + 4 * t
    ins = cand[_inside(M, P[cand], reach)]
    if len(ins) == 0:
        return 0, 0.0, None
    k = ins[int(np.argmax(f[ins]))]
    return len(ins), float(f[k]), P[k]


def drop_border_ears(F, max_fraction=0.25):
    """(F' (m',3), dropped): the region without its border 'ears', triangles with two border
    edges.  A border cut along whole triangles zigzags (a saw of such teeth, finer than a voxel),
    and the rim wall swept along that saw leaves tiny tunnels in the meshed solid; without the teeth
    the border runs along the next row's edges.  One pass only (a smooth border has no ears, a
    region of a few triangles keeps them: nothing is dropped when more than `max_fraction` of the
    triangles are ears or when a vertex would be left with no triangle of the border's row)."""
    F = np.asarray(F)
    if len(F) < 8:
        return F, 0
    from ..mesh.boundary import _topology_of_faces, boundary_loops

    topo = _topology_of_faces(F)
    border = topo.boundary_edges[topo.face_edges]  # (m,3): is each edge of each face a border edge
    ear = border.sum(axis=1) >= 2
    if not ear.any() or ear.sum() > max_fraction * len(F) or border.sum(axis=1).max() == 3:
        return F, 0
    kept = F[~ear]
    before, after = boundary_loops(F, topo), boundary_loops(kept)
    if len(after) != len(before) or len(np.unique(np.concatenate(after))) != sum(len(x) for x in after):
        return F, 0  # the saw's removal would split a loop or pinch a vertex: keep the teeth
    return kept, int(ear.sum())


def _topology_warnings(skin, M) -> list[str]:
    """A warning when the solid's topology is not the region's thickened: a thickened surface S
    has Euler characteristic 2 chi(S) (a disk with h holes -> a solid with h tunnels), so a
    difference counts tunnels the mesher added (a border zigzagging along whole faces finer
    than the resolution leaves tiny ones at the rim) or holes it closed over.  skin: the
    region's SkinDistance (its MeshTopology gives V - E + F); M: the solid (manifold3d's genus is
    1 - chi / 2 over the whole mesh)."""
    topo = skin.topo
    want = 2 * (int(topo.used_vertices.sum()) - len(topo.edges) + topo.m)
    got = 2 - 2 * int(M.genus())
    if got == want:
        return []
    extra = (want - got) // 2
    if extra > 0:
        return [f"the bolus has {extra} more tunnel(s) through it than the region has holes (Euler characteristic "
                f"{got}, {want} expected): tiny openings at the rim where the border zigzags along whole faces, "
                "finer than the resolution; check the rim, or select the area with Select Treatment Area (a smooth "
                "border) or choose a finer resolution"]
    return [f"the bolus has {-extra} fewer tunnel(s) than the region has holes, or more separate pieces (Euler "
            f"characteristic {got}, {want} expected): a hole may be closed over; check the holes"]


def _drop_crumbs(M):
    """(M without pieces below KEEP_PIECE_FRACTION of the largest one's volume, dropped volumes)."""
    comps = M.decompose()
    if len(comps) <= 1:
        return M, []
    vols = np.array([p.volume() for p in comps])
    keep = vols >= KEEP_PIECE_FRACTION * vols.max()
    kept = [p for p, k in zip(comps, keep) if k]
    M = m3.Manifold.batch_boolean(kept, m3.OpType.Add) if len(kept) > 1 else kept[0]
    return M, [float(v) for v in vols[~keep]]


#: mm: edges shorter than this are collapsed first (`manifold.weld_short_edges`)
SLIVER_TOL_MM = 1e-3


def _clean(M):
    """Slivers collapsed, crumbs dropped, and the arrays made stable.

    Marching cubes leaves tiny triangles where the surface passes within a hair of a lattice
    point, and a boolean with a hole channel can then leave two of them 1e-5 mm apart, which
    Blender's BVH overlap test (the 3D-Print Toolbox's intersection check) reports as
    intersecting: edges shorter than `SLIVER_TOL_MM` are collapsed (a `Manifold.simplify` to a
    micrometre, as before, also collapsed triangles across the skin's folds, and the tilted
    triangles crossed each other: 2 to 7 pairs on the bench regions at 0.5 mm; the marched
    solid's coplanar triangles are merged in `grid` to `COPLANAR_TOL_MM`, before the holes and the
    creases, since merging after them pulls crease vertices off their crease).  manifold3d's
    output can also hold coincident vertices that it collapses when the arrays are read back,
    which can pinch off more crumbs, so round-trip until reading back changes nothing.
    Returns (Manifold, V, F, dropped volumes, pieces)."""
    V, F = from_manifold(M)
    V2, F2, _ = weld_short_edges(V, F, SLIVER_TOL_MM)
    if len(F2) != len(F):
        M = to_manifold(V2, F2, "the shell")
    dropped = []
    for _ in range(4):
        M, d = _drop_crumbs(M)
        dropped += d
        V, F = from_manifold(M)
        back = to_manifold(V, F, "the shell")
        stable = back.num_tri() == len(F) and len(back.decompose()) == len(M.decompose())
        M = back  # read back from arrays: ray casts on it are fast (on a boolean's result each one took ms)
        if stable:
            break
    return M, V, F, dropped, len(M.decompose())
