"""Algorithm 3-1: topology and per-element geometry."""
import numpy as np
import pytest
from meshgen import grid, icosphere

from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.topology import MeshTopology, triangulate_polygons


def test_grid_counts_and_boundary():
    V, F = grid(4, 3)
    t = MeshTopology(V, F)
    # Euler: V - E + F = 1 for a disk
    assert t.n - len(t.edges) + t.m == 1
    assert t.boundary_edges.sum() == 2 * (4 + 3)
    assert t.boundary_vertices.sum() == 2 * (4 + 3)
    assert t.interior_vertices.sum() == 3 * 2
    assert set(np.unique(t.edge_face_count)) == {1, 2}
    assert not t.nonmanifold_vertices.any()
    # edge_faces agree with face_edges
    for f in range(t.m):
        for e in t.face_edges[f]:
            assert f in t.edge_faces[e]


def test_one_ring_of_grid_vertex():
    V, F = grid(2, 2)
    t = MeshTopology(V, F)
    centre = 4  # (1,1)
    ring = set(t.one_ring_vertices(centre).tolist())
    assert len(ring) == 6 and centre not in ring
    faces = t.one_ring_faces(centre)
    assert len(faces) == 6 and all(centre in F[f] for f in faces)


def test_geometry_of_a_known_triangle():
    V = np.array([[0.0, 0, 0], [3, 0, 0], [0, 4, 0]])
    F = np.array([[0, 1, 2]])
    t = MeshTopology(V, F)
    assert t.areas[0] == pytest.approx(6.0)
    np.testing.assert_allclose(t.centroids[0], [1, 4 / 3, 0])
    np.testing.assert_allclose(t.face_normals[0], [0, 0, 1])  # eq. 3-1, counter-clockwise
    np.testing.assert_allclose(t.angles[0], [np.pi / 2, np.arctan2(4, 3), np.arctan2(3, 4)])
    np.testing.assert_allclose(np.sort(t.edge_lengths), [3, 4, 5])


def test_vertex_normals_of_sphere_point_outward():
    V, F = icosphere(3)
    t = MeshTopology(V, F)
    cos = np.einsum("ij,ij->i", t.vertex_normals, V / np.linalg.norm(V, axis=1, keepdims=True))
    assert cos.min() > 0.999  # eq. 3-2


def test_polygons_are_triangulated_and_mapped_back():
    # a quad and a pentagon sharing an edge
    corners = np.array([0, 1, 2, 3, 1, 4, 5, 6, 2])
    sizes = np.array([4, 5])
    F, tri_face = triangulate_polygons(corners, sizes)
    assert F.shape == (2 + 3, 3)
    np.testing.assert_array_equal(tri_face, [0, 0, 1, 1, 1])
    assert set(F[tri_face == 0].ravel()) == {0, 1, 2, 3}
    assert set(F[tri_face == 1].ravel()) == {1, 4, 5, 6, 2}


def test_nonmanifold_edge_and_bowtie_vertex_detected():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]])
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])  # three faces on edge 0-1
    t = MeshTopology(V, F)
    assert t.nonmanifold_edges.sum() == 1
    assert t.nonmanifold_vertices[[0, 1]].all()
    # bow-tie: two triangles touching at one vertex only
    V2 = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [-1, 0, 0], [-1, -1, 0]])
    F2 = np.array([[0, 1, 2], [0, 3, 4]])
    t2 = MeshTopology(V2, F2)
    assert t2.vertex_fan_count[0] == 2 and t2.vertex_fan_count[1] == 1
    assert t2.nonmanifold_vertices[0] and not t2.interior_vertices[0]


def test_face_components():
    V, F = grid(2, 2)
    V2 = np.vstack([V, V + [10, 0, 0]])
    F2 = np.vstack([F, F + len(V)])
    n, comp = MeshTopology(V2, F2).face_components()
    assert n == 2 and len(set(comp[: len(F)])) == 1 and comp[0] != comp[-1]


def test_degenerate_faces_flagged():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]])
    F = np.array([[0, 1, 2], [0, 1, 3]])
    assert MeshTopology(V, F).degenerate_faces().tolist() == [True, False]


@pytest.mark.parametrize(
    "V,F,msg",
    [
        (np.zeros((3, 2)), np.array([[0, 1, 2]]), "vertices must be"),
        (np.zeros((3, 3)), np.array([[0, 1, 3]]), "outside"),
        (np.zeros((3, 3)), np.array([[0, 1, 1]]), "repeats"),
        (np.full((3, 3), np.nan), np.array([[0, 1, 2]]), "non-finite"),
        (np.zeros((3, 3)), np.array([[0.0, 1.0, 2.0]]), "integers"),
    ],
)
def test_bad_arrays_raise_value_error(V, F, msg):
    with pytest.raises(ValueError, match=msg):
        MeshTopology(V, F)
    with pytest.raises(BolusError):
        MeshTopology(V, F)


# ---------------------------------------------------------------- check_mesh / submesh
def _square():
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    return V, F


def test_check_mesh_names_coincident_vertices():
    from bolus_addon.core.mesh.topology import check_mesh

    V, F = _square()
    V = np.vstack([V, V[2]])  # vertex 4 sits on vertex 2
    F = np.vstack([F, [1, 2, 4]])
    with pytest.raises(BolusError, match=r"the patch has 1 zero-area triangle.*triangle 2 \(vertices 1, 2, 4\)"):
        check_mesh(V, F, "the patch")
    Vc, Fc = check_mesh(V, F, nondegenerate=False)
    assert Vc.dtype == np.float64 and Fc.dtype == np.int64


def test_check_mesh_names_nan_vertex_and_nonmanifold_edge():
    from bolus_addon.core.mesh.topology import check_mesh

    V, F = _square()
    Vn = V.copy()
    Vn[3, 1] = np.inf
    with pytest.raises(BolusError, match="vertex 3"):
        check_mesh(Vn, F)
    V2 = np.vstack([V, [[0.5, 0.5, 1.0]]])
    F2 = np.vstack([F, [[0, 2, 4]]])  # edge 0-2 now has three triangles
    check_mesh(V2, F2)  # allowed unless asked
    with pytest.raises(BolusError, match="non-manifold edge.*vertices 0 and 2"):
        check_mesh(V2, F2, manifold=True)
    with pytest.raises(BolusError, match="triangle 1 refers"):
        check_mesh(V, np.array([[0, 1, 2], [0, 2, 9]]))
    with pytest.raises(BolusError, match="at least 3"):
        check_mesh(V, F, min_faces=3)


def test_check_mesh_lets_needles_pass():
    from bolus_addon.core.mesh.topology import check_mesh

    V = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1e-4, 0]], dtype=float)  # smallest angle ~0.01 deg
    Vc, Fc = check_mesh(V, [[0, 1, 2]])
    assert np.array_equal(Fc, [[0, 1, 2]])


def test_submesh_compacts_and_keeps_order():
    from bolus_addon.core.analysis.spectral import submesh as spectral_submesh
    from bolus_addon.core.mesh.topology import submesh

    assert spectral_submesh is submesh  # one implementation, re-exported
    F = np.array([[0, 1, 2], [2, 3, 4], [4, 5, 6]])
    Fl, ids = submesh(F, np.array([False, True, True]))
    assert ids.tolist() == [2, 3, 4, 5, 6]
    assert np.array_equal(ids[Fl], F[1:])
    Fl2, ids2 = submesh(F, np.array([2]))
    assert np.array_equal(ids2[Fl2], F[[2]])


def test_surface_warnings_refuse_or_warn_with_user_indices():
    V, F = _square()
    V2 = np.vstack([V, [[0.5, 0.5, 1.0]]])
    F2 = np.vstack([F, [[0, 2, 4]]])
    topo = MeshTopology(V2, F2)
    ids = np.array([10, 11, 12, 13, 14])
    with pytest.raises(BolusError, match=r"The region has 1 non-manifold edges \(e.g. between vertices 10 and 12\)"):
        topo.surface_warnings(False, "the region", ids)
    (w,) = topo.surface_warnings(True, "the region", ids)
    assert "treated like boundary" in w
    assert MeshTopology(V, F).surface_warnings() == []
    Vd = np.vstack([V, V[2]])
    with pytest.raises(BolusError, match="on vertices 11, 12, 14"):
        MeshTopology(Vd, np.vstack([F, [1, 2, 4]])).surface_warnings(True, "the region", ids)
