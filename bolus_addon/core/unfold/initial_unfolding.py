"""Starting positions of a disk-like patch in the plane (seed 4.5.1, eq. 4-24; LSCM).

`initial_unfolding` is the seed's coordinate transformation (4.5.1): vertex labels by
breadth-first layers from the boundary; the central triangle has the largest label sum;
it is laid flat without deformation, then the *central triangle crossing*: the main
stripe (of several directions through the central triangle's centroid, the one crossing
most triangles) and its perpendicular are unfolded edge to edge without deformation;
then the adjacent crossings layer by layer: every triangle with an unfolded edge gets its
third vertex from two angles and that edge, the angles rescaled at interior vertices so
that they sum to 2 pi (eq. 4-24), on the side away from the unfolded neighbour.

`conformal_unfolding` is the least-squares conformal map (Levy et al. 2002) at true
area: one sparse solve, no accumulated error, the default start of `unfold_patch`.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.sparse.linalg import spsolve

from ..errors import BolusError
from ..mesh.geometry2d import cross2d
from .overlap import signed_areas
from .relax import relax_lbfgs
from .springs import Springs, sub_springs
from ..mesh.topology import MeshTopology

__all__ = ["initial_unfolding", "conformal_unfolding", "STRIPE_DIRECTIONS"]

STRIPE_DIRECTIONS = 12  # directions tried for the main stripe through the central triangle
STRIPE_TIES = 3  # central-triangle candidates (ties on the label sum) kept, nearest the patch centre
RELAX_LAYER_ITERS = 10  # L-BFGS iterations of the partial relaxation each time the unfolded part doubled
RELAX_GROWTH = 2.0  # the unfolded part is relaxed each time its vertex count grew by this factor
RELAX_FIRST = 64  # ... but not before this many vertices are placed
ANGLE_SCALE_CLIP = (0.5, 2.0)  # eq. 4-24's angle factor stays in this range (a wild factor folds the layer)
PARALLEL_DET = 1e-14  # a stripe line and a triangle edge this close to parallel do not cross


def _require_patch(topo: MeshTopology) -> None:
    """`topology.check_mesh` (zero-area triangles, non-manifold edges), and every vertex in a
    triangle (an unused vertex has no place in the plane: the conformal system is singular)."""
    topo.require_valid("the patch", manifold=True)
    unused = np.nonzero(~topo.used_vertices)[0]
    if len(unused):
        raise BolusError(f"the patch has {len(unused)} vertex(es) in no triangle, e.g. vertex {int(unused[0])}: "
                         "unfold the patch's triangles only (topology.submesh)")


def _boundary_layers(topo: MeshTopology) -> np.ndarray:
    """Vertex labels (n,): breadth-first layer from the boundary (0 on the boundary)."""
    bverts = np.nonzero(topo.boundary_vertices)[0]
    if not len(bverts):
        return np.zeros(topo.n)
    lab = dijkstra(topo.vertex_adjacency, directed=False, indices=bverts, unweighted=True, min_only=True)
    lab[~np.isfinite(lab)] = 0
    return lab


def _central_candidates(topo: MeshTopology, lab: np.ndarray) -> np.ndarray:
    """Faces with the largest label sum; of many ties the `STRIPE_TIES` nearest the centre."""
    fsum = lab[topo.F].sum(axis=1)
    best = np.nonzero(fsum == fsum.max())[0]
    if len(best) > STRIPE_TIES:
        c = topo.centroids
        centre = (c * topo.areas[:, None]).sum(axis=0) / topo.areas.sum()
        best = best[np.argsort(np.linalg.norm(c[best] - centre, axis=1))[:STRIPE_TIES]]
    return best


def _rot(u: np.ndarray, ang: np.ndarray) -> np.ndarray:
    c, s = np.cos(ang), np.sin(ang)
    return np.stack([c * u[:, 0] - s * u[:, 1], s * u[:, 0] + c * u[:, 1]], axis=1)


def _place_third(Pi, Pj, beta_i, beta_j, away_from):
    """Third vertex of triangles on edges Pi->Pj (k,2) with angles beta at i and j (law of sines),
    on the side of the edge opposite to the points ``away_from`` (k,2)."""
    e = Pj - Pi
    l1 = np.linalg.norm(e, axis=1)
    u = e / np.maximum(l1, 1e-300)[:, None]
    s = np.sin(np.clip(beta_i + beta_j, 1e-9, np.pi - 1e-9))
    r = l1 * np.sin(beta_j) / s
    side_ref = np.sign(cross2d(u, away_from - Pi))
    side_ref[side_ref == 0] = -1.0
    ang = -side_ref * beta_i  # rotate u towards the side away from the reference
    return Pi + r[:, None] * _rot(u, ang)


def _place_at(Pi, Pj, beta_i, length, away_from):
    """Point at ``length`` from Pi, at angle beta_i from the direction Pi->Pj, on the side
    of the line away from ``away_from`` (all (k,2) / (k,))."""
    e = Pj - Pi
    u = e / np.maximum(np.linalg.norm(e, axis=1), 1e-300)[:, None]
    side_ref = np.sign(cross2d(u, away_from - Pi))
    side_ref[side_ref == 0] = -1.0
    return Pi + length[:, None] * _rot(u, -side_ref * beta_i)


def _place_central(topo: MeshTopology, f: int) -> dict:
    """The central triangle f laid flat without deformation: {vertex: (2,) position}."""
    i, j, k = topo.F[f]
    Lij = np.linalg.norm(topo.V[j] - topo.V[i])
    out = {i: np.array([0.0, 0.0]), j: np.array([Lij, 0.0])}
    out[k] = _place_third(np.array([[0.0, 0.0]]), np.array([[Lij, 0.0]]), np.array([topo.angles[f, 0]]),
                          np.array([topo.angles[f, 1]]), np.array([[0.0, -1.0]]))[0]
    return out


class _StripeWalker:
    """Walks straight lines across the patch, unfolding faces edge to edge (plain Python
    floats: this loop runs a few thousand steps per stripe)."""

    def __init__(self, topo: MeshTopology):
        self.F = topo.F.tolist()
        self.face_edges = topo.face_edges.tolist()
        self.edge_faces = topo.edge_faces.tolist()
        self.edge_count = topo.edge_face_count.tolist()
        self.edges = topo.edges.tolist()
        self.alpha = topo.angles.tolist()

    def _exit_edge(self, f, allpos, c, dvec, came_from) -> int:
        """The edge of face f where the line c + t d leaves it (largest t), -1 if none."""
        tri = self.F[f]
        cx, cy = c
        dx, dy = dvec
        best_t, exit_edge = -math.inf, -1
        for k in range(3):
            ax, ay = allpos[tri[k]]
            bx, by = allpos[tri[(k + 1) % 3]]
            # c + t d = a + s (b - a)  ->  solve for t, s (Cramer)
            ex, ey = bx - ax, by - ay
            det = dx * (-ey) - dy * (-ex)
            if abs(det) < PARALLEL_DET:
                continue
            rx, ry = ax - cx, ay - cy
            t = (rx * (-ey) - ry * (-ex)) / det
            sv = (dx * ry - dy * rx) / det
            if 0.0 <= sv <= 1.0 and t > best_t:
                eid = self.face_edges[f][k]
                if eid == came_from:
                    continue
                best_t, exit_edge = t, eid
        return exit_edge

    def _unfold_across(self, f, nf, eid, allpos):
        """Position (x, y) of the third vertex of face nf across edge eid from face f (no
        deformation: the 3D angles at the edge's ends), or None if it is placed already."""
        vi, vj = self.edges[eid]
        tri_n = self.F[nf]
        other = [v for v in tri_n if v != vi and v != vj][0]
        if other in allpos:
            return other, None
        bi, bj = self.alpha[nf][tri_n.index(vi)], self.alpha[nf][tri_n.index(vj)]
        tri = self.F[f]
        awx = sum(allpos[v][0] for v in tri) / 3.0
        awy = sum(allpos[v][1] for v in tri) / 3.0
        pix, piy = allpos[vi]
        pjx, pjy = allpos[vj]
        ux, uy = pjx - pix, pjy - piy
        l1 = math.hypot(ux, uy)
        ux, uy = ux / l1, uy / l1
        r = l1 * math.sin(bj) / max(math.sin(bi + bj), 1e-12)
        side = ux * (awy - piy) - uy * (awx - pix)
        ang = -bi if side > 0 else bi
        c_, s_ = math.cos(ang), math.sin(ang)
        return other, (pix + r * (c_ * ux - s_ * uy), piy + r * (s_ * ux + c_ * uy))

    def stripe(self, f0, pos: dict, direction) -> tuple[list, dict]:
        """Unfold the faces crossed by the line through face f0's centroid along
        ``direction``, both ways.  Returns (faces, {vertex: new position})."""
        faces, newpos = [f0], {}
        allpos = {k: (float(v[0]), float(v[1])) for k, v in pos.items()}
        c = (sum(allpos[v][0] for v in self.F[f0]) / 3.0, sum(allpos[v][1] for v in self.F[f0]) / 3.0)
        seen = {f0}
        for sgn in (1.0, -1.0):
            dvec = (sgn * float(direction[0]), sgn * float(direction[1]))
            f, came_from = f0, -1
            while True:
                eid = self._exit_edge(f, allpos, c, dvec, came_from)
                if eid < 0 or self.edge_count[eid] != 2:
                    break
                f0e, f1e = self.edge_faces[eid]
                nf = f1e if f0e == f else f0e
                if nf in seen:
                    break
                other, p = self._unfold_across(f, nf, eid, allpos)
                if p is None:
                    break
                allpos[other] = p
                newpos[other] = np.array(p)
                faces.append(nf)
                seen.add(nf)
                f, came_from = nf, eid
        return faces, newpos


def _central_crossing(topo: MeshTopology, directions: int) -> np.ndarray:
    """UV (n,2), NaN where not placed: the central triangle and its crossing (main stripe,
    the direction crossing most triangles, and its perpendicular)."""
    walker = _StripeWalker(topo)
    dirs = [np.array([np.cos(t), np.sin(t)]) for t in np.linspace(0, np.pi, directions, endpoint=False)]
    best_choice = None
    for f in _central_candidates(topo, _boundary_layers(topo)):  # ties: the longest main stripe wins
        pos = _place_central(topo, f)
        counts = [len(walker.stripe(f, pos, d)[0]) for d in dirs]
        kbest = int(np.argmax(counts))
        if best_choice is None or counts[kbest] > best_choice[0]:
            best_choice = (counts[kbest], f, pos, dirs[kbest])
    _, f0, pos, dmain = best_choice
    pos.update(walker.stripe(f0, pos, dmain)[1])
    pos.update(walker.stripe(f0, pos, np.array([-dmain[1], dmain[0]]))[1])
    UV = np.full((topo.n, 2), np.nan)
    for v, p in pos.items():
        UV[v] = p
    return UV


def _angle_sums(topo: MeshTopology, UV, placed_face) -> tuple[np.ndarray, np.ndarray]:
    """(n,) 2D angle sums of the placed faces and 3D angle sums of the others at every vertex."""
    F, m, n = topo.F, topo.m, topo.n
    placed_ang = np.zeros((m, 3))
    if placed_face.any():
        Pp = UV[F][placed_face]
        a_ = np.roll(Pp, -1, axis=1) - Pp
        b_ = np.roll(Pp, -2, axis=1) - Pp
        placed_ang[placed_face] = np.arctan2(np.abs(cross2d(a_, b_)), np.einsum("mkc,mkc->mk", a_, b_))
    beta_sum = np.bincount(F.ravel(), weights=placed_ang.ravel(), minlength=n)
    alpha_free = np.bincount(F[~placed_face].ravel(), weights=topo.angles[~placed_face].ravel(), minlength=n)
    return beta_sum, alpha_free


def _away_points(topo: MeshTopology, UV, placed_face, tgt, ki, vi, vj) -> np.ndarray:
    """(k,2) points to place away from: the centroid of the unfolded neighbour across edge
    (vi, vj), else a point on the right of vi -> vj (the corner order stays counter-clockwise)."""
    F = topo.F
    ef = topo.edge_faces[topo.face_edges[tgt, ki]]
    nbr = np.where(ef[:, 0] == tgt, ef[:, 1], ef[:, 0])
    has_nbr = (nbr >= 0) & placed_face[np.maximum(nbr, 0)]
    away = np.where(has_nbr[:, None], np.nan_to_num(UV[F[np.maximum(nbr, 0)]].mean(axis=1)), 0.0)
    if (~has_nbr).any():
        e = UV[vj] - UV[vi]
        away = np.where(has_nbr[:, None], away, UV[vi] + np.stack([e[:, 1], -e[:, 0]], axis=1))
    return away


def _adjacent_layer(topo: MeshTopology, UV, placed_v, placed_face) -> np.ndarray:
    """One adjacent triangle crossing: place the free corner of every unplaced face with two
    placed corners (eq. 4-24).  Writes UV, returns the newly placed vertices (empty: stuck)."""
    F, V, n = topo.F, topo.V, topo.n
    beta_sum, alpha_free = _angle_sums(topo, UV, placed_face)
    tgt = np.nonzero((~placed_face) & (placed_v[F].sum(axis=1) == 2))[0]
    if len(tgt) == 0:
        return tgt
    T = F[tgt]
    k_free = np.argmin(placed_v[T], axis=1)  # the unplaced corner
    ki, kj = (k_free + 1) % 3, (k_free + 2) % 3
    rows = np.arange(len(tgt))
    vi, vj, vp = T[rows, ki], T[rows, kj], T[rows, k_free]
    interior = topo.interior_vertices

    def rescale(v, a):  # eq. 4-24 at interior vertices
        remaining = 2 * np.pi - beta_sum[v]
        fac = np.where(interior[v] & (alpha_free[v] > 0), remaining / np.maximum(alpha_free[v], 1e-300), 1.0)
        return a * np.clip(fac, *ANGLE_SCALE_CLIP)

    bi, bj = rescale(vi, topo.angles[tgt, ki]), rescale(vj, topo.angles[tgt, kj])
    away = _away_points(topo, UV, placed_face, tgt, ki, vi, vj)
    # The seed fixes P by the two angles and the unfolded edge (law of sines); where the
    # rescaled angles add up to nearly pi that puts P far away and the error grows layer
    # after layer.  We keep the rescaled angle *directions* at both ends but the true 3D
    # lengths |vi P| and |vj P|, and average the two positions.
    Lip = np.linalg.norm(V[vp] - V[vi], axis=1)
    Ljp = np.linalg.norm(V[vp] - V[vj], axis=1)
    Pnew = 0.5 * (_place_at(UV[vi], UV[vj], bi, Lip, away) + _place_at(UV[vj], UV[vi], bj, Ljp, away))
    # several triangles may target the same vertex in one layer: average them
    cnt = np.bincount(vp, minlength=n)
    newv = np.nonzero(cnt > 0)[0]
    UV[newv, 0] = np.bincount(vp, Pnew[:, 0], minlength=n)[newv] / cnt[newv]
    UV[newv, 1] = np.bincount(vp, Pnew[:, 1], minlength=n)[newv] / cnt[newv]
    return newv


def initial_unfolding(topo: MeshTopology, directions: int = STRIPE_DIRECTIONS,
                      springs: Springs | None = None) -> np.ndarray:
    """Initial 2D positions by the coordinate transformation of 4.5.1 (eq. 4-24).

    Parameters: topo, a disk-like patch's `MeshTopology` (V (n,3), F (m,3)); directions,
    stripe directions tried; springs (`springs.Springs`, optional): the part unfolded so
    far is relaxed by the mass-spring model each time it has doubled (the seed's second
    overlap-prevention method, 4.5.3: "optimize unfolded triangles after unfolding each
    adjacent triangle crossing"), so that errors do not pile up into folds.
    Returns UV (n,2).  Raises `BolusError` (`topology.check_mesh`, naming the first) on
    zero-area triangles (no angles), non-manifold edges and vertices in no triangle, and
    when some faces are not connected to the rest.
    """
    _require_patch(topo)
    return _greedy(topo, directions, springs)


def _greedy(topo: MeshTopology, directions: int = STRIPE_DIRECTIONS, springs: Springs | None = None) -> np.ndarray:
    """`initial_unfolding` without the input check (for callers that checked the patch already)."""
    F, n = topo.F, topo.n
    UV = _central_crossing(topo, directions)
    placed_v = ~np.isnan(UV[:, 0])
    placed_face = placed_v[F].all(axis=1)
    next_relax = max(int(placed_v.sum() * RELAX_GROWTH), RELAX_FIRST)
    for _layer in range(4 * topo.m):
        if placed_face.all():
            break
        newv = _adjacent_layer(topo, UV, placed_v, placed_face)
        if len(newv) == 0:  # a face with one placed vertex and nothing to hinge on: not connected
            break
        placed_v[newv] = True
        placed_face = placed_v[F].all(axis=1)
        count = int(placed_v.sum())
        if springs is not None and next_relax <= count < n:
            sub, ids = sub_springs(springs, placed_v)
            if len(sub.rest):
                UV[ids], _, _ = relax_lbfgs(UV[ids], sub, max_iter=RELAX_LAYER_ITERS)
            next_relax = int(count * RELAX_GROWTH) + 1
    if not placed_v.all():
        raise BolusError("the patch could not be unfolded: some of its faces are not connected to the rest")
    return UV


def conformal_unfolding(topo: MeshTopology) -> np.ndarray:
    """Least-squares conformal map (Levy et al. 2002) scaled to true area.

    Parameters: topo, a disk-like patch's `MeshTopology` (V (n,3), F (m,3)).
    Returns UV (n,2), counter-clockwise, sum of 2D areas = sum of 3D areas.  LSCM is the
    minimiser of a convex quadratic, so it has no accumulated error; two far-apart
    boundary vertices are pinned.  Raises `BolusError` (`topology.check_mesh`, naming the
    first) on zero-area triangles and vertices in no triangle (they make the system
    singular) and non-manifold edges.
    """
    _require_patch(topo)
    return _conformal(topo)


def _conformal(topo: MeshTopology) -> np.ndarray:
    """`conformal_unfolding` without the input check (for callers that checked the patch already)."""
    A = _lscm_matrix(topo)
    n = topo.n
    fixed, vals = _lscm_pins(topo)
    free = np.setdiff1d(np.arange(2 * n), fixed)
    Af, Ax = A[:, free], A[:, fixed]
    sol = spsolve((Af.T @ Af).tocsc(), Af.T @ -(Ax @ vals))
    x = np.empty(2 * n)
    x[free] = sol
    x[fixed] = vals
    UV = np.stack([x[:n], x[n:]], axis=1)
    A2 = signed_areas(UV, topo.F)
    if A2.sum() < 0:
        UV[:, 1] = -UV[:, 1]
    UV *= np.sqrt(topo.areas.sum() / max(abs(A2.sum()), 1e-300))
    return UV


def _lscm_matrix(topo: MeshTopology):
    """(2m, 2n) CSR matrix of the conformal energy: real and imaginary rows of every
    triangle in its own plane, unknowns [u (n), v (n)]."""
    V, F, n, m = topo.V, topo.F, topo.n, topo.m
    e1 = V[F[:, 1]] - V[F[:, 0]]  # each triangle in its own plane: p0 at 0, p1 on the x axis
    e2 = V[F[:, 2]] - V[F[:, 0]]
    l1 = np.linalg.norm(e1, axis=1)
    x2 = np.einsum("ij,ij->i", e1, e2) / l1
    y2 = np.linalg.norm(np.cross(e1, e2), axis=1) / l1
    xs = np.stack([np.zeros(m), l1, x2], 1)
    ys = np.stack([np.zeros(m), np.zeros(m), y2], 1)
    d = np.sqrt(np.maximum(xs[:, 1] * ys[:, 2], 1e-300))  # sqrt(2 A)
    # W_j = (x_{j+2} - x_{j+1}) + i (y_{j+2} - y_{j+1})
    Wr = (np.roll(xs, -2, axis=1) - np.roll(xs, -1, axis=1)) / d[:, None]
    Wi = (np.roll(ys, -2, axis=1) - np.roll(ys, -1, axis=1)) / d[:, None]
    rows = np.repeat(np.arange(m), 3)
    cols = F.ravel()
    # real rows: Wr u - Wi v; imaginary rows: Wi u + Wr v
    R = sp.coo_matrix((np.r_[Wr.ravel(), -Wi.ravel()], (np.r_[rows, rows], np.r_[cols, cols + n])), shape=(m, 2 * n))
    I_ = sp.coo_matrix((np.r_[Wi.ravel(), Wr.ravel()], (np.r_[rows, rows], np.r_[cols, cols + n])), shape=(m, 2 * n))
    return sp.vstack([R, I_]).tocsr()


def _lscm_pins(topo: MeshTopology) -> tuple[np.ndarray, np.ndarray]:
    """Pinned unknowns (4,) and their values: two far-apart boundary vertices, at true distance on the x axis."""
    V, n = topo.V, topo.n
    b = np.nonzero(topo.boundary_vertices)[0]
    if len(b) < 2:
        b = np.arange(n)
    p0 = b[np.argmax(np.linalg.norm(V[b] - V[b].mean(axis=0), axis=1))]
    p1 = b[np.argmax(np.linalg.norm(V[b] - V[p0], axis=1))]
    dist = float(np.linalg.norm(V[p1] - V[p0]))
    return np.array([p0, p1, p0 + n, p1 + n]), np.array([0.0, dist, 0.0, 0.0])
