"""The objective J(X) of the surface improvement (seed 4.3.1, eqs. 4-10..4-21).

Every vertex p moves only along one fixed unit direction N_p (its outward normal, eq. 3-2,
taken once before any move; eqs. 4-18..4-20) by d_p >= 0 mm; boundary vertices never move
(eq. 4-17).  With X(d) = X0 + N * d[:, None] (X0, N (n,3), d (n,) mm), over the interior V_in:

    J(d) = mu1 * sum_{V_in} |theta_p - 2 pi|           (4-10, theta of eq. 4-1)
         + mu2 * sum_{V_in} ||(L X)_p||^2              (4-13, L the uniform Laplacian 4-11, 4-12)
         + mu3 * sum_p ||x_p - x0_p||^2 = mu3 sum d^2   (4-16)
         + mu4 * sum_f |A_f - A0_f| / sum_f A0_f         (4-14)               (eq. 4-21)

with mu = `MU_DEFAULT` = (10, 1, 0.1, 10), the seed's values, in mm.  `SurfaceObjective` evaluates it:

  * `value` / `terms`: the exact J of one offset vector (terms: the four summands);
  * `value_and_grad`: J with |x| smoothed to sqrt(x^2 + s^2) - s and its exact gradient in d;
  * `batch_values`: the exact J of P candidates (P,k) that differ from a base d only at k given
    vertices, incrementally (only their one-rings) and vectorised over the candidates.

Design notes: docs/design/improve.md.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import BolusError
from ..mesh.topology import MeshTopology, check_mesh, corner_angles, face_areas

__all__ = ["MU_DEFAULT", "outward_directions", "uniform_laplacian", "SurfaceObjective"]

#: (mu1, mu2, mu3, mu4) of eq. 4-21: the seed's weights for all its examples
MU_DEFAULT = (10.0, 1.0, 0.1, 10.0)
TWO_PI = 2.0 * np.pi


def outward_directions(X, F) -> np.ndarray:
    """Unit vertex normals (n,3) of X (n,3) with triangles F (m,3): eq. 3-2, the area-weighted
    face normals (right-hand rule on the corner order, i.e. the side the faces point to).
    A vertex on no triangle gets the zero vector."""
    X, F = check_mesh(X, F, "the surface", nondegenerate=False)
    return MeshTopology(X, F).vertex_normals


def uniform_laplacian(topo: MeshTopology) -> sp.csr_matrix:
    """The uniform Laplacian L (n,n) of eq. 4-12: L_ii = 1, L_ij = -1/|N^i| for j in the one-ring."""
    A = topo.vertex_adjacency
    deg = np.asarray(A.sum(axis=1)).ravel()
    inv = np.divide(1.0, deg, out=np.zeros_like(deg), where=deg > 0)
    return (sp.identity(topo.n, format="csr") - sp.diags(inv) @ A).tocsr()


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (broadcasting), written out: np.cross is several times slower."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _angles_areas_batch(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inner angles (..., 3) and areas (...) of triangles with corner positions P (..., 3, 3).

    One cross product per triangle (|e0 x e1| = 2A at every corner) and three dot products:
    the angle at corner k is atan2(2A, -e_{k-1} . e_k), e_k = P_{k+1} - P_k (as
    topology.corner_angles, written out for speed)."""
    e0 = P[..., 1, :] - P[..., 0, :]
    e1 = P[..., 2, :] - P[..., 1, :]
    e2 = P[..., 0, :] - P[..., 2, :]
    cx = e0[..., 1] * e1[..., 2] - e0[..., 2] * e1[..., 1]
    cy = e0[..., 2] * e1[..., 0] - e0[..., 0] * e1[..., 2]
    cz = e0[..., 0] * e1[..., 1] - e0[..., 1] * e1[..., 0]
    two_a = np.sqrt(cx * cx + cy * cy + cz * cz)
    dots = np.stack([-(e2 * e0).sum(-1), -(e0 * e1).sum(-1), -(e1 * e2).sum(-1)], axis=-1)
    return np.arctan2(two_a[..., None], dots), 0.5 * two_a


class SurfaceObjective:
    """J of eq. 4-21 on one patch, as a function of the offsets d (n,) in mm.

    X0 (n,3) the surface the angles and areas are measured on (mm; the analysis copy of the skin),
    F (m,3) its triangles (consistently wound), N (n,3) unit directions (default
    `outward_directions(X0, F)`), mu the weights (mu1..mu4), movable (n,) bool the
    vertices allowed to move (default and at most: the interior vertices V_in), smooth_base
    (n,3) the surface whose smoothness (eq. 4-13) is measured, S(d) = smooth_base + N d
    (default X0).
    Raises BolusError for a broken mesh or a bad N / mu.
    """

    def __init__(self, X0, F, N=None, mu=MU_DEFAULT, movable=None, smooth_base=None):
        X0, F = check_mesh(X0, F, "the patch")
        self.X0, self.F = X0, F
        # the surface whose smoothness (4-13) is measured, moved by the same offsets: X0 itself, or
        # (the driver's choice) the skin as it is while the angles are taken on its analysis copy
        self.S0 = X0 if smooth_base is None else np.asarray(smooth_base, dtype=np.float64)
        if self.S0.shape != X0.shape or not np.all(np.isfinite(self.S0)):
            raise BolusError(f"smooth_base must be a finite ({len(X0)}, 3) array, got shape {self.S0.shape}")
        self.topo = topo = MeshTopology(X0, F)
        self.n, self.m = topo.n, topo.m
        self.N = outward_directions(X0, F) if N is None else np.asarray(N, dtype=np.float64)
        if self.N.shape != X0.shape or not np.all(np.isfinite(self.N)):
            raise BolusError(f"the directions must be a finite ({self.n}, 3) array, got shape {self.N.shape}")
        mu = np.asarray(mu, dtype=np.float64)
        if mu.shape != (4,) or not np.all(np.isfinite(mu)) or np.any(mu < 0):
            raise BolusError(f"mu must be four weights >= 0 (mu1..mu4 of eq. 4-21), got {mu.tolist()}")
        self.mu = mu
        self.interior = topo.interior_vertices.copy()
        mov = self.interior.copy() if movable is None else (np.asarray(movable, dtype=bool) & self.interior)
        self.movable = mov
        self.movable_ids = np.nonzero(mov)[0]
        self.L = uniform_laplacian(topo)
        self._Lin = self.L[np.nonzero(self.interior)[0]]  # the rows of V_in (eq. 4-13)
        self.A0 = face_areas(X0, F)
        self.sum_A0 = float(self.A0.sum())
        if self.sum_A0 <= 0:
            raise BolusError("the patch has no area")
        self.theta0 = self.theta(np.zeros(self.n))
        self._base_key = None
        self._local_key = None

    # ------------------------------------------------------------------ exact J
    def positions(self, d) -> np.ndarray:
        """X(d) (n,3) = X0 + N d."""
        return self.X0 + self.N * np.asarray(d, dtype=np.float64)[:, None]

    def smooth_positions(self, d) -> np.ndarray:
        """S(d) (n,3) = smooth_base + N d: where the smoothness term (4-13) is measured."""
        return self.S0 + self.N * np.asarray(d, dtype=np.float64)[:, None]

    def theta(self, d) -> np.ndarray:
        """Angle sums (n,) at X(d) (eq. 4-1)."""
        ang = corner_angles(self.positions(d), self.F)
        return np.bincount(self.F.ravel(), weights=ang.ravel(), minlength=self.n)

    def terms(self, d) -> np.ndarray:
        """The four unweighted terms (4,) of eq. 4-21 at d: [sum varpi (4-10), sum ||Lx||^2 (4-13),
        sum d^2 (4-16), area error (4-14)]."""
        d = np.asarray(d, dtype=np.float64)
        X = self.positions(d)
        ang = corner_angles(X, self.F)
        theta = np.bincount(self.F.ravel(), weights=ang.ravel(), minlength=self.n)
        t1 = float(np.abs(theta[self.interior] - TWO_PI).sum())
        t2 = float(np.sum((self._Lin @ self.smooth_positions(d)) ** 2))
        t3 = float(np.sum(d * d))
        t4 = float(np.abs(face_areas(X, self.F) - self.A0).sum() / self.sum_A0)
        return np.array([t1, t2, t3, t4])

    def value(self, d) -> float:
        """J(d) of eq. 4-21."""
        return float(self.mu @ self.terms(d))

    # ------------------------------------------------------------- smooth + grad
    def value_and_grad(self, d, smooth: float = 1e-4) -> tuple[float, np.ndarray]:
        """(J_s(d), dJ_s/dd (n,)): J with |x| -> sqrt(x^2 + smooth^2) - smooth in the angle and
        area terms (differentiable; J_s <= J <= J_s + smooth * (|V_in| mu1 + m mu4 / sum A0)).
        The gradient is exact for J_s and 0 on the vertices that cannot move."""
        d = np.asarray(d, dtype=np.float64)
        F, mu = self.F, self.mu
        X = self.positions(d)
        P = X[F]  # (m,3,3)
        u = np.roll(P, -1, axis=1) - P  # corner k -> next corner
        w = np.roll(P, -2, axis=1) - P  # corner k -> previous corner
        nrm = _cross(u[:, 0], w[:, 0])  # 2 A n_f
        crn = np.sqrt(np.einsum("mc,mc->m", nrm, nrm))  # 2 A
        nrm /= np.maximum(crn, 1e-300)[:, None]
        uu = np.einsum("mkc,mkc->mk", u, u)
        ww = np.einsum("mkc,mkc->mk", w, w)
        ang = np.arctan2(crn[:, None], np.einsum("mkc,mkc->mk", u, w))
        theta = np.bincount(F.ravel(), weights=ang.ravel(), minlength=self.n)
        # term 1: sum_{V_in} s(theta - 2 pi);  d alpha_k / d x_next = -(n x u)/|u|^2, d/d x_prev = (n x w)/|w|^2
        x1 = np.where(self.interior, theta - TWO_PI, 0.0)
        r1 = np.sqrt(x1 * x1 + smooth * smooth)
        t1 = float(np.sum(np.where(self.interior, r1 - smooth, 0.0)))
        g1 = np.where(self.interior, x1 / r1, 0.0)[F]  # (m,3) weight of each corner's angle
        nb = nrm[:, None, :]
        d_next = -_cross(nb, u) * (g1 / uu)[..., None]
        d_prev = _cross(nb, w) * (g1 / ww)[..., None]
        corner_grad = -(d_next + d_prev) + np.roll(d_next, 1, axis=1) + np.roll(d_prev, 2, axis=1)
        # term 4: s(A - A0) / sum A0;  dA/dx_k = 0.5 n x (x_prev - x_next)
        A = 0.5 * crn
        x4 = A - self.A0
        r4 = np.sqrt(x4 * x4 + smooth * smooth)
        t4 = float(np.sum(r4 - smooth) / self.sum_A0)
        g4 = (x4 / r4) / self.sum_A0
        dA = _cross(nb, w - u) * (0.5 * g4)[:, None, None]
        corner_grad = mu[0] * corner_grad + mu[3] * dA
        gX = np.stack([np.bincount(F.ravel(), weights=corner_grad[..., c].ravel(), minlength=self.n)
                       for c in range(3)], axis=1)
        # term 2: sum_{V_in} ||L x||^2 -> 2 L_in^T L_in X
        LX = self._Lin @ self.smooth_positions(d)
        t2 = float(np.sum(LX * LX))
        gX += mu[1] * 2.0 * (self._Lin.T @ LX)
        t3 = float(np.sum(d * d))
        g = np.einsum("nc,nc->n", gX, self.N) + mu[2] * 2.0 * d
        g[~self.movable] = 0.0
        return float(mu @ np.array([t1, t2, t3, t4])), g

    # -------------------------------------------------------------- incremental
    def _base(self, d: np.ndarray) -> dict:
        """Per-vertex / per-face figures of the base offsets d, cached for `batch_values`."""
        key = d.tobytes()
        if self._base_key != key:
            X = self.positions(d)
            ang = corner_angles(X, self.F)
            theta = np.bincount(self.F.ravel(), weights=ang.ravel(), minlength=self.n)
            A = face_areas(X, self.F)
            S = self.smooth_positions(d)
            LX = np.zeros_like(X)
            LX[self.interior] = self._Lin @ S
            self._base_cache = {
                "X": X, "S": S, "theta": theta, "A": A, "LX": LX, "ang": ang,
                "terms": np.array([
                    float(np.abs(theta[self.interior] - TWO_PI).sum()), float(np.sum(LX * LX)),
                    float(np.sum(d * d)), float(np.abs(A - self.A0).sum() / self.sum_A0)]),
            }
            self._base_key = key
        return self._base_cache

    def _local(self, nodes: np.ndarray) -> dict:
        """The one-ring data of the vertex set ``nodes``, cached: the faces touching them, the
        interior vertices whose angle sum changes, the Laplacian rows that change and a local
        index of every vertex involved."""
        key = nodes.tobytes()
        if self._local_key == key:
            return self._local_cache
        topo = self.topo
        faces = np.unique(topo.vertex_faces[nodes].indices)
        tverts = np.unique(self.F[faces])
        tverts = tverts[self.interior[tverts]]
        ring = np.unique(np.r_[nodes, topo.vertex_adjacency[nodes].indices])
        rows = ring[self.interior[ring]]
        Lrows = self.L[rows]
        local = np.unique(np.r_[self.F[faces].ravel(), Lrows.indices, nodes])
        pos = np.full(self.n, -1, dtype=np.int64)
        pos[local] = np.arange(len(local))
        Floc = pos[self.F[faces]]
        # corner angle -> angle-sum scatter (|tverts| x 3|faces|), only corners at interior vertices
        tpos = np.full(self.n, -1, dtype=np.int64)
        tpos[tverts] = np.arange(len(tverts))
        cv = tpos[self.F[faces].ravel()]
        keep = cv >= 0
        S = sp.csr_matrix((np.ones(int(keep.sum())), (cv[keep], np.nonzero(keep)[0])),
                          shape=(len(tverts), 3 * len(faces)))
        Lloc = sp.csr_matrix((Lrows.data, pos[Lrows.indices], Lrows.indptr), shape=(len(rows), len(local)))
        self._local_cache = {"faces": faces, "tverts": tverts, "rows": rows, "local": local,
                             "Floc": Floc, "S": S, "Lloc": Lloc, "node_pos": pos[nodes]}
        self._local_key = key
        return self._local_cache

    def batch_values(self, d, nodes, D) -> np.ndarray:
        """Exact J (P,) of P candidates: d with d[nodes] = D[p].

        d (n,) base offsets, nodes (k,) vertex ids (distinct), D (P,k) absolute offsets of those
        vertices.  Incremental: only the triangles around ``nodes``, the angle sums of their
        vertices and the Laplacian rows of their one-rings are evaluated again, for all P at
        once; equal to [value(d') for each candidate] up to rounding."""
        d = np.asarray(d, dtype=np.float64)
        nodes = np.asarray(nodes, dtype=np.int64)
        D = np.atleast_2d(np.asarray(D, dtype=np.float64))
        if D.shape[1] != len(nodes):
            raise BolusError(f"D must have one column per node ({len(nodes)}), got shape {D.shape}")
        base = self._base(d)
        if len(nodes) == 0:
            return np.full(len(D), float(self.mu @ base["terms"]))
        loc = self._local(nodes)
        P = len(D)
        Xl = np.broadcast_to(base["X"][loc["local"]], (P, len(loc["local"]), 3)).copy()
        Xl[:, loc["node_pos"]] = self.X0[nodes] + self.N[nodes] * D[..., None]
        T = Xl[:, loc["Floc"]]  # (P, f, 3, 3)
        ang, A = _angles_areas_batch(T)  # (P, f, 3), (P, f)
        faces, tverts = loc["faces"], loc["tverts"]
        base_ang = base["ang"][faces].ravel()
        theta = base["theta"][tverts][None, :] + (loc["S"] @ (ang.reshape(P, -1) - base_ang[None, :]).T).T
        t1 = (base["terms"][0] - np.abs(base["theta"][tverts] - TWO_PI).sum()
              + np.abs(theta - TWO_PI).sum(axis=1))
        t4 = base["terms"][3] + (np.abs(A - self.A0[faces]).sum(axis=1)
                                 - np.abs(base["A"][faces] - self.A0[faces]).sum()) / self.sum_A0
        rows = loc["rows"]
        nl = len(loc["local"])
        if self.S0 is self.X0:
            Sl = Xl
        else:
            Sl = np.broadcast_to(base["S"][loc["local"]], (P, nl, 3)).copy()
            Sl[:, loc["node_pos"]] = self.S0[nodes] + self.N[nodes] * D[..., None]
        LX = (loc["Lloc"] @ Sl.transpose(1, 0, 2).reshape(nl, 3 * P)).reshape(len(rows), P, 3)
        t2 = base["terms"][1] - np.sum(base["LX"][rows] ** 2) + np.einsum("rpc,rpc->p", LX, LX)
        t3 = base["terms"][2] - float(np.sum(d[nodes] ** 2)) + np.sum(D * D, axis=1)
        mu = self.mu
        return mu[0] * t1 + mu[1] * t2 + mu[2] * t3 + mu[3] * t4
