"""Small measures and checks of a mesh as arrays: input arrays, zero-area and mis-oriented faces, polygons triangulated, face areas and normals, corner angles."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..errors import BolusError


def as_mesh_arrays(V, F) -> tuple[np.ndarray, np.ndarray]:
    """Validate and convert ``V`` (n,3) and ``F`` (m,3) to float64 / int64 arrays.

    Raises `BolusError` naming the first offender for wrong shapes, non-finite
    coordinates (vertex index), out-of-range indices or triangles that repeat a vertex
    (triangle index).  Zero-area triangles pass; `check_mesh` refuses them too.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3:
        raise BolusError(f"vertices must be an (n, 3) array, got shape {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3:
        raise BolusError(f"triangles must be an (m, 3) array, got shape {F.shape}")
    if F.size and not np.issubdtype(F.dtype, np.integer):
        raise BolusError("triangle indices must be integers")
    F = F.astype(np.int64, copy=False)
    bad = np.nonzero(~np.isfinite(V).all(axis=1))[0]
    if len(bad):
        raise BolusError(f"the mesh has {len(bad)} vertex(es) with non-finite (NaN or infinite) coordinates, "
                         f"e.g. vertex {int(bad[0])}")
    if F.size:
        out = np.nonzero(((F < 0) | (F >= len(V))).any(axis=1))[0]
        if len(out):
            raise BolusError(f"triangle {int(out[0])} refers to a vertex index outside the vertex array "
                             f"({len(V)} vertices)")
        rep = np.nonzero((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2]))[0]
        if len(rep):
            raise BolusError(f"{len(rep)} triangle(s) with a repeated vertex: triangle {int(rep[0])} repeats one of "
                             "its vertices (degenerate face)")
    return V, F


#: a triangle is "zero-area" below this times the squared median edge length: far
#: below any scan's noise, so only coincident or collinear corners are caught
ZERO_AREA_REL = 1e-10


def zero_area_mask(areas, edge_lengths, rel_tol: float = ZERO_AREA_REL) -> np.ndarray:
    """(m,) bool: areas (m,) below rel_tol * median(edge_lengths)^2 (the one zero-area test)."""
    areas = np.asarray(areas, dtype=np.float64)
    if len(areas) == 0:
        return np.zeros(0, dtype=bool)
    L = float(np.median(edge_lengths)) if len(edge_lengths) else 0.0
    return areas <= rel_tol * L * L


def refuse_zero_area(F, bad, what: str = "the mesh", vert_ids=None) -> None:
    """Raise BolusError naming the first triangle of F (m,3) where bad (m,) bool is set.

    Such a triangle (coincident or collinear vertices) has no angles and no shape, so
    angle sums (eq. 4-1), cotangent weights and springs (eq. 3-22) are undefined on it.
    vert_ids (n,) int, optional: the user's index of each vertex (the message names
    those, e.g. Blender's vertex indices of a selected region)."""
    bad = np.nonzero(bad)[0]
    if len(bad) == 0:
        return
    f = int(bad[0])
    i, j, k = (int(x) for x in (F[f] if vert_ids is None else np.asarray(vert_ids)[F[f]]))
    at = f"triangle {f} (vertices {i}, {j}, {k})" if vert_ids is None else f"the triangle on vertices {i}, {j}, {k}"
    raise BolusError(
        f"{what} has {len(bad)} zero-area triangle(s), e.g. {at}: "
        "coincident or collinear vertices; merge them first (Mesh > Clean Up > Merge by Distance, "
        "then Degenerate Dissolve)"
    )


def triangulate_polygons(corner_verts, face_sizes) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate polygons given Blender-style as a flat corner list.

    corner_verts (c,) int: vertex index of every corner, polygon after polygon.
    face_sizes (p,) int: number of corners of each polygon (>= 3).
    Returns ``F`` (m,3) int64 and ``tri_face`` (m,) int64, the polygon of each triangle.
    A polygon with k corners gives k-2 triangles (c0, ci, ci+1), i = 1..k-2, which is
    exact for convex polygons (the Blender layer uses Blender's own triangulation,
    which also handles concave n-gons).
    """
    corner_verts = np.asarray(corner_verts, dtype=np.int64)
    face_sizes = np.asarray(face_sizes, dtype=np.int64)
    if np.any(face_sizes < 3):
        raise BolusError("every polygon needs at least three corners")
    if face_sizes.sum() != len(corner_verts):
        raise BolusError("face sizes do not add up to the number of corners")
    starts = np.concatenate([[0], np.cumsum(face_sizes)[:-1]])
    ntri = face_sizes - 2
    tri_face = np.repeat(np.arange(len(face_sizes)), ntri)
    # index of the triangle inside its polygon: 0..k-3
    local = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    base = starts[tri_face]
    F = np.stack(
        [corner_verts[base], corner_verts[base + local + 1], corner_verts[base + local + 2]],
        axis=1,
    )
    return F, tri_face


def misoriented_faces(F) -> np.ndarray:
    """(m,) bool: the triangles of F (m,3) wound against the majority of their edge-connected
    piece (two triangles that share an edge agree when they walk it in opposite directions);
    all False when every piece is consistently wound.  A piece that cannot be wound
    consistently (a Moebius strip) has all its triangles flagged."""
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    m = len(F)
    if m == 0:
        return np.zeros(0, dtype=bool)
    he = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    lo, hi = he.min(axis=1), he.max(axis=1)
    order = np.lexsort((hi, lo))
    face = np.repeat(np.arange(m), 3)[order]
    fwd = (he[:, 0] < he[:, 1])[order]
    pair = (lo[order][1:] == lo[order][:-1]) & (hi[order][1:] == hi[order][:-1])
    a, b = face[:-1][pair], face[1:][pair]
    agree = fwd[:-1][pair] != fwd[1:][pair]
    # node f: triangle f as wound, node f + m: f turned over; agreeing neighbours join f-g and
    # f'-g', disagreeing ones f-g' and f'-g
    i = np.r_[a, a + m]
    j = np.r_[np.where(agree, b, b + m), np.where(agree, b + m, b)]
    G = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(2 * m, 2 * m))
    _, side = connected_components(G, directed=False)
    _, piece = connected_components(sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(m, m)), directed=False)
    first = np.full(piece.max() + 1, m)
    np.minimum.at(first, piece, np.arange(m))
    turned = side[:m] != side[first[piece]]  # against the piece's first triangle
    bad = side[:m] == side[m:]  # both ways in one class: not orientable
    n_turned = np.bincount(piece, weights=turned, minlength=len(first))
    n_all = np.bincount(piece, minlength=len(first))
    flag = np.where(n_turned[piece] * 2 > n_all[piece], ~turned, turned)
    return flag | bad[first[piece]]


def misoriented_text(F) -> str:
    """'12 of its 200 triangles point the other way' (`misoriented_faces`) for a refusal."""
    k = int(misoriented_faces(F).sum())
    m = len(np.asarray(F).reshape(-1, 3))
    return f"{k} of its {m} triangles point{'s' if k == 1 else ''} the other way"


def _face_cross(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    return np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])


def face_areas(V, F) -> np.ndarray:
    """Triangle areas (m,)."""
    return 0.5 * np.linalg.norm(_face_cross(V, F), axis=1)


def face_normals(V, F) -> np.ndarray:
    """Unit face normals (m,3), eq. 3-1 (right-hand rule on the corner order).

    A zero-area triangle gets the zero vector.
    """
    c = _face_cross(V, F)
    n = np.linalg.norm(c, axis=1, keepdims=True)
    return np.divide(c, n, out=np.zeros_like(c), where=n > 0)


def corner_angles(V, F) -> np.ndarray:
    """Inner angles (m,3): entry [f, k] is the angle of triangle f at corner F[f, k].

    Uses atan2(|a x b|, a . b), which stays accurate for needle triangles.
    """
    P = V[F]  # (m,3,3)
    a = np.roll(P, -1, axis=1) - P  # to next corner
    b = np.roll(P, -2, axis=1) - P  # to previous corner
    cr = np.linalg.norm(np.cross(a, b), axis=2)
    dt = np.einsum("mkc,mkc->mk", a, b)
    return np.arctan2(cr, dt)
