"""Patches that are not disks are cut to a disk along short paths."""
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from paths import data_mesh
from meshgen import grid, grid_with_holes, icosphere, ring_surface, torus

from bolus_addon.core.mesh.boundary import boundary_loops, cut_to_disk, loop_length, split_along_edges, surface_type
from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.objfile import load_obj
from bolus_addon.core.mesh.topology import MeshTopology


def polygon_area(P):
    return 0.5 * np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])


def flat_annulus(r_out=80.0, r_in=40.0, nr=8, na=48):
    profile = np.stack([np.linspace(r_out, r_in, nr), np.zeros(nr)], 1)
    V, F, _ = ring_surface(profile, na=na, pole=False)
    return V, F


def knee_tube(radius=45.0, length=120.0, nl=12, na=32):
    profile = np.stack([np.full(nl + 1, radius), np.linspace(0, length, nl + 1)], 1)
    V, F, _ = ring_surface(profile, na=na, pole=False)
    return V, F


def tetrahedron():
    V = np.array([[0.0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]])
    F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    return V, F


# ------------------------------------------------------------- boundary loops
def test_boundary_loop_of_grid_is_ordered_and_counter_clockwise():
    V, F = grid(4, 3, size=40.0)
    (loop,) = boundary_loops(F)
    assert len(loop) == 2 * (4 + 3) and len(set(loop.tolist())) == len(loop)
    t = MeshTopology(V, F)
    E = {tuple(e) for e in t.edges[t.boundary_edges].tolist()}
    steps = {tuple(sorted(p)) for p in zip(loop.tolist(), np.roll(loop, -1).tolist())}
    assert steps == E  # consecutive loop vertices are exactly the boundary edges
    assert polygon_area(V[loop, :2]) > 0  # follows the counter-clockwise triangles
    assert loop_length(V, loop) == pytest.approx(2 * (40 + 40))


def test_boundary_loops_of_grid_with_holes():
    V, F = grid_with_holes(12, 12, 120.0, holes=((2, 2, 4, 4), (7, 6, 9, 10)))
    loops = boundary_loops(F)
    assert [len(lp) for lp in loops] == [48, 12, 8]  # longest first
    areas = [polygon_area(V[lp, :2]) for lp in loops]
    assert areas[0] == pytest.approx(120.0**2)  # outer loop counter-clockwise
    assert areas[1] == pytest.approx(-800.0) and areas[2] == pytest.approx(-400.0)  # holes clockwise


def test_boundary_loop_runs_twice_through_a_pinched_vertex():
    # two holes touching at one vertex: one inner loop passes that vertex twice
    V, F = grid_with_holes(5, 5, 50.0, holes=((1, 1, 2, 2), (2, 2, 3, 3)))
    loops = boundary_loops(F)
    assert [len(lp) for lp in loops] == [20, 8]
    inner = loops[1].tolist()
    pinch = [v for v in set(inner) if inner.count(v) == 2]
    assert len(pinch) == 1 and MeshTopology(V, F).vertex_fan_count[pinch[0]] == 2
    t = MeshTopology(V, F)
    B = {tuple(e) for e in t.edges[t.boundary_edges].tolist()}
    assert {tuple(sorted(p)) for p in zip(inner, inner[1:] + inner[:1])} | {
        tuple(sorted(p)) for p in zip(loops[0].tolist(), np.roll(loops[0], -1).tolist())} == B


def test_closed_surface_has_no_boundary_loop():
    assert boundary_loops(icosphere(1)[1]) == []


# -------------------------------------------------------------- surface type
@pytest.mark.parametrize(
    "mesh,chi,loops,genus,disk",
    [
        (grid(5, 4), 1, 1, 0, True),
        (flat_annulus(), 0, 2, 0, False),
        (knee_tube(), 0, 2, 0, False),
        (grid_with_holes(holes=((2, 2, 4, 4), (7, 6, 9, 10))), -1, 3, 0, False),
        (icosphere(2), 2, 0, 0, False),
        (torus(), 0, 0, 1, False),
    ],
    ids=["disk", "annulus", "tube", "two-holes", "sphere", "torus"],
)
def test_surface_type(mesh, chi, loops, genus, disk):
    st = surface_type(*mesh)
    assert st["euler_characteristic"] == chi
    assert st["boundary_loops"] == loops
    assert st["genus"] == genus
    assert st["components"] == 1
    assert st["is_disk"] is disk
    assert st["orientable"] and st["consistently_oriented"]


def test_surface_type_flags_parts_orientation_and_nonmanifold_edges():
    V, F = grid(2, 2)
    st = surface_type(np.vstack([V, V + [50, 0, 0]]), np.vstack([F, F + len(V)]))
    assert st["components"] == 2 and st["genus"] == 0 and not st["is_disk"]
    F2 = F.copy()
    F2[0] = F2[0, ::-1]
    st = surface_type(V, F2)
    assert st["orientable"] and not st["consistently_oriented"] and st["is_disk"]
    Vn = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]])
    Fn = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    st = surface_type(Vn, Fn)
    assert st["nonmanifold_edges"] == 1 and st["boundary_loops"] is None and not st["is_disk"]


def test_moebius_strip_is_not_orientable():
    n = 24
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V = np.concatenate([
        np.stack([(50 + s * np.cos(t / 2)) * np.cos(t), (50 + s * np.cos(t / 2)) * np.sin(t), s * np.sin(t / 2)], 1)
        for s in (10.0, -10.0)
    ])
    F = []
    for i in range(n):
        j = (i + 1) % n
        a, b = i, n + i
        c, d = (j, n + j) if j else (n + j, j)  # the strip comes back with its sides swapped
        F += [[a, b, d], [a, d, c]]
    st = surface_type(V, np.array(F))
    assert not st["orientable"] and st["boundary_loops"] == 1 and st["genus"] is None
    with pytest.raises(BolusError, match="not orientable"):
        cut_to_disk(V, np.array(F))


# ---------------------------------------------------------------- splitting
def test_split_along_a_path_across_a_grid_gives_two_pieces():
    V, F = grid(4, 4)  # vertex (i, j) is 5 i + j
    path = np.array([5 * i + 2 for i in range(5)])  # the line j = 2 from one side to the other
    F2, origin = split_along_edges(F, np.stack([path[:-1], path[1:]], 1))
    assert F2.shape == F.shape
    np.testing.assert_array_equal(origin[F2], F)  # same faces, same original vertices
    np.testing.assert_array_equal(origin[: len(V)], np.arange(len(V)))
    assert len(origin) == len(V) + len(path) and sorted(origin[len(V):].tolist()) == sorted(path.tolist())
    n, _ = MeshTopology(V[origin], F2).face_components()
    assert n == 2


def test_split_along_interior_path_makes_a_slit():
    V, F = grid(4, 4)
    path = np.array([6, 12, 18])  # interior diagonal (1,1) - (2,2) - (3,3), edges of the grid
    F2, origin = split_along_edges(F, np.stack([path[:-1], path[1:]], 1))
    assert len(origin) == len(V) + 1 and origin[-1] == 12  # only the middle vertex is doubled
    st = surface_type(V[origin], F2)
    assert st["boundary_loops"] == 2 and st["euler_characteristic"] == 0
    t = MeshTopology(V[origin], F2)
    assert t.boundary_edges.sum() == 16 + 4


def test_split_with_no_cut_only_separates_pinched_vertices():
    V, F = grid(3, 3)
    F2, origin = split_along_edges(F, np.zeros((0, 2), dtype=int))
    np.testing.assert_array_equal(F2, F)
    np.testing.assert_array_equal(origin, np.arange(len(V)))
    Vb = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [-1, 0, 0], [-1, -1, 0]])
    Fb = np.array([[0, 1, 2], [0, 3, 4]])  # bow-tie at vertex 0
    F3, origin = split_along_edges(Fb, np.zeros((0, 2), dtype=int))
    np.testing.assert_array_equal(F3, [[0, 1, 2], [5, 3, 4]])
    np.testing.assert_array_equal(origin, [0, 1, 2, 3, 4, 0])


def test_split_rejects_an_edge_that_is_not_in_the_mesh():
    _, F = grid(2, 2)
    with pytest.raises(BolusError, match="not an edge"):
        split_along_edges(F, [[0, 8]])


# ------------------------------------------------------------------ cutting
def assert_valid_cut(V, F, res, n_paths):
    """Disk, same faces, paths on the input's interior edges joining different loops."""
    st = surface_type(res.V, res.F)
    assert st["is_disk"], st
    assert (st["components"], st["boundary_loops"], st["euler_characteristic"]) == (1, 1, 1)
    assert res.F.shape == F.shape
    np.testing.assert_array_equal(res.vert_origin[res.F], F)
    np.testing.assert_array_equal(res.V, V[res.vert_origin])
    np.testing.assert_array_equal(res.vert_origin[: len(V)], np.arange(len(V)))
    assert len(res.cut_paths) == n_paths
    t = MeshTopology(V, F)
    E = {tuple(e) for e in t.edges.tolist()}
    B = {tuple(e) for e in t.edges[t.boundary_edges].tolist()}
    total = 0.0
    for p in res.cut_paths:
        assert len(p) >= 2 and len(set(p.tolist())) == len(p)  # a simple path
        steps = [tuple(sorted(s)) for s in zip(p[:-1].tolist(), p[1:].tolist())]
        assert all(s in E for s in steps) and not any(s in B for s in steps)  # never along a boundary
        total += np.linalg.norm(np.diff(V[p], axis=0), axis=1).sum()
        if t.boundary_vertices.any():
            assert t.boundary_vertices[p[[0, -1]]].all()
            assert not t.boundary_vertices[p[1:-1]].any()  # runs through the interior
        # the cut edges are boundary twice in the result
        tr = MeshTopology(res.V, res.F)
        be = tr.edges[tr.boundary_edges]
        ob = np.sort(res.vert_origin[be], axis=1)
        for s in steps:
            assert np.sum(np.all(ob == s, axis=1)) == 2
    assert res.cut_length_mm == pytest.approx(total)
    for p in res.cut_paths:
        assert f"{int(p[0])} and {int(p[-1])}" in res.description
    assert "mm" in res.description


def test_disk_is_not_cut():
    V, F = grid(5, 5)
    res = cut_to_disk(V, F)
    assert not res.was_cut and res.cut_length_mm == 0.0
    np.testing.assert_array_equal(res.F, F)
    np.testing.assert_array_equal(res.V, V)
    assert "no cut" in res.description


def test_annulus_is_cut_radially():
    V, F = flat_annulus(80.0, 40.0, nr=8)
    res = cut_to_disk(V, F)
    assert_valid_cut(V, F, res, 1)
    assert res.cut_length_mm == pytest.approx(40.0)  # the shortest way across is radial
    loops = boundary_loops(F)
    p = res.cut_paths[0]
    assert {p[0] in loops[0], p[-1] in loops[0]} == {True, False}
    assert "40.0 mm path joining the boundary loops at vertices" in res.description


def test_grid_with_a_hole():
    V, F = grid_with_holes(12, 12, 120.0, holes=((4, 4, 8, 8),))
    res = cut_to_disk(V, F)
    assert_valid_cut(V, F, res, 1)
    assert res.cut_length_mm == pytest.approx(40.0)


def test_knee_like_tube_is_cut_along_its_length():
    V, F = knee_tube(45.0, 120.0)
    res = cut_to_disk(V, F)
    assert_valid_cut(V, F, res, 1)
    assert res.cut_length_mm == pytest.approx(120.0)


def test_grid_with_two_holes_gets_two_cuts_that_do_not_cross():
    V, F = grid_with_holes(12, 12, 120.0, holes=((2, 2, 4, 4), (7, 6, 9, 10)))
    res = cut_to_disk(V, F)
    assert_valid_cut(V, F, res, 2)
    p, q = res.cut_paths
    assert not set(p[1:-1].tolist()) & set(q.tolist()) and not set(q[1:-1].tolist()) & set(p.tolist())
    assert res.cut_length_mm == pytest.approx(20.0 + 20.0)  # each hole is two cells from the edge
    assert res.description.startswith("cut along 2 paths (40.0 mm in all)")


def test_holes_close_together_are_chained_not_crossed():
    # the second hole is nearer to the first hole than to the outer edge: the greedy
    # tree may end its cut on the first hole or its cut, never crossing it
    V, F = grid_with_holes(16, 16, 160.0, holes=((3, 6, 6, 10), (8, 6, 11, 10)))
    res = cut_to_disk(V, F)
    assert_valid_cut(V, F, res, 2)


def test_closed_sphere_is_cut_between_far_vertices():
    V, F = icosphere(2, 50.0)
    res = cut_to_disk(V, F)
    assert_valid_cut(V, F, res, 1)
    p = res.cut_paths[0]
    assert len(p) >= 3
    assert np.linalg.norm(V[p[0]] - V[p[-1]]) == pytest.approx(100.0)  # antipodal vertices of a 50 mm sphere
    assert res.cut_length_mm == pytest.approx(165.5, rel=0.15)  # measured; the half great circle is 157.1 mm
    assert len(res.V) == len(V) + len(p) - 2  # inner path vertices are doubled
    assert "closed" in res.description


def test_closed_tetrahedron_gets_a_cut_of_two_edges():
    V, F = tetrahedron()
    res = cut_to_disk(V, F)
    assert_valid_cut(V, F, res, 1)
    assert len(res.cut_paths[0]) == 3


def test_pinched_vertex_is_split():
    V, F = grid_with_holes(4, 4, 40.0, holes=((0, 0, 1, 1), (1, 1, 2, 2)))  # notch and hole touch at a vertex
    assert len(boundary_loops(F)) == 1 and not surface_type(V, F)["is_disk"]
    res = cut_to_disk(V, F)
    assert surface_type(res.V, res.F)["is_disk"]
    assert len(res.V) == len(V) + 1 and not res.cut_paths
    np.testing.assert_array_equal(res.vert_origin[res.F], F)
    assert "pinched" in res.description
    V, F = grid_with_holes(5, 5, 50.0, holes=((1, 1, 2, 2), (2, 2, 3, 3)))  # two holes touching
    res = cut_to_disk(V, F)
    assert surface_type(res.V, res.F)["is_disk"] and len(res.cut_paths) == 1


@pytest.mark.parametrize(
    "mesh,match",
    [
        (torus(), "genus 1.*segment it into more patches"),
        ((np.vstack([grid(2, 2)[0], grid(2, 2)[0] + [50, 0, 0]]), np.vstack([grid(2, 2)[1], grid(2, 2)[1] + 9])),
         "2 separate parts"),
        ((np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]]),
          np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])), "more than two faces"),
    ],
    ids=["torus", "two-parts", "non-manifold"],
)
def test_what_cannot_be_cut_raises_bolus_error(mesh, match):
    with pytest.raises(BolusError, match=match):
        cut_to_disk(*mesh)


def shortest_interior_distance(V, F):
    """Independent check: shortest path over interior edges between the two boundary loops."""
    t = MeshTopology(V, F)
    E = t.edges[~t.boundary_edges]
    L = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    G = sp.coo_matrix((np.r_[L, L], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(len(V),) * 2)
    a, b = boundary_loops(F)[:2]
    return float(dijkstra(G.tocsr(), indices=a, min_only=True)[b].min())


@pytest.mark.parametrize("name", ["makehuman_knee_patch.obj", "makehuman_face_patch.obj"])
def test_real_patches_with_two_loops(name):
    V, F, _ = load_obj(data_mesh(name), 100)  # dm -> mm
    st = surface_type(V, F)
    assert st["boundary_loops"] == 2 and not st["is_disk"]
    res = cut_to_disk(V, F)
    assert_valid_cut(V, F, res, 1)
    assert res.cut_length_mm == pytest.approx(shortest_interior_distance(V, F))


def test_tube_cut_is_the_shortest_path():
    V, F = knee_tube(45.0, 120.0)
    V[:, 0] *= 1.0 + 0.3 * np.sin(V[:, 2] / 30.0)  # a bumpy, knee-like tube
    res = cut_to_disk(V, F)
    assert_valid_cut(V, F, res, 1)
    assert res.cut_length_mm == pytest.approx(shortest_interior_distance(V, F))


def test_real_face_with_eye_and_mouth_holes():
    V, F, _ = load_obj(data_mesh("ict_face_narrow.obj"), 10)  # cm -> mm, 4 boundary loops
    assert surface_type(V, F)["boundary_loops"] == 4
    res = cut_to_disk(V, F)
    assert_valid_cut(V, F, res, 3)
    assert res.description.startswith("cut along 3 paths")
