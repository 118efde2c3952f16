"""Normal curvature by the Moreton-Sequin estimate (seed 6.1.3, eqs. 6-15..6-20).

Eq. 6-17 gives one value per neighbour j of a vertex i:
    k_ij = 2 n_i . (v_j - v_i) / |v_j - v_i|^2
with n_i the area-weighted vertex normal (eq. 3-2).  The vertex value is the mean over
its one-ring edges (the mean of the normal curvatures in the edge directions, close to
the mean curvature); the face value is the mean of its corners (eq. 6-18).  With
outward normals a convex surface is negative and a concave one positive (eq. 6-19).
Eq. 6-20 maps the face values to [0, 1] between the 1st and 99th percentiles
(``spectral.unit_interval``) so one spike does not squash every other value.

Degenerate input: NaN/inf and bad indices are refused (`topology.check_mesh`).
Coincident vertices (an edge of length 0) are sound: that edge has no direction and is
left out of the vertex's mean (it counts as 0); a vertex whose normal is the zero
vector (all its faces of zero area) gets curvature 0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .spectral import unit_interval
from ..mesh.topology import MeshTopology, check_mesh

__all__ = ["NormalCurvature", "normal_curvature"]


@dataclass
class NormalCurvature:
    """Moreton-Sequin normal curvature (1/mm): per vertex (n,) eq. 6-17 averaged over the
    one ring, per face (m,) eq. 6-18, and the face values mapped to [0, 1] (eq. 6-20)."""

    vertex: np.ndarray
    face: np.ndarray
    face_normalised: np.ndarray

    def concave(self, eps: float = 0.0) -> np.ndarray:
        """(m,) bool: eq. 6-19, K(f) > eps (concave for outward normals)."""
        return self.face > eps


def normal_curvature(V, F, topo: MeshTopology | None = None) -> NormalCurvature:
    """Eqs. 6-15..6-20 on a triangle mesh (module doc).

    Parameters: V (n,3) mm, F (m,3) int; ``topo`` a `MeshTopology` of (V, F) already built.
    Returns a `NormalCurvature` with vertex (n,), face (m,) and face_normalised (m,), 1/mm.
    """
    topo = MeshTopology(*check_mesh(V, F, nondegenerate=False)) if topo is None else topo
    E = topo.edges
    Nv = topo.vertex_normals
    d = topo.V[E[:, 1]] - topo.V[E[:, 0]]
    dd = np.einsum("ij,ij->i", d, d)
    dd = np.where(dd > 0, dd, np.inf)  # a zero-length edge has no direction: it adds 0
    k01 = 2.0 * np.einsum("ij,ij->i", Nv[E[:, 0]], d) / dd  # eq. 6-17 at E[:,0] towards E[:,1]
    k10 = -2.0 * np.einsum("ij,ij->i", Nv[E[:, 1]], d) / dd
    n = topo.n
    s = np.bincount(E[:, 0], weights=k01, minlength=n) + np.bincount(E[:, 1], weights=k10, minlength=n)
    c = np.bincount(E.ravel(), minlength=n)
    Kv = np.divide(s, c, out=np.zeros(n), where=c > 0)
    Kf = Kv[topo.F].mean(axis=1)  # eq. 6-18
    return NormalCurvature(Kv, Kf, unit_interval(Kf))  # eq. 6-20
