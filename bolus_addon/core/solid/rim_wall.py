"""The rim wall of the bolus solid: a ruled strip along the region's outer and end border loops.

Through a border loop B (k,3) mm the wall is the ruled surface {B_i + h N_i}, h from -below to
+above (mm), N_i (k,3) the skin's normal at the border smoothed along the loop: the mean of the
skin's vertex normals within NORMAL_RADIUS_MM of each border vertex, then a Gaussian of
SMOOTH_MM (arc length) along the loop, made perpendicular to the loop's tangent.  Its signed
distance (positive on the region's side, libigl's AABB tree on the strip's triangles) is the
rim term of the shell field (`distance_field.SkinDistance.terms`): a true distance, so the
marched wall is as smooth as the strip, where the skin's own nearest-feature boundary (the
planes normal to each border face) would crease the wall at every border vertex.
Arrays: loops (lists of vertex indices), X (k,3) query points, out (k,) mm.

Design notes: docs/design/solid.md.
"""
from __future__ import annotations

import numpy as np
import igl

from ..mesh.topology import MeshTopology
from .signed_surface import closest_on_triangles, feature_normals, pseudo_normals

__all__ = ["RimWall", "smoothed_border_normals", "unfolded_rulings", "NORMAL_RADIUS_MM", "SMOOTH_MM",
           "STRIP_STEP_MM"]

#: skin normals within this radius (mm) of a border vertex are averaged (scan noise)
NORMAL_RADIUS_MM = 2.0
#: Gaussian sigma (mm of arc length) of the normals' smoothing along the loop
SMOOTH_MM = 2.0
#: the strip's rows are at most this far apart (mm) along the rulings
STRIP_STEP_MM = 1.0


def _rows(below: float, above: float) -> np.ndarray:
    """Heights (J+1,) mm of the strip's rows along the rulings, at most STRIP_STEP_MM apart."""
    return np.linspace(-below, above, max(1, int(np.ceil((below + above) / STRIP_STEP_MM))) + 1)


def _loop_arc(P: np.ndarray) -> tuple[np.ndarray, float]:
    """Arc length (k,) mm at each vertex of the closed polyline P (k,3) and its length."""
    seg = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)[:-1]])
    return s, float(seg.sum())


def smoothed_border_normals(P, Nraw, sigma: float = SMOOTH_MM) -> np.ndarray:
    """Unit normals (k,3) along the closed loop P (k,3): Nraw (k,3) smoothed by a Gaussian of
    ``sigma`` mm of arc length (periodic) and made perpendicular to the loop's central-difference
    tangent."""
    k = len(P)
    s, L = _loop_arc(P)
    N = np.asarray(Nraw, dtype=np.float64).copy()
    if sigma > 0 and k > 2 and L > 0:
        half = int(min(k // 2, max(4, np.ceil(3 * sigma / max(L / k, 1e-9)))))
        idx = (np.arange(k)[:, None] + np.arange(-half, half + 1)[None]) % k
        ds = np.abs(s[idx] - s[:, None])
        ds = np.minimum(ds, L - ds)
        w = np.exp(-0.5 * (ds / sigma) ** 2)
        N = np.einsum("ij,ijk->ik", w, N[idx])
    return _perpendicular(P, N, Nraw)


def _perpendicular(P, N, Nraw) -> np.ndarray:
    """N (k,3) made perpendicular to the loop P's central-difference tangent and unit (Nraw
    where that leaves nothing)."""
    T = np.roll(P, -1, axis=0) - np.roll(P, 1, axis=0)
    T /= np.maximum(np.linalg.norm(T, axis=1), 1e-12)[:, None]
    N = N - np.einsum("ij,ij->i", N, T)[:, None] * T
    ln = np.linalg.norm(N, axis=1)
    bad = ln < 1e-9
    if bad.any():
        N[bad] = np.asarray(Nraw)[bad]
        ln[bad] = np.maximum(np.linalg.norm(N[bad], axis=1), 1e-12)
    return N / ln[:, None]


def unfolded_rulings(P, N, below: float, above: float, rounds: int = 400) -> np.ndarray:
    """The rulings N (k,3) of the loop P (k,3) smoothed where the strip (`RimWall._strip`, from
    -below to +above mm) would fold over itself: a column of quads (between P_i and P_{i+1})
    folds where a quad's normal turns more than 90 degrees from the bottom quad's of that column
    (neighbouring rulings cross: along a valley, or at a sharp turn of the border).  The rulings of
    folded columns and of their neighbours (a window of 3 on each side) are averaged ((1, 2, 1) /
    4) and made perpendicular to the loop again, round after round, until no column folds
    (parallel rulings never cross) or ``rounds`` have run."""
    N = np.asarray(N, dtype=np.float64).copy()
    k = len(P)
    for _ in range(rounds):
        bad = _folded_columns(P, N, below, above)
        if len(bad) == 0:
            break
        near = np.unique((bad[:, None] + np.arange(-3, 5)[None, :]) % k)
        avg = 0.25 * (np.roll(N, 1, axis=0) + 2 * N + np.roll(N, -1, axis=0))
        N[near] = avg[near]
        N = _perpendicular(P, N, N)
    return N


def _folded_columns(P, N, below, above) -> np.ndarray:
    """Indices i of the columns (P_i, P_{i+1}) of the strip whose quads' normals (at the strip's
    rows) turn more than 90 degrees from the quad at the bottom: the strip folds there."""
    rows = _rows(below, above)
    a = P[None] + rows[:, None, None] * N[None]           # (J+1, k, 3)
    b = np.roll(a, -1, axis=1)
    n = np.cross(b[1:] - a[:-1], a[1:] - b[:-1])          # quad normals by their diagonals
    ref = n[0]
    dots = np.einsum("jkc,kc->jk", n, ref)
    return np.nonzero((dots <= 0).any(axis=0))[0]


class RimWall:
    """The wall strips of the loops (signed distance, module docstring).

    skin: a `SkinDistance` (V, F, vn, vtree); loops: border loops (vertex index arrays);
    below / above: the strip's reach (mm) under and over the border along N.  Attributes:
    V (n,3), F (m,3) the strip's triangles (normals towards the region), N (list of (k,3)
    the rulings per loop)."""

    def __init__(self, skin, loops, below: float, above: float):
        Vs, Fs, Ns = [], [], []
        base = 0
        for lp in loops:
            P = skin.V[lp]
            near = skin.vtree.query_ball_point(P, NORMAL_RADIUS_MM)
            Nraw = np.array([skin.vn[ix].sum(axis=0) if len(ix) else skin.vn[v] for ix, v in zip(near, lp)])
            N = unfolded_rulings(P, smoothed_border_normals(P, Nraw), below, above)
            Vl, Fl = self._strip(P, N, below, above)
            Fl = self._inward(skin, P, Vl, Fl)
            Vs.append(Vl)
            Fs.append(Fl + base)
            Ns.append(N)
            base += len(Vl)
        self.N = Ns
        self.V = np.ascontiguousarray(np.concatenate(Vs) if Vs else np.zeros((0, 3)))
        self.F = np.ascontiguousarray(np.concatenate(Fs) if Fs else np.zeros((0, 3), dtype=np.int64))
        self.aabb = None
        if len(self.F):
            fn = np.cross(self.V[self.F[:, 1]] - self.V[self.F[:, 0]], self.V[self.F[:, 2]] - self.V[self.F[:, 0]])
            fn /= np.maximum(np.linalg.norm(fn, axis=1), 1e-300)[:, None]
            self.fn, self.edge_pn, self.vn_angle = pseudo_normals(self.V, self.F, MeshTopology(self.V, self.F), fn)
            self.aabb = igl.AABB()
            self.aabb.init(self.V, self.F)

    @staticmethod
    def _strip(P, N, below, above):
        """Rows of the loop P (k,3) moved by h N, h from -below to +above: (V (k*(J+1),3),
        F (2kJ,3)), quads (i, j), (i+1, j), (i+1, j+1), (i, j+1) split on one diagonal."""
        k = len(P)
        h = _rows(below, above)
        J = len(h) - 1
        V = (P[None, :, :] + h[:, None, None] * N[None, :, :]).reshape(-1, 3)
        i = np.arange(k)
        i1 = (i + 1) % k
        j = np.arange(J)
        a = (j[:, None] * k + i[None, :]).ravel()
        b = (j[:, None] * k + i1[None, :]).ravel()
        c = ((j[:, None] + 1) * k + i1[None, :]).ravel()
        d = ((j[:, None] + 1) * k + i[None, :]).ravel()
        F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
        return V, F

    @staticmethod
    def _inward(skin, P, Vl, Fl):
        """Fl wound so that the strip's normals point to the region's side of the loop P (k,3):
        the majority vote of the skin near each edge's midpoint against the first row's
        triangles."""
        k = len(P)
        ab = np.roll(P, -1, axis=0) - P
        n_first = np.cross(Vl[Fl[:k, 1]] - Vl[Fl[:k, 0]], Vl[Fl[:k, 2]] - Vl[Fl[:k, 0]])
        # the region's side of each border edge: the centroid of the skin near its midpoint
        mid = P + 0.5 * ab
        _, nearest = skin.vtree.query(mid, k=min(8, len(skin.V)))
        inside = skin.V[np.atleast_2d(nearest)].mean(axis=1) - mid
        vote = np.einsum("ij,ij->i", n_first, inside)
        return Fl if vote.sum() >= 0 else np.ascontiguousarray(Fl[:, ::-1])

    def signed(self, X) -> tuple[np.ndarray, np.ndarray]:
        """(signed distance (k,) mm, closest strip point (k,3)) of points X (k,3): positive on
        the region's side."""
        X = np.ascontiguousarray(np.asarray(X, dtype=np.float64).reshape(-1, 3))
        if self.aabb is None or len(X) == 0:
            return np.full(len(X), np.inf), X.copy()
        _, fi, _ = self.aabb.squared_distance(self.V, self.F, X)
        fi = np.asarray(fi, dtype=np.int64)
        T = self.V[self.F[fi]]
        C, u, v, w = closest_on_triangles(X, T[:, 0], T[:, 1], T[:, 2])
        PN = feature_normals(fi, np.stack([u, v, w], axis=1), self.F, self.fn, self.edge_pn, self.vn_angle)
        d = np.linalg.norm(X - C, axis=1)
        return np.where(np.einsum("ij,ij->i", X - C, PN) >= 0, d, -d), C
