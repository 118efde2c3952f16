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

Nearest triangles come from a KD-tree of sub-triangle centres (pieces of radius <= ``sub_radius``
mm): exact, or farther than the true nearest by at most sub_radius.
Arrays: V (n,3) float64 mm, F (m,3) int64, query points X (k,3).

Design notes: docs/design/solid.md.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..mesh.boundary import boundary_loops
from ..mesh.topology import MeshTopology, corner_angles

__all__ = ["closest_on_triangles", "SkinDistance"]


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
    rim_tree (KD-tree of border samples every 0.05 mm), rmax (largest sub-triangle radius),
    area (float mm^2).
    """

    def __init__(self, V, F, sub_radius: float = 1.0):
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
        self._triangle_trees(sub_radius)
        self.kd_eps = 0.0

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
        longest loop is not it where a border zigzags along whole faces: a dome's cut top)."""
        V = self.V
        loops = boundary_loops(self.F, self.topo)
        lengths = [float(np.linalg.norm(V[lp] - V[np.roll(lp, -1)], axis=1).sum()) for lp in loops]
        mean_n = mean_n / max(float(np.linalg.norm(mean_n)), 1e-300)
        enclosed = [abs(float(np.cross(V[lp], V[np.roll(lp, -1)]).sum(axis=0) @ mean_n)) / 2 for lp in loops]
        order = sorted(range(len(loops)), key=lambda i: (enclosed[i], lengths[i]), reverse=True)
        self.loops = [loops[i] for i in order]
        self.loop_lengths = [lengths[i] for i in order]
        self.loop_areas = [enclosed[i] for i in order]

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

    def _triangle_trees(self, sub_radius: float) -> None:
        """KD-trees of the triangle centres (cent_tree: fast band tests far from the skin, where a
        tree of a dense sheet is slow to query) and of sub-triangle centres (tree over sub_pts
        (s,3), owner triangle sub_owner (s,)): each triangle split regularly into k^2 pieces of
        radius <= sub_radius mm.  tri_rmax, rmax: the largest triangle and piece radius (mm)."""
        A, B, C = self.A, self.B, self.C
        cent = (A + B + C) / 3.0
        rad = np.max(np.linalg.norm(np.stack([A, B, C]) - cent[None], axis=2), axis=0)
        self.cent = cent
        self.cent_tree = cKDTree(cent)
        self.tri_rmax = float(rad.max())
        ks = np.maximum(1, np.ceil(rad / sub_radius)).astype(int)
        pts, owner = [cent[ks == 1]], [np.nonzero(ks == 1)[0]]
        radii = [rad[ks == 1]]
        for k in np.unique(ks[ks > 1]):
            sel = np.nonzero(ks == k)[0]
            # centres of the k^2 sub-triangles of a regular split
            ij = [(i, j) for i in range(k) for j in range(k - i)]
            bc = [((i + 1 / 3) / k, (j + 1 / 3) / k) for i, j in ij] + \
                 [((i + 2 / 3) / k, (j + 2 / 3) / k) for i, j in ij if i + j < k - 1]
            bc = np.array(bc)
            u, v = bc[:, 0], bc[:, 1]
            w = 1 - u - v
            P = (A[sel][:, None] * w[None, :, None] + B[sel][:, None] * u[None, :, None]
                 + C[sel][:, None] * v[None, :, None])
            pts.append(P.reshape(-1, 3))
            owner.append(np.repeat(sel, len(bc)))
            radii.append(np.repeat(rad[sel] / k, len(bc)) * 1.0001)
        self.sub_pts = np.concatenate(pts)
        self.sub_owner = np.concatenate(owner)
        self.rmax = float(np.concatenate(radii).max())
        self.tree = cKDTree(self.sub_pts, leafsize=32, balanced_tree=False, compact_nodes=False)

    # ------------------------------------------------------------------ nearest
    def _best_of(self, X, cand, skip=None):
        """Best of candidate triangles cand (k, j) for points X (k,3); skip (k, j) bool: entries
        not to evaluate (repeats)."""
        best = np.full(len(X), np.inf)
        bq = np.zeros((len(X), 3))
        bf = np.zeros(len(X), dtype=np.int64)
        bb = np.zeros((len(X), 3))
        for j in range(cand.shape[1]):
            rows = np.arange(len(X)) if skip is None else np.nonzero(~skip[:, j])[0]
            if len(rows) == 0:
                continue
            f = cand[rows, j]
            x = X[rows]
            q, u, v, w = closest_on_triangles(x, self.A[f], self.B[f], self.C[f])
            dd = np.linalg.norm(x - q, axis=1)
            better = dd < best[rows]
            if not better.any():
                continue
            r = rows[better]
            best[r] = dd[better]
            bq[r] = q[better]
            bf[r] = f[better]
            bb[r] = np.stack([u[better], v[better], w[better]], axis=1)
        return best, bq, bf, bb

    def nearest(self, X, k: int = 12, chunk: int = 100_000):
        """Nearest skin point of X (k,3): distance (k,), foot (k,3), face (k,), barycentrics (k,3).

        The candidates are the triangles of the k nearest sub-triangle centres.  The distance
        found is exact or too large by at most the sub-radius (the true foot's piece has its
        centre within sub_radius of the foot), and by about sub_radius^2 / (2 d) at a distance
        d above a smooth patch: 0.0125 mm at the outer face for t = 10 mm, resolution 0.5 mm."""
        X = np.asarray(X, dtype=np.float64).reshape(-1, 3)
        n = len(X)
        D = np.empty(n)
        Q = np.empty((n, 3))
        FI = np.empty(n, dtype=np.int64)
        BC = np.empty((n, 3))
        kk = min(k, len(self.sub_pts))
        for s in range(0, n, chunk):
            x = X[s:s + chunk]
            _, ci = self.tree.query(x, k=kk, eps=self.kd_eps, workers=2)
            cand = self.sub_owner[ci.reshape(len(x), -1)]
            # each owner once (sorted per row; repeats are skipped)
            cand = np.sort(cand, axis=1)
            rep = np.zeros(cand.shape, dtype=bool)
            rep[:, 1:] = cand[:, 1:] == cand[:, :-1]
            best, bq, bf, bb = self._best_of(x, cand, rep)
            D[s:s + chunk], Q[s:s + chunk], FI[s:s + chunk], BC[s:s + chunk] = best, bq, bf, bb
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
