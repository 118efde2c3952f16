"""Mesh topology and per-element geometry: Algorithm 3-1 of the seed, vectorised.

`MeshTopology(V, F)` prepares, once, everything later steps ask of a triangle mesh:
edges with their faces, boundary and non-manifold elements, one-ring vertices and
faces (as sparse incidence matrices), face areas, centroids, inner angles, face
normals (eq. 3-1) and area-weighted vertex normals (eq. 3-2).  Quantities are
computed lazily and cached, so a caller that only needs angle sums pays for nothing
else.  Polygons with more than three corners are fan-triangulated by
`triangulate_polygons`, which also returns the triangle -> polygon map so results can
be taken back to the original faces.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..errors import BolusError
from .mesh_checks import (  # noqa: F401 (re-exported)
    as_mesh_arrays,
    ZERO_AREA_REL,
    zero_area_mask,
    refuse_zero_area,
    triangulate_polygons,
    misoriented_faces,
    misoriented_text,
    _face_cross,
    face_areas,
    face_normals,
    corner_angles,
)

__all__ = [
    "MeshTopology",
    "as_mesh_arrays",
    "check_mesh",
    "zero_area_mask",
    "refuse_zero_area",
    "submesh",
    "triangulate_polygons",
    "face_areas",
    "face_normals",
    "corner_angles",
    "misoriented_faces",
    "misoriented_text",
]


def check_mesh(V, F, what: str = "the mesh", *, nondegenerate: bool = True, manifold: bool = False,
               min_faces: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The core's one input check for a triangle mesh; returns ``(V, F)`` as float64 / int64.

    Parameters
    ----------
    V : (n,3) array_like, F : (m,3) array_like of int
    what : how the message names the mesh ("the patch", "part 2", ...)
    nondegenerate : refuse zero-area triangles (coincident or collinear vertices), which
        have no angles (eq. 4-1) and no spring rest shape (eq. 3-22)
    manifold : refuse edges shared by more than two triangles
    min_faces : refuse meshes with fewer triangles

    Raises `BolusError` naming the problem and where (vertex / triangle / edge index);
    see `as_mesh_arrays` for the array checks.  Needle triangles (tiny angles but a
    positive area) pass: the cotangent weights and springs stay finite on them.  A caller
    that holds the mesh's `MeshTopology` calls its `require_valid` instead (no rebuild).
    """
    V, F = as_mesh_arrays(V, F)
    if len(F) < min_faces:
        raise BolusError(f"{what} has {len(F)} triangle(s); at least {min_faces} are needed")
    if not (nondegenerate or manifold) or len(F) == 0:
        return V, F
    MeshTopology(V, F).require_valid(what, nondegenerate=nondegenerate, manifold=manifold)
    return V, F


def submesh(F, face_mask) -> tuple[np.ndarray, np.ndarray]:
    """The triangles selected by ``face_mask`` with compacted vertex indices.

    Parameters: F (m,3) int; face_mask (m,) bool or an index array.
    Returns ``(F_local (k,3) int64, vert_ids (j,) int64)``: ``F_local`` indexes
    ``vert_ids``, the sorted original indices of the vertices used, so the sub-mesh is
    ``(V[vert_ids], F_local)``.  This is the one implementation; callers never inline it.
    """
    Fs = np.asarray(F, dtype=np.int64)[face_mask]
    vert_ids, inv = np.unique(Fs.ravel(), return_inverse=True)
    return inv.reshape(-1, 3).astype(np.int64), vert_ids.astype(np.int64)


class MeshTopology:
    """Topological data structure of a triangle mesh (Algorithm 3-1).

    Attributes (all numpy arrays, computed on first access):
      edges (e,2)            sorted vertex pairs, unique
      face_edges (m,3)       edge index of side k (F[f,k] -> F[f,k+1])
      edge_face_count (e,)   number of faces on each edge (1 boundary, 2 manifold, >2 non-manifold)
      edge_faces (e,2)       the first two faces of each edge, -1 where missing
      edge_lengths (e,)
      boundary_edges (e,) bool, nonmanifold_edges (e,) bool
      boundary_vertices (n,) bool, vertex_fan_count (n,), interior_vertices (n,) bool
      used_vertices (n,) bool  vertices referenced by at least one triangle
      vertex_adjacency (n,n) csr  one-ring vertices (N^i), 1 where an edge joins them
      vertex_faces (n,m) csr      one-ring triangles (F^i)
      face_adjacency (m,m) csr    faces sharing an edge (dual graph)
      areas (m,), centroids (m,3), angles (m,3), face_normals (m,3) (eq. 3-1),
      vertex_normals (n,3) (eq. 3-2), angle_sums (n,) (theta of eq. 4-1)
    """

    def __init__(self, V, F):
        self.V, self.F = as_mesh_arrays(V, F)
        self.n = len(self.V)
        self.m = len(self.F)

    # ------------------------------------------------------------------ edges
    @cached_property
    def _halfedges(self) -> tuple[np.ndarray, np.ndarray]:
        F = self.F
        he = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)  # (3m,2)
        lo, hi = np.minimum(he[:, 0], he[:, 1]), np.maximum(he[:, 0], he[:, 1])
        key = lo * max(self.n, 1) + hi  # 1-D keys: much faster than np.unique(axis=0)
        ukey, inverse = np.unique(key, return_inverse=True)
        edges = np.stack([ukey // max(self.n, 1), ukey % max(self.n, 1)], axis=1)
        return edges, inverse.reshape(-1)

    @cached_property
    def edges(self) -> np.ndarray:
        return self._halfedges[0]

    @cached_property
    def face_edges(self) -> np.ndarray:
        return self._halfedges[1].reshape(-1, 3)

    @cached_property
    def edge_face_count(self) -> np.ndarray:
        return np.bincount(self._halfedges[1], minlength=len(self.edges))

    @cached_property
    def _halfedge_order(self) -> np.ndarray:
        """Half-edge ids h = 3 f + i (from F[f, i] to F[f, i+1]) sorted by edge (stable)."""
        return np.argsort(self._halfedges[1], kind="stable")

    @cached_property
    def _edge_face_sorted(self) -> tuple[np.ndarray, np.ndarray]:
        """Half-edges sorted by edge: (edge id, face id) in that order."""
        order = self._halfedge_order
        return self._halfedges[1][order], order // 3

    @cached_property
    def edge_faces(self) -> np.ndarray:
        eid, fid = self._edge_face_sorted
        out = np.full((len(self.edges), 2), -1, dtype=np.int64)
        first = np.ones(len(eid), dtype=bool)
        first[1:] = eid[1:] != eid[:-1]
        out[eid[first], 0] = fid[first]
        second = np.zeros(len(eid), dtype=bool)
        second[1:] = (eid[1:] == eid[:-1]) & first[:-1]
        out[eid[second], 1] = fid[second]
        return out

    @cached_property
    def edge_lengths(self) -> np.ndarray:
        E = self.edges
        return np.linalg.norm(self.V[E[:, 0]] - self.V[E[:, 1]], axis=1)

    @cached_property
    def boundary_edges(self) -> np.ndarray:
        return self.edge_face_count == 1

    @cached_property
    def nonmanifold_edges(self) -> np.ndarray:
        return self.edge_face_count > 2

    # --------------------------------------------------------------- vertices
    @cached_property
    def used_vertices(self) -> np.ndarray:
        used = np.zeros(self.n, dtype=bool)
        used[self.F.ravel()] = True
        return used

    @cached_property
    def boundary_vertices(self) -> np.ndarray:
        b = np.zeros(self.n, dtype=bool)
        b[self.edges[self.boundary_edges].ravel()] = True
        return b

    @cached_property
    def vertex_fan_count(self) -> np.ndarray:
        """Number of triangle fans around each vertex (1 on a manifold vertex).

        Corners of the same vertex are joined across every edge they share; a vertex
        whose corners fall into several groups is a non-manifold ("bow-tie") vertex.
        """
        m = self.m
        eid, _ = self._edge_face_sorted
        order = self._halfedge_order
        # consecutive half-edges h1, h2 of one edge: their corners at the same vertex are joined
        same = np.nonzero(eid[1:] == eid[:-1])[0]
        h1, h2 = order[same], order[same + 1]
        Fr = self.F.ravel()
        e1, e2 = 3 * (h1 // 3) + (h1 % 3 + 1) % 3, 3 * (h2 // 3) + (h2 % 3 + 1) % 3  # the corners they end at
        along = Fr[h1] == Fr[h2]  # both run the same way (inconsistent winding)
        rows = np.r_[h1, e1]
        cols = np.r_[np.where(along, h2, e2), np.where(along, e2, h2)]
        G = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * m, 3 * m))
        ncomp, comp = connected_components(G, directed=False)
        # every component is the corners of one vertex: count the components of each vertex
        comp_vertex = np.zeros(ncomp, dtype=np.int64)
        comp_vertex[comp] = Fr
        return np.bincount(comp_vertex, minlength=self.n)

    @cached_property
    def nonmanifold_vertices(self) -> np.ndarray:
        """Vertices on a non-manifold edge or with several fans (bow-tie)."""
        bad = self.vertex_fan_count > 1
        bad[self.edges[self.nonmanifold_edges].ravel()] = True
        return bad

    @cached_property
    def interior_vertices(self) -> np.ndarray:
        """Used vertices that are neither on the boundary nor non-manifold."""
        return self.used_vertices & ~self.boundary_vertices & ~self.nonmanifold_vertices

    # ------------------------------------------------------- one-ring (sparse)
    @cached_property
    def vertex_adjacency(self) -> sp.csr_matrix:
        E = self.edges
        n = self.n
        A = sp.coo_matrix(
            (np.ones(2 * len(E)), (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(n, n)
        )
        return A.tocsr()

    @cached_property
    def vertex_faces(self) -> sp.csr_matrix:
        m = self.m
        rows = self.F.ravel()
        cols = np.repeat(np.arange(m), 3)
        return sp.csr_matrix((np.ones(3 * m), (rows, cols)), shape=(self.n, m))

    def one_ring_vertices(self, i: int) -> np.ndarray:
        """N^i: indices of the vertices sharing an edge with vertex i."""
        A = self.vertex_adjacency
        return A.indices[A.indptr[i] : A.indptr[i + 1]]

    def one_ring_faces(self, i: int) -> np.ndarray:
        """F^i: indices of the triangles that contain vertex i."""
        A = self.vertex_faces
        return A.indices[A.indptr[i] : A.indptr[i + 1]]

    @cached_property
    def face_adjacency_pairs(self) -> np.ndarray:
        """(k,2) pairs of faces that share an edge (consecutive faces on non-manifold edges)."""
        eid, fid = self._edge_face_sorted
        same = np.nonzero(eid[1:] == eid[:-1])[0]
        return np.stack([fid[same], fid[same + 1]], axis=1)

    @cached_property
    def face_adjacency_edges(self) -> np.ndarray:
        """(k,) edge index of each pair in `face_adjacency_pairs`."""
        eid, _ = self._edge_face_sorted
        same = np.nonzero(eid[1:] == eid[:-1])[0]
        return eid[same]

    @cached_property
    def face_adjacency(self) -> sp.csr_matrix:
        P = self.face_adjacency_pairs
        m = self.m
        A = sp.coo_matrix(
            (np.ones(2 * len(P)), (np.r_[P[:, 0], P[:, 1]], np.r_[P[:, 1], P[:, 0]])), shape=(m, m)
        )
        return A.tocsr()

    def face_components(self, mask=None) -> tuple[int, np.ndarray]:
        """Edge-connected components of the faces.

        mask: optional (m,) int labels; faces are joined only when their labels agree.
        Returns (count, component (m,) int).
        """
        P = self.face_adjacency_pairs
        if mask is not None:
            mask = np.asarray(mask)
            P = P[mask[P[:, 0]] == mask[P[:, 1]]]
        G = sp.coo_matrix((np.ones(len(P)), (P[:, 0], P[:, 1])), shape=(self.m, self.m))
        return connected_components(G, directed=False)

    # ---------------------------------------------------------------- geometry
    @cached_property
    def areas(self) -> np.ndarray:
        return face_areas(self.V, self.F)

    @cached_property
    def centroids(self) -> np.ndarray:
        return self.V[self.F].mean(axis=1)

    @cached_property
    def angles(self) -> np.ndarray:
        return corner_angles(self.V, self.F)

    @cached_property
    def face_normals(self) -> np.ndarray:
        """Eq. 3-1."""
        return face_normals(self.V, self.F)

    @cached_property
    def vertex_normals(self) -> np.ndarray:
        """Eq. 3-2: sum of area(f) N(f) over the one-ring triangles, normalised (Taubin)."""
        w = self.face_normals * self.areas[:, None]
        N = np.zeros((self.n, 3))
        for k in range(3):
            np.add.at(N, self.F[:, k], w)
        ln = np.linalg.norm(N, axis=1, keepdims=True)
        return np.divide(N, ln, out=np.zeros_like(N), where=ln > 0)

    @cached_property
    def angle_sums(self) -> np.ndarray:
        """theta(v) of eq. 4-1: the sum of the inner angles at each vertex (n,)."""
        return np.bincount(self.F.ravel(), weights=self.angles.ravel(), minlength=self.n)

    @cached_property
    def mean_edge_length(self) -> float:
        return float(self.edge_lengths.mean()) if len(self.edges) else 0.0

    def require_valid(self, what: str = "the mesh", *, nondegenerate: bool = True, manifold: bool = False) -> None:
        """`check_mesh` on this topology (its arrays were checked when it was built)."""
        if self.m == 0:
            raise BolusError(f"{what} has 0 triangle(s); at least 1 are needed")
        if nondegenerate:
            self.require_nondegenerate(what)
        if manifold:
            bad = np.nonzero(self.nonmanifold_edges)[0]
            if len(bad):
                i, j = (int(x) for x in self.edges[bad[0]])
                raise BolusError(f"{what} has {len(bad)} non-manifold edge(s) (shared by more than two triangles), "
                                 f"e.g. the edge between vertices {i} and {j}; Select > Select All by Trait > "
                                 "Non Manifold shows them: delete the extra faces there")

    def require_nondegenerate(self, what: str = "the mesh", vert_ids=None) -> None:
        """Raise BolusError naming the first zero-area triangle (`refuse_zero_area`)."""
        refuse_zero_area(self.F, self.degenerate_faces(), what, vert_ids)

    def surface_warnings(self, allow_nonmanifold: bool = False, what: str = "the region", vert_ids=None) -> list[str]:
        """Check a surface before analysis; return the warnings to show.

        Zero-area triangles are refused (`require_nondegenerate`); non-manifold edges and
        bow-tie vertices are refused unless ``allow_nonmanifold`` (saliency can treat their
        vertices like boundary vertices, flattenability 0), then they give a warning.
        vert_ids (n,) int, optional: the user's vertex indices, used in messages.
        """
        self.require_nondegenerate(what, vert_ids)
        nm = int(self.nonmanifold_edges.sum())
        nmv = int((self.vertex_fan_count > 1).sum())
        if not (nm or nmv):
            return []
        ids = np.arange(self.n) if vert_ids is None else np.asarray(vert_ids)
        if nm:
            i, j = (int(x) for x in ids[self.edges[np.argmax(self.nonmanifold_edges)]])
            where = f"{nm} non-manifold edges (e.g. between vertices {i} and {j})"
        else:
            where = f"{nmv} non-manifold vertices (e.g. vertex {int(ids[np.argmax(self.vertex_fan_count > 1)])})"
        if not allow_nonmanifold:
            raise BolusError(
                f"{what[0].upper() + what[1:]} has {where}; a bolus must be a manifold surface: find them with "
                "Select > Select All by Trait > Non Manifold and delete the extra faces there (an edge may border "
                "two faces, a vertex one fan of faces), or select only the faces to work on"
            )
        return [f"{where}: their vertices are treated like boundary vertices (flattenability 0)"]

    def degenerate_faces(self) -> np.ndarray:
        """(m,) bool: the zero-area triangles (`zero_area_mask`), computed once."""
        return self._zero_area

    @cached_property
    def _zero_area(self) -> np.ndarray:
        return zero_area_mask(self.areas, self.edge_lengths)
