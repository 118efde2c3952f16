"""Seed 4.5.3: flipped triangles and self-overlaps of a flat pattern are detected."""
import numpy as np
import pytest
import scipy.sparse as sp
from paths import data_mesh
from meshgen import grid, grid_with_holes, spiral_strip
from scipy.sparse.linalg import splu

from bolus_addon.core.mesh.boundary import boundary_loops, cut_to_disk
from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.geometry2d import cross2d
from bolus_addon.core.mesh.objfile import load_obj
from bolus_addon.core.unfold.overlap import (
    boundary_edge_array,
    boundary_self_intersections,
    candidate_pairs,
    flipped_faces,
    overlap_summary,
    overlapping_face_pairs,
    overlapping_faces,
    point_in_polygon,
    segment_intersections,
    signed_areas,
)
from bolus_addon.core.mesh.topology import MeshTopology


def flat(nx=10, ny=10, size=100.0, jitter=0.0):
    V, F = grid(nx, ny, size, jitter=jitter)
    return V[:, :2].copy(), F


def brute_force_overlaps(UV, F, tol=1e-9):
    """Reference: every pair, by sampling points strictly inside one triangle in the other."""
    m = len(F)
    w = np.array([[1, 1, 1], [4, 1, 1], [1, 4, 1], [1, 1, 4], [2, 2, 1], [2, 1, 2], [1, 2, 2]], float)
    w /= w.sum(1, keepdims=True)
    hit = np.zeros(m, dtype=bool)
    for i in range(m):
        S = w @ UV[F[i]]  # sample points inside triangle i
        for j in range(m):
            if i == j:
                continue
            T = UV[F[j]]
            d = [cross2d(T[(k + 1) % 3] - T[k], S - T[k]) for k in range(3)]
            inside = (np.all(np.array(d) > tol, axis=0) | np.all(np.array(d) < -tol, axis=0))
            if inside.any():
                hit[i] = hit[j] = True
    return hit


def test_signed_areas_and_orientation():
    UV = np.array([[0.0, 0], [4, 0], [0, 3]])
    assert signed_areas(UV, [[0, 1, 2]])[0] == pytest.approx(6.0)
    assert signed_areas(UV, [[0, 2, 1]])[0] == pytest.approx(-6.0)
    assert flipped_faces(UV, np.array([[0, 1, 2], [0, 2, 1]])).tolist() == [False, True]
    UVc = np.array([[0.0, 0], [1, 0], [2, 0]])  # collapsed triangle counts as flipped
    assert flipped_faces(UVc, np.array([[0, 1, 2]])).tolist() == [True]


def test_flat_grid_has_nothing():
    for jitter in (0.0, 0.3):
        UV, F = flat(jitter=jitter)
        assert not flipped_faces(UV, F).any()
        assert not overlapping_faces(UV, F).any()
        assert len(boundary_self_intersections(UV, F)) == 0
        assert overlap_summary(UV, F)["ok"]


def test_vertex_moved_across_its_neighbours_is_a_fold():
    UV, F = flat()
    c = 5 * 11 + 5  # interior vertex at (50, 50); its neighbour (60, 50) is passed
    assert np.allclose(UV[c], [50, 50])
    UV[c] = [65.0, 52.0]
    flipped = flipped_faces(UV, F)
    over = overlapping_faces(UV, F)
    assert flipped.any()
    assert over[flipped].all()  # every flipped face overlaps its neighbour across the fold
    assert over.sum() > flipped.sum()
    assert set(np.nonzero(over)[0]) == set(np.nonzero(brute_force_overlaps(UV, F))[0])
    # the faces involved are all near the moved vertex
    near = np.linalg.norm(UV[F].mean(axis=1) - [60, 50], axis=1) < 25
    assert near[over].all()
    assert len(boundary_self_intersections(UV, F)) == 0  # the outline is untouched
    s = overlap_summary(UV, F)
    assert not s["ok"] and s["flipped_faces"] == flipped.sum() and s["overlapping_faces"] == over.sum()


def test_spiral_strip_whose_ends_overlap():
    V, F = spiral_strip(turns=1.27)  # turns chosen so that no vertex lies exactly on another edge
    UV = V[:, :2]
    assert not flipped_faces(UV, F).any()  # no triangle is turned over ...
    cross = boundary_self_intersections(UV, F)
    assert len(cross) > 0  # ... but the outline crosses itself
    E = boundary_edge_array(F)
    assert all(not set(E[a]) & set(E[b]) for a, b in cross)  # never two edges with a common vertex
    over = overlapping_faces(UV, F)
    na, nw = 120, 3
    column = (np.arange(len(F)) % (na * nw)) // nw  # angle step of each face (grid() cell order)
    assert over.any()
    assert np.all((column[over] < 0.3 * na) | (column[over] > 0.7 * na))  # only the two ends overlap
    # with loops given, the same crossings are found (indices into the loop edges)
    loops = boundary_loops(F)
    cross2 = boundary_self_intersections(UV, F, loops)
    E2 = boundary_edge_array(F, loops)
    assert {frozenset(map(tuple, np.sort(E[p], 1).tolist())) for p in cross} == {
        frozenset(map(tuple, np.sort(E2[p], 1).tolist())) for p in cross2
    }


def test_spiral_strip_that_does_not_close_is_fine():
    V, F = spiral_strip(turns=0.9)
    assert overlap_summary(V[:, :2], F)["ok"]


def test_separate_islands_apart_report_nothing_and_on_top_report_overlap():
    UV, F = flat(4, 4, 40.0)
    far = np.vstack([UV, UV + [60.0, 5.0]])
    F2 = np.vstack([F, F + len(UV)])
    assert overlap_summary(far, F2)["ok"]
    touching = np.vstack([UV, UV + [40.0, 0.0]])  # sides touch along x = 40: not an overlap
    assert overlap_summary(touching, F2)["ok"]
    on_top = np.vstack([UV, UV + [25.0, 13.0]])
    over = overlapping_faces(on_top, F2)
    assert over[: len(F)].any() and over[len(F):].any()
    assert len(boundary_self_intersections(on_top, F2)) > 0


def test_cut_flat_annulus_closing_up_exactly_is_not_an_overlap():
    V, F = grid_with_holes(12, 12, 120.0, holes=((4, 4, 8, 8),))
    res = cut_to_disk(V, F)
    UV = res.V[:, :2]  # the two sides of the cut lie on top of each other, touching only
    assert overlap_summary(UV, res.F, boundary_loops(res.F))["ok"]


def test_duplicate_face_overlaps_and_shared_edge_side_by_side_does_not():
    UV = np.array([[0.0, 0], [1, 0], [0, 1], [1, 1]])
    assert overlapping_face_pairs(UV, np.array([[0, 1, 2], [1, 3, 2]])).shape == (0, 2)
    assert overlapping_face_pairs(UV, np.array([[0, 1, 2], [0, 1, 2]])).tolist() == [[0, 1]]
    # fold: both triangles on the same side of the shared edge 1-2
    UVf = np.array([[0.0, 0], [1, 0], [0, 1], [0.2, 0.2]])
    assert overlapping_face_pairs(UVf, np.array([[0, 1, 2], [1, 3, 2]])).tolist() == [[0, 1]]
    # one shared vertex, interiors crossing
    UVv = np.array([[0.0, 0], [2, 0], [0, 2], [2, 1], [1, 2]])
    assert overlapping_face_pairs(UVv, np.array([[0, 1, 2], [0, 3, 4]])).tolist() == [[0, 1]]
    UVv2 = np.array([[0.0, 0], [2, 0], [1, 1], [-2, 0], [-1, -1]])
    assert overlapping_face_pairs(UVv2, np.array([[0, 1, 2], [0, 3, 4]])).shape == (0, 2)


def test_random_triangles_match_brute_force():
    rng = np.random.default_rng(3)
    UV = rng.uniform(0, 100, (90, 2))
    F = rng.permutation(90).reshape(30, 3)
    F[signed_areas(UV, F) < 0] = F[signed_areas(UV, F) < 0][:, ::-1]
    np.testing.assert_array_equal(overlapping_faces(UV, F), brute_force_overlaps(UV, F))


def test_segment_intersections_proper_only():
    P = np.array([[0.0, 0], [2, 2], [0, 2], [2, 0], [1, 1], [3, 3], [5, 0], [6, 0], [7, 0]])
    E = np.array([[0, 1], [2, 3], [4, 5], [6, 7], [7, 8]])
    # 0 and 1 cross at (1, 1); 2 starts at that point (touching 0 and 1) and runs along 0 (collinear):
    # neither is proper; 3 and 4 share a vertex
    assert segment_intersections(P, E).tolist() == [[0, 1]]


def test_candidate_pairs_match_brute_force():
    rng = np.random.default_rng(1)
    lo = rng.uniform(0, 100, (400, 2))
    hi = lo + rng.exponential(4, (400, 2))
    hi[:3] += 60  # a few large boxes
    got = {tuple(p) for p in candidate_pairs(lo, hi).tolist()}
    want = {(i, j) for i in range(400) for j in range(i + 1, 400) if np.all(lo[i] <= hi[j]) and np.all(lo[j] <= hi[i])}
    assert got == want


def test_point_in_polygon():
    L = np.array([[0.0, 0], [4, 0], [4, 1], [1, 1], [1, 4], [0, 4]])  # an L shape
    pts = np.array([[0.5, 0.5], [3, 0.5], [0.5, 3], [3, 3], [-1, 0.5], [5, 5]])
    assert point_in_polygon(pts, L).tolist() == [True, True, True, False, False, False]


def test_bad_pattern_arrays_raise():
    with pytest.raises(BolusError, match=r"\(n, 2\)"):
        flipped_faces(np.zeros((3, 3)), [[0, 1, 2]])
    with pytest.raises(BolusError, match="outside"):
        overlapping_faces(np.zeros((3, 2)), [[0, 1, 3]])


def tutte_embedding(V, F, radius=100.0):
    """Reference flattening of a disk: boundary on a circle (by arc length), uniform Laplacian inside."""
    loop = boundary_loops(F)[0]
    seg = np.linalg.norm(V[np.roll(loop, -1)] - V[loop], axis=1)
    th = 2 * np.pi * np.r_[0, np.cumsum(seg)[:-1]] / seg.sum()
    UV = np.zeros((len(V), 2))
    UV[loop] = radius * np.c_[np.cos(th), np.sin(th)]
    A = MeshTopology(V, F).vertex_adjacency
    L = (sp.diags(np.asarray(A.sum(1)).ravel()) - A).tocsr()
    free = np.setdiff1d(np.arange(len(V)), loop)
    UV[free] = splu(L[free][:, free].tocsc()).solve(-(L[free][:, loop] @ UV[loop]))
    return UV


def test_flattened_cut_knee_is_clean_until_a_vertex_is_pushed_over():
    V, F, _ = load_obj(data_mesh("makehuman_knee_patch.obj"), 100)
    cut = cut_to_disk(V, F)
    UV = tutte_embedding(cut.V, cut.F)  # a convex-boundary Tutte map of a disk has no fold
    loops = boundary_loops(cut.F)
    assert overlap_summary(UV, cut.F, loops)["ok"]
    # push an interior vertex through one of its neighbours
    inner = np.setdiff1d(np.unique(cut.F), loops[0])
    v = inner[len(inner) // 2]
    nb = cut.F[np.any(cut.F == v, axis=1)].ravel()
    w = nb[nb != v][0]
    UV[v] = UV[w] + 1.5 * (UV[w] - UV[v])
    s = overlap_summary(UV, cut.F, loops)
    assert not s["ok"] and s["flipped_faces"] > 0 and s["overlapping_faces"] >= s["flipped_faces"]


# ------------------------------------------------------------ degenerate input
def coincident_pattern():
    """A flat 4 x 4 grid whose vertices 6 and 7 coincide: two collapsed (zero-area) triangles."""
    UV, F = flat(4, 4, 40.0)
    UV[7] = UV[6]
    return UV, F


def test_coincident_vertices_collapse_triangles_that_count_as_flipped():
    UV, F = coincident_pattern()
    A = signed_areas(UV, F)
    collapsed = np.abs(A) < 1e-12
    assert collapsed.sum() == 2 and np.isfinite(A).all()
    assert np.array_equal(flipped_faces(UV, F), collapsed)  # documented: a collapsed triangle is a fold
    # touching, not overlapping: the collapsed triangles lie on their neighbours' edge
    assert not overlapping_faces(UV, F).any()
    assert len(boundary_self_intersections(UV, F)) == 0
    s = overlap_summary(UV, F)
    assert s == {"flipped_faces": 2, "overlapping_faces": 0, "boundary_crossings": 0, "ok": False}


def test_needle_triangles_are_neither_flipped_nor_overlapping():
    UV, F = flat(4, 4, 40.0)
    UV[7] = UV[6] + [0.0, 1e-3]  # needles of 1 um next to 10 mm sides, still counter-clockwise
    assert (signed_areas(UV, F) > 0).all()
    assert overlap_summary(UV, F)["ok"]


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_coordinates_are_refused_by_name(bad):
    UV, F = flat(3, 3)
    UV[9, 1] = bad
    for fn in (signed_areas, flipped_faces, overlapping_faces, overlapping_face_pairs, boundary_self_intersections,
               overlap_summary):
        with pytest.raises(BolusError, match="non-finite.*vertex 9"):
            fn(UV, F)
    with pytest.raises(BolusError, match="point 9 of a segment is not finite"):
        segment_intersections(UV, [[8, 9], [0, 5]])
    with pytest.raises(BolusError, match="box 1 has a non-finite"):
        candidate_pairs(UV[[0, 9]], UV[[0, 9]] + 1)
    with pytest.raises(BolusError, match="point 0 is not finite"):
        point_in_polygon(UV[[9]], UV[[0, 3, 15]])
    with pytest.raises(BolusError, match="polygon corner 1 is not finite"):
        point_in_polygon(UV[[0]], UV[[0, 9, 15]])


def test_repeated_vertex_and_bad_indices_are_refused_by_triangle():
    UV, F = flat(3, 3)
    F = F.copy()
    F[4] = [5, 5, 6]
    with pytest.raises(BolusError, match="triangle 4 repeats one of its vertices"):
        flipped_faces(UV, F)
    with pytest.raises(BolusError, match="triangle 2 refers to a vertex index outside"):
        overlapping_faces(UV, np.r_[[[0, 1, 2]], [[0, 1, 2]], [[0, 1, -1]]])


def test_non_manifold_edge_fold_is_an_overlap_and_not_a_boundary_edge():
    """Three triangles on edge 0-1, two of them on the same side: a fold-over (sound result)."""
    UV = np.array([[0.0, 0], [10, 0], [5, 8], [5, -8], [4, 6]])
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    assert overlapping_faces(UV, F).tolist() == [True, False, True]
    E = boundary_edge_array(F)
    assert not any(set(e) == {0, 1} for e in E.tolist()) and len(E) == 6
