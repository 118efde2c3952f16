"""Exact one-sided distance field of an open skin region, for the bolus shell.

The shell is the set where

    f(x) = min( sd(x) - c,  t - sd(x),  r(x) )  > 0                                  (field)

* ``sd``: the signed distance to the skin triangles, the exact point-triangle distance (Ericson's
  closest point, vectorised), signed by ``(x - foot) . n`` with n the pseudo-normal of the foot's
  feature (Baerentzen & Aanaes 2005: face, edge or angle-weighted vertex normal);
* ``c`` the clearance (inner face), ``t`` the thickness (outer face), both mm from the skin;
* ``r`` closes the rim: where the foot lies on a border edge or vertex (exact, from the
  barycentrics), r = -(lateral distance of x from the border's normal line); elsewhere the
  foot's distance to the border, capped at a few voxels.  Hole borders get the same wall.

The nearest triangle comes from libigl's AABB tree (compiled, exact); Ericson's closest point on
that one triangle then gives the barycentrics with exact zeros on edges and vertices.
Arrays: V (n,3) float64 mm, F (m,3) int64, query points X (k,3).

Design notes: docs/design/solid.md.
"""
from __future__ import annotations

import numpy as np
import igl  # the AABB tree: exact nearest triangles, compiled
from scipy.spatial import cKDTree

from ..mesh.boundary import boundary_loops
from ..mesh.topology import MeshTopology, corner_angles

__all__ = ["closest_on_triangles", "SkinDistance", "HOLE_FRACTION", "ACROSS_COS"]

#: a border loop other than the outer one is an END, open like the outer rim, when both hold:
#: its membrane's vector area is at least HOLE_FRACTION of the largest loop's, and the skin
#: stands across that membrane (the mean |n . m| of the skin's vertex normals n along the loop
#: against the membrane's unit vector area m is under ACROSS_COS): the far end of a sleeve round
#: a knee or an elbow.  Every other loop is a HOLE (a channel is cut through the bolus): a
#: nostril, an eye, a stoma, the top of a dome cut open, where the skin would run on over the
#: membrane.  (A vector area needs no plane: it is the same for every surface the loop bounds.)
HOLE_FRACTION = 0.2
ACROSS_COS = 0.5


def closest_on_triangles(p, a, b, c):
    """Closest points on triangles (a, b, c) (k,3) to points p (k,3) (Ericson 5.1.5).

    Returns q (k,3) and barycentrics u, v, w (k,) with q = u a + v b + w c; on an edge or a
    vertex region the other coordinates are exactly 0."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v = vb / den
        w = vc / den
        m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)  # edge BC
        wbc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        v = np.where(m, 1 - wbc, v)
        w = np.where(m, wbc, w)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)  # edge AC
        wac = d2 / (d2 - d6)
        v = np.where(m, 0.0, v)
        w = np.where(m, wac, w)
        m = (d6 >= 0) & (d5 <= d6)  # vertex C
        v = np.where(m, 0.0, v)
        w = np.where(m, 1.0, w)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)  # edge AB
        vab = d1 / (d1 - d3)
        v = np.where(m, vab, v)
        w = np.where(m, 0.0, w)
        m = (d3 >= 0) & (d4 <= d3)  # vertex B
        v = np.where(m, 1.0, v)
        w = np.where(m, 0.0, w)
        m = (d1 <= 0) & (d2 <= 0)  # vertex A
        v = np.where(m, 0.0, v)
        w = np.where(m, 0.0, w)
    v = np.nan_to_num(v)
    w = np.nan_to_num(w)
    u = 1.0 - v - w
    q = a * u[:, None] + b * v[:, None] + c * w[:, None]
    return q, u, v, w


class SkinDistance:
    """Exact nearest-point queries and the shell field (module docstring) on a skin region.

    V (n,3), F (m,3) an open, consistently wound, non-degenerate region (checked by the
    caller).  Attributes: vn (n,3) unit area-weighted vertex normals, loops (list of border
    vertex loops, outer one first: the one enclosing the most area along the mean normal),
    rim_tree (KD-tree of border samples every 0.05 mm), aabb (libigl's AABB tree of the triangles),
    area (float mm^2).
    """

    def __init__(self, V, F):
        self.V = V
        self.F = F
        self.topo = MeshTopology(V, F)
        self.A, self.B, self.C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
        fn = self._normals()
        self.vtree = cKDTree(V)
        self._pseudo_normals()
        self._border()
        self._order_loops(fn.sum(axis=0))
        self._rim_samples()
        self._triangle_trees()

    def _normals(self) -> np.ndarray:
        """Sets area (mm^2), fn (m,3) unit face normals and vn (n,3) unit area-weighted vertex
        normals; returns the unnormalised face normals (m,3) (length: twice the area)."""
        V, F, A = self.V, self.F, self.A
        fn = np.cross(self.B - A, self.C - A)
        dbl = np.linalg.norm(fn, axis=1)
        self.area = float(0.5 * dbl.sum())
        self.fn = fn / dbl[:, None]
        vn = np.zeros_like(V)
        for j in range(3):
            np.add.at(vn, F[:, j], fn)
        ln = np.linalg.norm(vn, axis=1)
        ln[ln == 0] = 1.0
        self.vn = vn / ln[:, None]
        return fn

    def _pseudo_normals(self) -> None:
        """Pseudo-normals for the sign (Baerentzen & Aanaes 2005): the face normal inside a face,
        the sum of the two face normals on an edge (edge_pn (m,3,3): edge opposite corner j), the
        angle-weighted normal at a vertex (vn_angle (n,3))."""
        V, F, topo = self.V, self.F, self.topo
        ang = corner_angles(V, F)
        van = np.zeros_like(V)
        for j in range(3):
            np.add.at(van, F[:, j], self.fn * ang[:, j:j + 1])
        self.vn_angle = van
        ef = topo.edge_faces[topo.face_edges]  # (m,3,2): faces on edge F[j] -> F[j+1]
        other = np.where(ef[:, :, 0] == np.arange(len(F))[:, None], ef[:, :, 1], ef[:, :, 0])  # (m,3), -1 on border
        en = self.fn[:, None, :] + np.where(other[:, :, None] >= 0, self.fn[np.maximum(other, 0)], 0.0)
        self.edge_pn = np.stack([en[:, 1], en[:, 2], en[:, 0]], axis=1)  # (m,3,3): edge opposite corner j

    def _border(self) -> None:
        """Border flags: fborder (m,3) of the edge opposite corner j, vborder (n,) per vertex, and
        border_edges (b,2) vertex pairs."""
        topo = self.topo
        be = topo.boundary_edges[topo.face_edges]  # (m,3): edge F[j] -> F[j+1]
        self.fborder = np.stack([be[:, 1], be[:, 2], be[:, 0]], axis=1)  # opposite corner j
        self.vborder = topo.boundary_vertices
        self.border_edges = topo.edges[topo.boundary_edges]

    def _order_loops(self, mean_n) -> None:
        """loops, loop_lengths (mm), loop_areas (mm^2): the border loops, outer one first.  The
        outer loop encloses the most area seen along the region's mean normal mean_n (3,) (the
        longest loop is not it where a border zigzags along whole faces: a dome's cut top).
        outer_loops: the first loop of each island (edge-connected piece of the region); hole_loops
        / end_loops: the other loops split by `HOLE_FRACTION` (against the largest membrane of
        their island) and `ACROSS_COS` (membrane_areas mm^2, loop_along: mean |n . m| along each
        loop)."""
        V = self.V
        loops = boundary_loops(self.F, self.topo)
        lengths = [float(np.linalg.norm(V[lp] - V[np.roll(lp, -1)], axis=1).sum()) for lp in loops]
        mean_n = mean_n / max(float(np.linalg.norm(mean_n)), 1e-300)
        enclosed = [abs(float(np.cross(V[lp], V[np.roll(lp, -1)]).sum(axis=0) @ mean_n)) / 2 for lp in loops]
        order = sorted(range(len(loops)), key=lambda i: (enclosed[i], lengths[i]), reverse=True)
        self.loops = [loops[i] for i in order]
        self.loop_lengths = [lengths[i] for i in order]
        self.loop_areas = [enclosed[i] for i in order]
        # the membrane's vector area of each loop (the same for every surface spanning it)
        vec = [np.cross(V[lp], V[np.roll(lp, -1)]).sum(axis=0) / 2 for lp in self.loops]
        membrane = [float(np.linalg.norm(v)) for v in vec]
        self.membrane_areas = membrane
        # how far the skin along each loop runs on over its membrane (1: in its plane, 0: across)
        self.loop_along = [float(np.abs(self.vn[lp] @ (v / max(a, 1e-300))).mean())
                           for lp, v, a in zip(self.loops, vec, membrane)]
        # each island (edge-connected piece of the region) has its own outer loop, its first loop
        # in this order; the other loops are judged against the largest membrane of their island
        _, comp = self.topo.face_components()
        vface = np.full(len(V), -1, dtype=np.int64)
        vface[self.F.ravel()] = np.repeat(comp, 3)
        island = [int(vface[lp[0]]) for lp in self.loops]
        big: dict = {}
        for i, a in zip(island, membrane):
            big[i] = max(big.get(i, 0.0), a)
        outer, seen = [], set()
        for i in island:
            outer.append(i not in seen)
            seen.add(i)
        self.outer_loops = [lp for lp, o in zip(self.loops, outer) if o]
        end = [a >= HOLE_FRACTION * big[i] and c < ACROSS_COS for a, c, i in zip(membrane, self.loop_along, island)]
        self.hole_loops = [lp for lp, e, o in zip(self.loops, end, outer) if not (e or o)]
        self.end_loops = [lp for lp, e, o in zip(self.loops, end, outer) if e and not o]

    def _rim_samples(self) -> None:
        """rim_pts (s,3): the border edges sampled every 0.05 mm (one far point when the region
        has no border), and their KD-tree rim_tree."""
        V = self.V
        if len(self.border_edges):
            P, Q = V[self.border_edges[:, 0]], V[self.border_edges[:, 1]]
            n = np.maximum(2, np.ceil(np.linalg.norm(Q - P, axis=1) / 0.05).astype(int) + 1)
            s = np.concatenate([np.linspace(0.0, 1.0, k) for k in n])
            e = np.repeat(np.arange(len(P)), n)
            self.rim_pts = P[e] * (1 - s)[:, None] + Q[e] * s[:, None]
        else:
            self.rim_pts = np.full((1, 3), 1e12)
        self.rim_tree = cKDTree(self.rim_pts)

    def _triangle_trees(self) -> None:
        """cent_tree: a KD-tree of the triangle centres (fast band tests far from the skin, where a
        tree of a dense sheet is slow to query); aabb: libigl's AABB tree of the triangles for the
        exact nearest point.  tri_rmax: the largest triangle radius about its centre (mm)."""
        A, B, C = self.A, self.B, self.C
        cent = (A + B + C) / 3.0
        rad = np.max(np.linalg.norm(np.stack([A, B, C]) - cent[None], axis=2), axis=0)
        self.cent = cent
        self.cent_tree = cKDTree(cent)
        self.tri_rmax = float(rad.max())
        self._Vc = np.ascontiguousarray(self.V, dtype=np.float64)
        self._Fc = np.ascontiguousarray(self.F, dtype=np.int64)
        self.aabb = igl.AABB()
        self.aabb.init(self._Vc, self._Fc)

    # ------------------------------------------------------------------ nearest
    def nearest(self, X, chunk: int = 200_000):
        """Nearest skin point of X (k,3): distance (k,), foot (k,3), face (k,), barycentrics (k,3).

        Exact: the face from the AABB tree, the foot and barycentrics from Ericson's closest point
        on it (on an edge or a vertex the other coordinates are exactly 0, which `terms` uses for
        the sign and the rim)."""
        X = np.ascontiguousarray(np.asarray(X, dtype=np.float64).reshape(-1, 3))
        n = len(X)
        D = np.empty(n)
        Q = np.empty((n, 3))
        FI = np.empty(n, dtype=np.int64)
        BC = np.empty((n, 3))
        for s in range(0, n, chunk):
            x = X[s:s + chunk]
            _, f, _ = self.aabb.squared_distance(self._Vc, self._Fc, x)
            f = np.asarray(f, dtype=np.int64)
            q, u, v, w = closest_on_triangles(x, self.A[f], self.B[f], self.C[f])
            D[s:s + chunk] = np.linalg.norm(x - q, axis=1)
            Q[s:s + chunk], FI[s:s + chunk] = q, f
            BC[s:s + chunk] = np.stack([u, v, w], axis=1)
        return D, Q, FI, BC

    # ------------------------------------------------------------------ field
    def terms(self, X, thickness: float, clearance: float, rim_cap: float):
        """The three terms of the field at X (k,3): (sd - c, t - sd, r), each (k,)."""
        d, Q, FI, BC = self.nearest(X)
        Fv = self.F[FI]
        N = (self.vn[Fv[:, 0]] * BC[:, :1] + self.vn[Fv[:, 1]] * BC[:, 1:2] + self.vn[Fv[:, 2]] * BC[:, 2:3])
        ln = np.linalg.norm(N, axis=1)
        ln[ln == 0] = 1.0
        N /= ln[:, None]
        diff = X - Q
        h = np.einsum("ij,ij->i", diff, N)
        # sign from the pseudo-normal of the foot's feature (exact zeros / ones from Ericson)
        PN = self.fn[FI].copy()
        for j in range(3):
            on_e = BC[:, j] == 0.0
            PN[on_e] = self.edge_pn[FI[on_e], j]
        for j in range(3):
            on_v = BC[:, j] == 1.0
            PN[on_v] = self.vn_angle[Fv[on_v, j]]
        sd = np.where(np.einsum("ij,ij->i", diff, PN) >= 0, d, -d)
        eps = 1e-9
        on_rim = np.zeros(len(X), dtype=bool)
        for j in range(3):
            on_rim |= (BC[:, j] < eps) & self.fborder[FI, j]
            on_rim |= (BC[:, j] > 1 - eps) & self.vborder[Fv[:, j]]
        lat = np.linalg.norm(diff - h[:, None] * N, axis=1)
        drim = np.full(len(X), rim_cap)
        near = ~on_rim
        if near.any():
            dr, _ = self.rim_tree.query(Q[near], workers=2, distance_upper_bound=rim_cap)
            drim[near] = np.minimum(dr, rim_cap)
        r = np.where(on_rim, -lat, drim)
        return sd - clearance, thickness - sd, r

    def field(self, X, thickness: float, clearance: float, rim_cap: float):
        """f(X) (k,) of the module docstring: positive inside the shell."""
        a, b, r = self.terms(X, thickness, clearance, rim_cap)
        return np.minimum(np.minimum(a, b), r)
