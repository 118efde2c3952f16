"""Closed solids: the one Manifold <-> arrays conversion and the checks of a printable solid.

The volume work (shell, part cuts, pegs, engraving) uses the `manifold3d`
library (a small compiled wheel, numpy its only dependency): its meshes are manifold by
construction and its booleans are exact and robust, so nothing here is hand-written
marching cubes or boolean code.  This module is the only place that converts between
``manifold3d.Manifold`` and the core's arrays; it also holds the SPEC checks of a solid
(closed: every edge has two faces running in opposite directions) and the ray-cast
thickness (SPEC "Printed bolus").

Face classes of a solid (face attribute ``bolus_shell_side`` in Blender):
SIDE_INNER (on the skin, moved out by the clearance), SIDE_OUTER (at the thickness),
SIDE_RIM (the rim wall and the walls of holes), SIDE_CUT (joint faces between parts),
SIDE_CONNECTOR (pegs and their holes).
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

import manifold3d as m3

from ..errors import BolusError

__all__ = [
    "SIDE_INNER", "SIDE_OUTER", "SIDE_RIM", "SIDE_CUT", "SIDE_CONNECTOR", "SIDE_NAMES",
    "to_manifold", "from_manifold", "closed_report", "ray_thickness", "WELD_MM", "weld_short_edges",
]

#: edges shorter than this (mm) are collapsed before a solid is written (`weld_short_edges`): far below
#: any printer's resolution, far above float32 rounding of mm coordinates (~1e-5 mm at 100 mm)
WELD_MM = 1e-3

SIDE_INNER, SIDE_OUTER, SIDE_RIM, SIDE_CUT, SIDE_CONNECTOR = 0, 1, 2, 3, 4
SIDE_NAMES = {SIDE_INNER: "inner", SIDE_OUTER: "outer", SIDE_RIM: "rim", SIDE_CUT: "cut", SIDE_CONNECTOR: "connector"}

_STATUS_TEXT = {
    "NonFiniteVertex": "a vertex has a non-finite (NaN or infinite) coordinate",
    "NotManifold": "it is not a closed manifold (an edge without its opposite twin: a hole, a "
                   "non-manifold edge or inconsistently wound faces)",
    "VertexOutOfBounds": "a triangle refers to a vertex index outside the vertex array",
    "InvalidConstruction": "the construction was invalid",
    "ResultTooLarge": "the result is too large",
}


def _status_name(M) -> str:
    return str(M.status()).split(".")[-1]


def to_manifold(V, F, what: str = "the solid") -> m3.Manifold:
    """Manifold of the closed triangle mesh V (n,3) float, F (m,3) int (outward wound).

    Raises `BolusError` naming the problem (from `closed_report` where the mesh is open or
    non-manifold) when manifold3d refuses it."""
    V = np.ascontiguousarray(np.asarray(V, dtype=np.float64))
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise BolusError(f"{what}: vertices must be (n, 3) and triangles (m, 3), got {V.shape} and {F.shape}")
    if len(F) == 0:
        return m3.Manifold()
    if not np.isfinite(V).all():
        i = int(np.nonzero(~np.isfinite(V).all(axis=1))[0][0])
        raise BolusError(f"{what} has a non-finite coordinate at vertex {i}")
    if F.min() < 0 or F.max() >= len(V):
        raise BolusError(f"{what} has a triangle index outside its {len(V)} vertices")
    M = m3.Manifold(m3.Mesh64(vert_properties=V, tri_verts=np.ascontiguousarray(F, dtype=np.uint64)))
    name = _status_name(M)
    if name != "NoError":
        rep = closed_report(V, F)
        detail = (f"{rep['boundary_edges']} open edge(s), {rep['nonmanifold_edges']} non-manifold edge(s), "
                  f"{rep['inconsistent_edges']} edge(s) with both faces wound the same way")
        raise BolusError(f"{what} is not a closed solid: {_STATUS_TEXT.get(name, name)} ({detail})")
    return M


def from_manifold(M: m3.Manifold) -> tuple[np.ndarray, np.ndarray]:
    """(V (n,3) float64, F (m,3) int64) of a Manifold (outward wound)."""
    mesh = M.to_mesh64()
    V = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3].copy()
    F = np.asarray(mesh.tri_verts, dtype=np.int64).reshape(-1, 3).copy()
    return V, F


def closed_report(V, F) -> dict:
    """SPEC closedness figures of a triangle mesh V (n,3), F (m,3).

    Returns {"closed": every edge has exactly two faces that run along it in opposite
    directions, "boundary_edges", "nonmanifold_edges", "inconsistent_edges" (two faces
    running the same way), "components" (face-connected pieces), "genus" (per the Euler
    characteristic, summed over components as sum(1 - chi_i / 2); None when not closed),
    "volume_mm3" (signed divergence-theorem volume, positive for outward winding)}."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    m = len(F)
    if m == 0:
        return {"closed": False, "boundary_edges": 0, "nonmanifold_edges": 0, "inconsistent_edges": 0,
                "components": 0, "genus": None, "volume_mm3": 0.0}
    n = int(F.max()) + 1
    he = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    lo, hi = he.min(axis=1), he.max(axis=1)
    key = lo * n + hi
    fwd = he[:, 0] < he[:, 1]
    ukey, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    nfwd = np.bincount(inv, weights=fwd, minlength=len(ukey))
    boundary = int(np.sum(cnt == 1))
    nonmanifold = int(np.sum(cnt > 2))
    inconsistent = int(np.sum((cnt == 2) & (nfwd != 1)))
    # face components through shared edges
    order = np.argsort(inv, kind="stable")
    fid = np.repeat(np.arange(m), 3)[order]
    s = inv[order]
    same = s[1:] == s[:-1]
    a, b = fid[:-1][same], fid[1:][same]
    G = coo_matrix((np.ones(len(a)), (a, b)), shape=(m, m))
    ncomp, lab = connected_components(G, directed=False)
    closed = boundary == 0 and nonmanifold == 0 and inconsistent == 0
    genus = None
    if closed:
        # chi = V - E + F per component
        comp_of_edge = lab[fid[np.r_[True, ~same]]]  # first face of each edge (sorted by edge)
        ecount = np.bincount(comp_of_edge, minlength=ncomp)
        fcount = np.bincount(lab, minlength=ncomp)
        vcomp = np.full(n, -1)
        vcomp[F.ravel()] = np.repeat(lab, 3)
        used = vcomp >= 0
        vcount = np.bincount(vcomp[used], minlength=ncomp)
        chi = vcount - ecount + fcount
        genus = int(round(float(np.sum(1 - chi / 2))))
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    vol = float(np.einsum("ij,ij->i", A, np.cross(B, C)).sum() / 6.0)
    return {"closed": bool(closed), "boundary_edges": boundary, "nonmanifold_edges": nonmanifold,
            "inconsistent_edges": inconsistent, "components": int(ncomp), "genus": genus, "volume_mm3": vol}


def ray_thickness(V, F, origins, directions, max_mm, *, min_mm: float = 1e-3, return_points: bool = False):
    """Distance (k,) from each origin (k,3) along its unit direction (k,3) to the first face
    of the closed solid V, F hit beyond ``min_mm`` (1e-3 mm), inf where none within ``max_mm``.

    libigl's AABB tree of the triangles (compiled, all rays in one call): each ray starts
    ``min_mm`` along its direction, so the face it starts on is not hit.  With
    ``return_points`` also returns the hit points (k,3) (NaN where none)."""
    import igl  # the AABB tree (libigl)

    O = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    D = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if len(O) != len(D):
        raise BolusError(f"ray_thickness: {len(O)} origins but {len(D)} directions")
    if not (np.isfinite(O).all() and np.isfinite(D).all()):
        raise BolusError("ray_thickness: an origin or direction is not finite")
    nrm = np.linalg.norm(D, axis=1)
    if np.any(nrm < 1e-12):
        raise BolusError(f"ray_thickness: direction {int(np.argmin(nrm))} is zero")
    D = D / nrm[:, None]
    out = np.full(len(O), np.inf)
    pts = np.full((len(O), 3), np.nan)
    Vc = np.ascontiguousarray(np.asarray(V, dtype=np.float64))
    Fc = np.ascontiguousarray(np.asarray(F, dtype=np.int64).reshape(-1, 3))
    if len(O) and len(Fc):
        tree = igl.AABB()
        tree.init(Vc, Fc)
        start = np.ascontiguousarray(O + min_mm * D)
        face, s, _ = tree.intersect_ray_first(Vc, Fc, start, np.ascontiguousarray(D), float(max_mm) - min_mm)
        hit = (np.asarray(face) >= 0) & np.isfinite(s)
        out[hit] = np.asarray(s)[hit] + min_mm
        pts[hit] = start[hit] + np.asarray(s)[hit, None] * D[hit]
    if return_points:
        return out, pts
    return out


def weld_short_edges(V, F, tol: float = WELD_MM) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Collapse the edges shorter than ``tol`` of a closed solid V (n,3) mm, F (m,3).

    The booleans leave a few sliver triangles whose shortest edge is a few 1e-6 mm: written as
    float32 (Blender's mesh, an STL file) its two ends become one point and a slicer that merges
    equal coordinates sees collapsed triangles.  Every connected group of short edges is merged
    into its lowest vertex (placed at the group's mean), triangles left with fewer than three
    distinct corners are dropped and unused vertices removed.  When the result is not closed
    (`closed_report`; a collapse that would pinch the surface) the input is returned unchanged.
    Returns (V' (n',3), F' (m',3), keep (m,) bool: the input triangles kept, in order).
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    keep_all = np.ones(len(F), dtype=bool)
    if len(F) == 0:
        return V, F, keep_all
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    short = np.einsum("ij,ij->i", V[E[:, 0]] - V[E[:, 1]], V[E[:, 0]] - V[E[:, 1]]) < tol * tol
    if not short.any():
        return V, F, keep_all
    n = len(V)
    S = E[short]
    _, lab = connected_components(coo_matrix((np.ones(len(S)), (S[:, 0], S[:, 1])), shape=(n, n)), directed=False)
    rep = np.full(lab.max() + 1, n, dtype=np.int64)
    np.minimum.at(rep, lab, np.arange(n))
    to = rep[lab]
    W = V.copy()
    grouped = np.bincount(to, minlength=n) > 1
    if grouped.any():
        sums = np.zeros((n, 3))
        np.add.at(sums, to, V)
        W[grouped] = sums[grouped] / np.bincount(to, minlength=n)[grouped][:, None]
    G = to[F]
    keep = (G[:, 0] != G[:, 1]) & (G[:, 1] != G[:, 2]) & (G[:, 0] != G[:, 2])
    used, inv = np.unique(G[keep], return_inverse=True)
    V2, F2 = W[used], inv.reshape(-1, 3)
    if not closed_report(V2, F2)["closed"]:
        return V, F, keep_all
    return V2, F2, keep

