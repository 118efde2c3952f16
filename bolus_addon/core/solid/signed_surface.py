"""Signed distance to a triangle surface, open or closed: the exact closest point on a
triangle (Ericson) and the sign from the pseudo-normal of the closest feature (Baerentzen &
Aanaes 2005: the face normal inside a face, the sum of the two face normals on an edge, the
angle-weighted normal at a vertex).  A face normal alone gives the wrong sign for points whose
closest point is an edge or a vertex where the surface bends.
Arrays: V (n,3) float64 mm, F (m,3) int64, points (k,3), barycentrics (k,3).
"""
from __future__ import annotations

import numpy as np

from ..mesh.topology import MeshTopology, corner_angles

__all__ = ["closest_on_triangles", "pseudo_normals", "feature_normals"]


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


def pseudo_normals(V, F, topo: MeshTopology, fn) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(fn (m,3) unit face normals, edge_pn (m,3,3): the pseudo-normal of the edge opposite
    corner j of each face (the sum of its faces' normals; the face's own on a border edge),
    vn_angle (n,3): the angle-weighted vertex normals)."""
    ang = corner_angles(V, F)
    van = np.zeros_like(V)
    for j in range(3):
        np.add.at(van, F[:, j], fn * ang[:, j:j + 1])
    ef = topo.edge_faces[topo.face_edges]  # (m,3,2): faces on edge F[j] -> F[j+1]
    other = np.where(ef[:, :, 0] == np.arange(len(F))[:, None], ef[:, :, 1], ef[:, :, 0])  # (m,3), -1 on border
    en = fn[:, None, :] + np.where(other[:, :, None] >= 0, fn[np.maximum(other, 0)], 0.0)
    edge_pn = np.stack([en[:, 1], en[:, 2], en[:, 0]], axis=1)  # (m,3,3): edge opposite corner j
    return fn, edge_pn, van


def feature_normals(FI, BC, F, fn, edge_pn, vn_angle) -> np.ndarray:
    """(k,3) the pseudo-normal of the feature each closest point lies on: faces FI (k,),
    barycentrics BC (k,3) with exact zeros on an edge and exact ones at a vertex (Ericson)."""
    PN = fn[FI].copy()
    for j in range(3):
        on_e = BC[:, j] == 0.0
        PN[on_e] = edge_pn[FI[on_e], j]
    Fv = F[FI]
    for j in range(3):
        on_v = BC[:, j] == 1.0
        PN[on_v] = vn_angle[Fv[on_v, j]]
    return PN
