"""Degenerate input to the cut-line and cutting core: coincident vertices,
zero-area and needle triangles, NaN/inf, non-manifold edges.  Each public function either
raises BolusError naming the problem and where, or gives a sound (finite, documented) result."""
from __future__ import annotations

import numpy as np
import pytest
from meshgen import grid, grid_with_holes

from bolus_addon.core.cuts.borders import border_components, turning_per_mm
from bolus_addon.core.cuts.curvefit import fit_closed_curve, fit_open_curve, project_to_plane, signed_distance_closed
from bolus_addon.core.cuts.cutlines import cut_region_check, patch_table, smooth_cuts
from bolus_addon.core.mesh.boundary import boundary_loops, cut_to_disk, split_along_edges, surface_type
from bolus_addon.core.errors import BolusError
from bolus_addon.core.cuts.mbo import diffused_indicator
from bolus_addon.core.analysis.spectral import patch_stats
from bolus_addon.core.mesh.topology import MeshTopology

N = 20  # grid cells per side; vertex (i, j) is i * (N + 1) + j at (5 i, 5 j) mm


def vid(i, j):
    return i * (N + 1) + j


def jagged_sheet():
    """A 100 mm sheet of N x N cells, two patches with a slanted (jagged) border."""
    V, F = grid(N, N, size=100.0)
    c = V[F].mean(axis=1)
    labels = (c[:, 0] > 50 + 0.3 * (c[:, 1] - 50)).astype(int)
    return V, F, labels


FIN = (vid(5, 5), vid(6, 5))  # an inner edge in patch 0


def with_fin(V, F):
    """A third triangle on the inner edge FIN of the grid: a non-manifold edge."""
    V2 = np.vstack([V, [27.5, 25.0, 5.0]])
    return V2, np.vstack([F, [[FIN[0], FIN[1], len(V)]]])


def faces_with_edge(F, u, v):
    return np.nonzero([{u, v} <= set(f) for f in F.tolist()])[0]


# ------------------------------------------------------------------ smooth_cuts
@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_smooth_cuts_refuses_non_finite_vertex_by_index(value):
    V, F, labels = jagged_sheet()
    V[vid(7, 3), 1] = value
    with pytest.raises(BolusError, match=f"non-finite.*vertex {vid(7, 3)}"):
        smooth_cuts(V, F, labels)


def test_smooth_cuts_refuses_bad_and_repeated_indices():
    V, F, labels = jagged_sheet()
    F2 = F.copy()
    F2[5, 1] = len(V)
    with pytest.raises(BolusError, match="triangle 5 refers to a vertex index outside"):
        smooth_cuts(V, F2, labels)
    F2 = F.copy()
    F2[9, 2] = F2[9, 0]
    with pytest.raises(BolusError, match="triangle 9 repeats"):
        smooth_cuts(V, F2, labels)


def test_smooth_cuts_refuses_coincident_vertices_in_a_patch():
    V, F, labels = jagged_sheet()
    V[vid(10, 10)] = V[vid(11, 10)]  # the edge between them collapses: its two triangles have no area
    bad = faces_with_edge(F, vid(10, 10), vid(11, 10))
    with pytest.raises(BolusError, match=rf"2 zero-area triangle\(s\), e\.g\. triangle {bad[0]} \(vertices"):
        smooth_cuts(V, F, labels)


def test_smooth_cuts_refuses_a_non_manifold_edge_by_its_vertices():
    V, F, labels = jagged_sheet()
    V2, F2 = with_fin(V, F)
    with pytest.raises(BolusError, match=f"non-manifold edge.*vertices {FIN[0]} and {FIN[1]}"):
        smooth_cuts(V2, F2, np.r_[labels, 0])


def test_zero_area_triangles_outside_the_patches_are_left_alone():
    """Faces in no patch are never split: a degenerate one there does not matter."""
    V, F, labels = jagged_sheet()
    labels = labels.copy()
    V[vid(0, 19)] = V[vid(0, 20)]  # a collapsed edge in the corner, outside the patches
    out = np.zeros(len(F), dtype=bool)
    out[faces_with_edge(F, vid(0, 19), vid(0, 20))] = True
    out |= V[F].mean(axis=1)[:, 1] > 90
    labels[out] = -1
    res = smooth_cuts(V, F, labels)
    assert res.changed and np.isfinite(res.V).all()
    keep = res.labels < 0
    np.testing.assert_array_equal(np.sort(res.face_parent[keep]), np.nonzero(out)[0])
    assert res.face_unchanged[keep].all()


def test_needle_triangles_give_a_sound_cut():
    """A vertex 1e-4 of an edge from its neighbour (needle triangles, positive area) on the border."""
    V, F, labels = jagged_sheet()
    V[vid(10, 10)] = V[vid(11, 10)] + [-5e-4, 5e-4, 0.0]
    assert MeshTopology(V, F).areas.min() > 0
    res = smooth_cuts(V, F, labels)
    assert res.changed and np.isfinite(res.V).all()
    A0 = MeshTopology(V, F).areas.sum()
    assert MeshTopology(res.V, res.F).areas.sum() == pytest.approx(A0, rel=1e-12)
    np.testing.assert_array_equal(res.V[: len(V)], V)
    for r in res.borders:
        assert np.isfinite([r.turning_after, r.length_after_mm, r.max_shift_mm]).all()


# ------------------------------------------------------------------ the region check
def test_cut_region_check_looks_at_the_patch_faces_only():
    V, F, labels = jagged_sheet()
    V2, F2 = with_fin(V, F)
    assert cut_region_check(V2, F2, np.r_[labels, -1]) == ([], None)
    with pytest.raises(BolusError, match="non-manifold edges"):
        cut_region_check(V2, F2, np.r_[labels, 0])
    Vz = V.copy()
    Vz[vid(10, 10)] = Vz[vid(11, 10)]
    with pytest.raises(BolusError, match="zero-area"):
        cut_region_check(Vz, F, labels)
    ids = np.arange(len(V)) + 1000  # the user's vertex numbers appear in the message
    with pytest.raises(BolusError, match=f"vertices {vid(10, 10) + 1000}"):
        cut_region_check(Vz, F, labels, ids)


def test_cut_region_check_says_why_there_is_nothing_to_smooth():
    V, F, labels = jagged_sheet()
    assert cut_region_check(V, F, np.zeros(len(F), dtype=int))[1] == "there is only one patch"
    c = V[F].mean(axis=1)
    apart = np.where(c[:, 0] < 30, 0, np.where(c[:, 0] > 70, 1, -1))
    assert cut_region_check(V, F, apart)[1] == "the patches do not share any border"
    with pytest.raises(BolusError, match="do not share any border"):
        smooth_cuts(V, F, apart)


def test_patch_table_is_patch_stats_of_the_patch_faces():
    V, F, labels = jagged_sheet()
    labels = labels.copy()
    labels[:7] = -1
    rows = patch_table(V, F, labels, 0.0)
    ref = [p.as_dict() for p in patch_stats(V, F[labels >= 0], labels[labels >= 0])]
    assert rows == ref
    assert sum(r["faces"] for r in rows) == len(F) - 7
    assert sum(r["area_mm2"] for r in rows) == pytest.approx(100.0 * 100.0 - 7 * 12.5)


# ------------------------------------------------------------------ borders
def test_border_components_are_topological():
    """Zero-area triangles do not change the borders; a border on a non-manifold edge is refused."""
    V, F, labels = jagged_sheet()
    ref = border_components(MeshTopology(V, F), labels)
    Vz = V.copy()
    Vz[vid(10, 10)] = Vz[vid(11, 10)]
    got = border_components(MeshTopology(Vz, F), labels)
    assert len(got) == len(ref) == 1
    np.testing.assert_array_equal(got[0].edges, ref[0].edges)
    np.testing.assert_array_equal(got[0].order, ref[0].order)
    V2, F2 = with_fin(V, F)
    assert len(border_components(MeshTopology(V2, F2), np.r_[labels, 0])) == 1  # the fin is inside patch 0
    with pytest.raises(BolusError, match=f"non-manifold edge \\(vertices {FIN[0]}, {FIN[1]}"):
        border_components(MeshTopology(V2, F2), np.r_[labels, 1])  # the fin is patch 1: a border on that edge
    with pytest.raises(BolusError, match="one patch per triangle"):
        border_components(MeshTopology(V, F), labels[:-1])


def walked_edges(order, closed):
    """Sorted vertex pairs of consecutive vertices of an order (with the closing edge)."""
    nxt = np.roll(order, -1) if closed else order[1:]
    cur = order if closed else order[:-1]
    return sorted(tuple(sorted(p)) for p in zip(cur.tolist(), nxt.tolist()))


def faces_around(V, F, v):
    """Triangles around vertex v, counter-clockwise by the angle of their centroid."""
    f = np.nonzero((F == v).any(axis=1))[0]
    d = V[F[f]].mean(axis=1)[:, :2] - V[v, :2]
    return f[np.argsort(np.arctan2(d[:, 1], d[:, 0]))]


def test_border_touching_itself_is_walked_along_the_surface():
    """Two squares of patch 1 touching at one vertex (a pinch): one closed border passing the
    vertex twice, each time from one square to the other (patch 0's boundary, cutting.boundary_loops)."""
    V, F = grid(N, N, size=100.0)
    c = V[F].mean(axis=1)
    sq1 = (c[:, 0] > 25) & (c[:, 0] < 50) & (c[:, 1] > 25) & (c[:, 1] < 50)
    sq2 = (c[:, 0] > 50) & (c[:, 0] < 75) & (c[:, 1] > 50) & (c[:, 1] < 75)
    labels = (sq1 | sq2).astype(int)
    (bd,) = border_components(MeshTopology(V, F), labels)
    assert bd.closed and len(bd.order) == len(bd.edges) == 40
    assert walked_edges(bd.order, True) == sorted(map(tuple, bd.edges.tolist()))
    v = vid(10, 10)
    at = np.nonzero(bd.order == v)[0]
    assert len(at) == 2
    for k in at:
        prev, nxt = V[bd.order[k - 1], :2], V[bd.order[(k + 1) % len(bd.order)], :2]
        assert (prev.sum() < 100) != (nxt.sum() < 100)  # from one square to the other


def test_border_joined_where_a_third_patch_splits_a_fan_and_a_branch_is_none():
    V, F = grid(N, N, size=100.0)
    c = V[F].mean(axis=1)
    labels = ((c[:, 0] > 25) & (c[:, 0] < 75) & (c[:, 1] > 25) & (c[:, 1] < 75)).astype(int)
    for j in (10, 7):  # vertices (75, 50) and (75, 35) on the square's right side
        outer = [f for f in faces_around(V, F, vid(15, j))
                 if c[f, 0] > 75 and not {vid(15, j - 1), vid(15, j + 1)} & set(F[f].tolist())]
        assert len(outer) == 1
        labels[outer[0]] = 2  # a triangle of patch 2 touching the square at one vertex: 0's fan there in two wedges
    bds = border_components(MeshTopology(V, F), labels)
    (bd,) = [b for b in bds if (b.a, b.b) == (0, 1)]
    assert bd.closed and len(bd.order) == len(bd.edges) == 40 and len(set(bd.order.tolist())) == 40
    assert walked_edges(bd.order, True) == sorted(map(tuple, bd.edges.tolist()))
    # a branch: three 0|1 edges meeting at one vertex
    w = vid(5, 5)
    ring = faces_around(V, F, w)
    lab = np.full(len(F), 2)
    lab[ring] = [0, 1, 0, 1, 2, 2]
    (bd,) = border_components(MeshTopology(V, F), lab)[:1]
    assert (bd.a, bd.b) == (0, 1) and len(bd.edges) == 3 and bd.order is None and not bd.closed


def test_turning_per_mm_with_coincident_vertices_and_nan():
    # a right-angle staircase; a zero-length edge has no direction: its two ends are skipped
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 1, 0], [2, 1, 0]], dtype=float)
    E = np.array([[0, 1], [1, 2], [2, 3], [3, 4]])
    t, L = turning_per_mm(V, E)
    assert L == pytest.approx(3.0) and t == pytest.approx((np.pi / 2) / 3.0)  # only vertex 3 counts
    V[3, 0] = np.nan
    with pytest.raises(BolusError, match="border vertex 3 has a non-finite"):
        turning_per_mm(V, E)


# ------------------------------------------------------------------ curve fitting
def test_curve_fits_refuse_nan_and_coincident_points():
    x = np.linspace(0, 10, 12)
    with pytest.raises(BolusError, match="point 4 has a non-finite"):
        fit_open_curve(np.where(np.arange(12) == 4, np.nan, x), x, 1.0)
    with pytest.raises(BolusError, match="coincide"):
        fit_open_curve(np.full(5, 3.0), np.arange(5.0), 1.0)
    s = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    xy = np.stack([np.cos(s), np.sin(s)], 1)
    xy[2, 1] = np.inf
    with pytest.raises(BolusError, match="point 2 has a non-finite"):
        fit_closed_curve(xy, 0.1)
    with pytest.raises(BolusError, match="coincide"):
        fit_closed_curve(np.ones((8, 2)), 0.1)
    with pytest.raises(BolusError, match="at least 6 points"):
        fit_closed_curve(np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]]), 0.1)
    coef = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 2.0]])
    with pytest.raises(BolusError, match="point 1 has a non-finite"):
        signed_distance_closed(np.array([[0.0, 0.0], [np.nan, 1.0]]), coef)


def test_projection_refuses_a_zero_normal():
    with pytest.raises(BolusError, match="finite non-zero"):
        project_to_plane(np.ones((3, 3)), np.zeros(3), np.zeros(3))
    with pytest.raises(BolusError, match="finite non-zero"):
        project_to_plane(np.ones((3, 3)), [np.nan, 0, 1], np.zeros(3))


def test_diffused_indicator_refuses_zero_area_and_bad_sigma():
    V, F, labels = jagged_sheet()
    u = diffused_indicator(V, F, labels, 0, 1, 10.0)
    assert np.isfinite(u).all() and (u[F[labels == 0]].mean() > 0) and (u[F[labels == 1]].mean() < 0)
    with pytest.raises(BolusError, match="positive"):
        diffused_indicator(V, F, labels, 0, 1, 0.0)
    V[vid(10, 10)] = V[vid(11, 10)]
    bad = faces_with_edge(F, vid(10, 10), vid(11, 10))[0]
    with pytest.raises(BolusError, match=f"triangle {bad} .*zero area"):
        diffused_indicator(V, F, labels, 0, 1, 10.0)


# ------------------------------------------------------------------ cutting
def flat_annulus_grid():
    return grid_with_holes(12, 12, 120.0, holes=((4, 4, 8, 8),))


def test_boundary_loops_of_an_annulus_and_a_non_manifold_edge():
    V, F = flat_annulus_grid()
    loops = boundary_loops(F)
    assert [len(lp) for lp in loops] == [48, 16]
    t = MeshTopology(V, F)
    B = {tuple(e) for e in t.edges[t.boundary_edges].tolist()}
    walked = {tuple(sorted(p)) for lp in loops for p in zip(lp.tolist(), np.roll(lp, -1).tolist())}
    assert walked == B
    Vn = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]])
    Fn = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    with pytest.raises(BolusError, match="more than two faces \\(e\\.g\\. between vertices 0 and 1\\)"):
        boundary_loops(Fn)
    with pytest.raises(BolusError, match="triangle 1 repeats"):
        boundary_loops(np.array([[0, 1, 2], [2, 2, 3]]))
    with pytest.raises(BolusError, match="triangle 0 refers to a vertex index outside"):
        boundary_loops(np.array([[0, -1, 2]]))


def test_cutting_is_topological_on_zero_area_triangles():
    """Coincident vertices (zero-area triangles) leave loops, type and cut as on the clean mesh."""
    V, F = flat_annulus_grid()
    ref = cut_to_disk(V, F)
    Vz = V.copy()
    i = F[0, 1]
    Vz[i] = Vz[F[0, 0]]  # collapse one boundary edge of the outer loop
    assert MeshTopology(Vz, F).degenerate_faces().any()
    assert [len(lp) for lp in boundary_loops(F)] == [48, 16]
    st, st0 = surface_type(Vz, F), surface_type(V, F)
    assert st == st0
    res = cut_to_disk(Vz, F)
    assert surface_type(res.V, res.F)["is_disk"] and len(res.cut_paths) == len(ref.cut_paths) == 1
    np.testing.assert_array_equal(res.vert_origin[res.F], F)


@pytest.mark.parametrize("value", [np.nan, -np.inf])
def test_cutting_refuses_non_finite_vertices_by_index(value):
    V, F = flat_annulus_grid()
    V[17, 2] = value
    for fn in (cut_to_disk, surface_type):
        with pytest.raises(BolusError, match="non-finite.*vertex 17"):
            fn(V, F)


def test_cut_to_disk_names_a_non_manifold_edge_and_refuses_no_faces():
    Vn = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]])
    Fn = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    with pytest.raises(BolusError, match="between vertices 0 and 1"):
        cut_to_disk(Vn, Fn)
    with pytest.raises(BolusError, match="0 triangle"):
        cut_to_disk(Vn, np.zeros((0, 3), dtype=int))


def test_split_along_edges_refuses_repeated_indices():
    with pytest.raises(BolusError, match="repeats"):
        split_along_edges(np.array([[0, 1, 1]]), np.zeros((0, 2), dtype=int))
