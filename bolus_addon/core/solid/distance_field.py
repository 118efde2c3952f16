"""Exact one-sided distance field of an open skin region, for the bolus shell.

The shell is the set where

    f(x) = min( sd(x) - c,  t - sd(x),  r(x) )  > 0                                  (field)

* ``sd``: the signed distance to the skin triangles, the exact point-triangle distance (Ericson's
  closest point, vectorised), signed by ``(x - foot) . n`` with n the pseudo-normal of the foot's
  feature (Baerentzen & Aanaes 2005: face, edge or angle-weighted vertex normal);
* ``c`` the clearance (inner face), ``t`` the thickness (outer face), both mm from the skin;
* ``r`` closes the rim.  ``rim="faces"`` (the default): where the foot lies on a border edge or
  vertex (exact, from the barycentrics), r = -(lateral distance of x from the border's normal
  line), elsewhere the foot's distance to the border, capped at a few voxels; the wall is then
  the planes normal to the border faces, creased at every border vertex.  ``rim="strip"``:
  along the outer and end loops, the signed distance to the ruled wall strip of
  `rim_wall.RimWall` (rulings along the smoothed border normals) where the foot lies within
  reach of those loops, capped; hole loops keep the first rule.

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
from ..mesh.topology import MeshTopology
from .rim_wall import RimWall
from .signed_surface import closest_on_triangles, feature_normals, pseudo_normals

__all__ = ["closest_on_triangles", "SkinDistance", "HOLE_FRACTION", "ACROSS_COS", "RIMS"]

#: the rim wall's rule (module docstring): the border faces' normal planes, or a ruled strip
RIMS = ("faces", "strip")

#: a border loop other than the outer one is an END, open like the outer rim, when both hold:
#: its membrane's vector area is at least HOLE_FRACTION of the largest loop's, and the skin
#: stands across that membrane (the mean |n . m| of the skin's vertex normals n along the loop
#: against the membrane's unit vector area m is under ACROSS_COS): the far end of a sleeve round
#: a knee or an elbow.  Every other loop is a HOLE (a channel is cut through the bolus): a
#: nostril, an eye, a stoma, the top of a dome cut open, where the skin would run on over the
#: membrane.  (A vector area needs no plane: it is the same for every surface the loop bounds.)
HOLE_FRACTION = 0.2
ACROSS_COS = 0.5


class SkinDistance:
    """Exact nearest-point queries and the shell field (module docstring) on a skin region.

    V (n,3), F (m,3) an open, consistently wound, non-degenerate region (checked by the
    caller).  Attributes: vn (n,3) unit area-weighted vertex normals, loops (list of border
    vertex loops, outer one first: the one enclosing the most area along the mean normal),
    rim_tree (KD-tree of border samples every 0.05 mm), aabb (libigl's AABB tree of the triangles),
    area (float mm^2).
    """

    def __init__(self, V, F, rim: str = "faces"):
        if rim not in RIMS:
            raise ValueError(f"rim must be one of {RIMS}, got {rim!r}")
        self.V = V
        self.F = F
        self.rim = rim
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
        """Pseudo-normals for the sign (`signed_surface.pseudo_normals`): edge_pn (m,3,3) of the
        edge opposite corner j, vn_angle (n,3) angle-weighted at the vertices."""
        _, self.edge_pn, self.vn_angle = pseudo_normals(self.V, self.F, self.topo, self.fn)

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
        """Border samples every 0.05 mm and their KD-trees: rim_pts / rim_tree of every border
        edge, hole_tree of the hole loops' edges, wall_tree of the outer and end loops' edges
        (one far point where there is none).  vkind (n,) int8: 1 on a hole loop's vertices, 2 on
        an outer or end loop's, 0 elsewhere."""
        V = self.V
        self.vkind = np.zeros(len(V), dtype=np.int8)
        self.vkind[self.vborder] = 1
        if self.rim == "strip":
            for lp in self.outer_loops + self.end_loops:
                self.vkind[lp] = 2
        E = self.border_edges
        self.rim_pts = self._samples(E)
        self.rim_tree = cKDTree(self.rim_pts)
        self.hole_tree = cKDTree(self._samples(E[self.vkind[E[:, 0]] == 1])) if self.rim == "strip" else self.rim_tree
        self.wall_tree = cKDTree(self._samples(E[self.vkind[E[:, 0]] == 2]))
        self._walls: dict = {}

    def _samples(self, E) -> np.ndarray:
        """Points (s,3) every 0.05 mm along the edges E (e,2); one far point when E is empty."""
        if len(E) == 0:
            return np.full((1, 3), 1e12)
        P, Q = self.V[E[:, 0]], self.V[E[:, 1]]
        n = np.maximum(2, np.ceil(np.linalg.norm(Q - P, axis=1) / 0.05).astype(int) + 1)
        s = np.concatenate([np.linspace(0.0, 1.0, k) for k in n])
        e = np.repeat(np.arange(len(P)), n)
        return P[e] * (1 - s)[:, None] + Q[e] * s[:, None]

    def wall(self, thickness: float, rim_cap: float) -> RimWall:
        """The rim wall strip (`rim_wall.RimWall`) of the outer and end loops for a shell of
        ``thickness`` mm: from 2 rim_cap under the border to thickness + 3 rim_cap over it."""
        key = (round(float(thickness), 9), round(float(rim_cap), 9))
        if key not in self._walls:
            self._walls[key] = RimWall(self, self.outer_loops + self.end_loops, 2 * rim_cap,
                                       float(thickness) + 3 * rim_cap)
        return self._walls[key]

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
        return self.terms_and_feet(X, thickness, clearance, rim_cap)[:3]

    def terms_and_feet(self, X, thickness: float, clearance: float, rim_cap: float):
        """The three terms (sd - c, t - sd, r) (k,) each, and where each term's zero surface is
        nearest X (k,3) along its gradient (k,3) each: Q + c g and Q + t g on the inner and
        outer faces (Q the foot, g the unit gradient of sd: (X - Q) / sd, the skin's normal
        where X is on the skin), the wall strip's closest point where r is the wall's
        (NaN where it is a hole's term or the cap)."""
        d, Q, FI, BC = self.nearest(X)
        Fv = self.F[FI]
        N = (self.vn[Fv[:, 0]] * BC[:, :1] + self.vn[Fv[:, 1]] * BC[:, 1:2] + self.vn[Fv[:, 2]] * BC[:, 2:3])
        ln = np.linalg.norm(N, axis=1)
        ln[ln == 0] = 1.0
        N /= ln[:, None]
        diff = X - Q
        h = np.einsum("ij,ij->i", diff, N)
        # sign from the pseudo-normal of the foot's feature (exact zeros / ones from Ericson)
        PN = feature_normals(FI, BC, self.F, self.fn, self.edge_pn, self.vn_angle)
        sd = np.where(np.einsum("ij,ij->i", diff, PN) >= 0, d, -d)
        kind = self._foot_border_kind(FI, Fv, BC)
        r_hole = self._hole_term(kind == 1, diff, h, N, Q, rim_cap)
        r_wall, C = self._wall_term(X, Q, kind == 2, thickness, rim_cap)
        g = np.where((d > 1e-9)[:, None], diff / np.where(sd == 0, 1.0, sd)[:, None], N)
        C[~((r_wall < r_hole) & (np.abs(r_wall) < rim_cap))] = np.nan
        return (sd - clearance, thickness - sd, np.minimum(r_hole, r_wall),
                Q + clearance * g, Q + thickness * g, C)

    def _foot_border_kind(self, FI, Fv, BC) -> np.ndarray:
        """(k,) int8: `vkind` of the border edge or vertex a foot lies on (exact zeros / ones of
        the barycentrics BC (k,3) on faces FI, corners Fv (k,3)), 0 for a foot off the border."""
        eps = 1e-9
        kind = np.zeros(len(FI), dtype=np.int8)
        for j in range(3):
            on_e = (BC[:, j] < eps) & self.fborder[FI, j]
            kind[on_e] = self.vkind[Fv[on_e, (j + 1) % 3]]
            on_v = (BC[:, j] > 1 - eps) & self.vborder[Fv[:, j]]
            kind[on_v] = self.vkind[Fv[on_v, j]]
        return kind

    def _hole_term(self, on_hole, diff, h, N, Q, rim_cap) -> np.ndarray:
        """The holes' rim term (k,): -(lateral distance from the border's normal line) where the
        foot is on a hole's border, else the foot's distance to the holes' borders, capped."""
        r = np.full(len(Q), rim_cap)
        if not (self.vkind == 1).any():
            return r
        near = ~on_hole
        if near.any():
            dr, _ = self.hole_tree.query(Q[near], workers=2, distance_upper_bound=rim_cap)
            r[near] = np.minimum(dr, rim_cap)
        lat = np.linalg.norm(diff[on_hole] - h[on_hole, None] * N[on_hole], axis=1)
        r[on_hole] = -lat
        return r

    def _wall_term(self, X, Q, on_wall, thickness, rim_cap) -> np.ndarray:
        """The outer and end loops' rim term (k,): the wall strip's signed distance clipped to
        +-rim_cap where the foot Q lies within rim_cap + thickness / 4 of those loops (the strip
        may lean out of the plane normal to the border face by some degrees), rim_cap elsewhere;
        and the strip's closest points (k,3) (NaN where not asked)."""
        r = np.full(len(X), rim_cap)
        C = np.full((len(X), 3), np.nan)
        if not (self.vkind == 2).any():
            return r, C
        reach = rim_cap + 0.25 * thickness
        dw, _ = self.wall_tree.query(Q, workers=2, distance_upper_bound=reach)
        cand = np.nonzero(np.isfinite(dw) | on_wall)[0]
        if len(cand):
            s, C[cand] = self.wall(thickness, rim_cap).signed(X[cand])
            r[cand] = np.clip(s, -rim_cap, rim_cap)
        return r, C

    def field(self, X, thickness: float, clearance: float, rim_cap: float):
        """f(X) (k,) of the module docstring: positive inside the shell."""
        a, b, r = self.terms(X, thickness, clearance, rim_cap)
        return np.minimum(np.minimum(a, b), r)
