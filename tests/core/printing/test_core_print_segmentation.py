"""Area-balanced spectral print segmentation, eqs. 6-21..6-36."""
import numpy as np
import pytest
from meshgen import box, graded_strip, grid, icosphere, sheet_with_dome

from bolus_addon.core.errors import BolusError
from bolus_addon.core.printing.segmentation import (
    abcut_laplacian,
    area_balance,
    dual_graph_weights,
    part_stats,
    print_segment,
    print_segmentation,
)
from bolus_addon.core.analysis.spectral import graph_laplacian
from bolus_addon.core.mesh.topology import MeshTopology


def _assert_parts_edge_connected(t, labels):
    p = labels.max() + 1
    assert set(np.unique(labels)) == set(range(p))
    _, comp = t.face_components(labels)
    for q in range(p):
        assert len(np.unique(comp[labels == q])) == 1, f"part {q} falls apart"


def test_dual_graph_weights_are_symmetric_positive_and_lower_across_creases():
    V, F = box((40.0, 30.0, 20.0), 4)
    t = MeshTopology(V, F)
    W = dual_graph_weights(t)
    assert abs(W - W.T).max() < 1e-14
    P = t.face_adjacency_pairs
    w = np.asarray(W[P[:, 0], P[:, 1]]).ravel()
    assert (w > 0).all() and W.nnz == 2 * len(P)  # dual-graph edges only, none vanishes
    crease = np.einsum("ij,ij->i", t.face_normals[P[:, 0]], t.face_normals[P[:, 1]]) < 0.5
    assert crease.any() and w[crease].max() < w[~crease].min()  # eq. 6-23: alike faces stay together


def test_abcut_laplacian_is_the_area_normalised_laplacian():
    V, F, _ = sheet_with_dome(n_sheet=4, n_dome=4, na=16)
    t = MeshTopology(V, F)
    L = graph_laplacian(dual_graph_weights(t))
    Lp, s = abcut_laplacian(L, t.areas)  # eq. 6-36
    np.testing.assert_allclose(s, 1 / np.sqrt(t.areas))
    assert abs(Lp - Lp.T).max() < 1e-12
    np.testing.assert_allclose(Lp @ np.sqrt(t.areas), 0.0, atol=1e-9)  # F^1/2 1 spans the null space
    # generalised problem L h = lambda F h (eqs. 6-32..6-35)
    vals = np.linalg.eigvalsh(Lp.toarray())
    assert vals.min() > -1e-9
    seg = print_segmentation(V, F, 3, method="abcut", rng=0, topo=t)
    H = seg.embedding  # U' = F^-1/2 U
    np.testing.assert_allclose(H.T @ (t.areas[:, None] * H), np.eye(3), atol=1e-8)  # eq. 6-34
    np.testing.assert_allclose(L @ H, t.areas[:, None] * H * seg.eigenvalues, atol=1e-7)


def test_abcut_balances_areas_where_ratiocut_does_not():
    """Most triangles lie in the fine half: RatioCut balances counts, ABcut balances areas."""
    V, F = graded_strip()
    t = MeshTopology(V, F)
    ab = print_segment(V, F, 2, method="abcut", rng=0, topo=t)
    rc = print_segment(V, F, 2, method="ratiocut", rng=0, topo=t)
    for lab in (ab, rc):
        assert lab.max() + 1 == 2
        _assert_parts_edge_connected(t, lab)
    assert area_balance(ab, t.areas) < 1.18  # 1.022 measured
    assert 2.36 < area_balance(rc, t.areas) < 3.19  # 2.776 measured
    assert area_balance(ab, t.areas) < area_balance(rc, t.areas)
    # RatioCut's parts have nearly equal face counts instead
    assert np.bincount(rc).max() / np.bincount(rc).min() < 1.16  # 1.006 measured


@pytest.mark.parametrize("method", ["abcut", "ratiocut"])
@pytest.mark.parametrize("k", [2, 3, 4])
def test_parts_are_edge_connected_numbered_and_deterministic(method, k):
    V, F = icosphere(3, 50.0)  # 1,280 faces: the sparse eigen-solver path
    t = MeshTopology(V, F)
    a = print_segment(V, F, k, method=method, rng=3, topo=t)
    b = print_segment(V, F, k, method=method, rng=3)
    np.testing.assert_array_equal(a, b)
    _assert_parts_edge_connected(t, a)
    areas = np.bincount(a, weights=t.areas)
    assert (np.diff(areas) <= 1e-9).all()  # by decreasing area
    assert areas.min() >= 0.05 * t.areas.sum() - 1e-9  # crumbs merged
    stats = part_stats(V, F, a, t)
    assert sum(s.faces for s in stats) == len(F)
    assert sum(s.area_mm2 for s in stats) == pytest.approx(t.areas.sum())


def test_one_part_and_small_dense_meshes():
    V, F = grid(3, 3, 30.0)
    assert (print_segment(V, F, 1) == 0).all()
    lab = print_segment(V, F, 2, min_part_fraction=0.0)
    _assert_parts_edge_connected(MeshTopology(V, F), lab)


def test_bad_input_is_refused():
    V, F = grid(2, 2, 10.0)  # 8 triangles
    with pytest.raises(BolusError, match="at least 1 part"):
        print_segment(V, F, 0)
    with pytest.raises(BolusError, match="fewer than"):
        print_segment(V, F, 9)
    with pytest.raises(BolusError, match="zero area"):
        print_segment(np.zeros_like(V), F, 2)
    with pytest.raises(BolusError, match="method"):
        print_segment(V, F, 2, method="ncut")
    with pytest.raises(BolusError):
        print_segment(V, F, 2.5)
    with pytest.raises(BolusError):
        part_stats(V, F, np.zeros(3, dtype=int))


# ------------------------------------------------------------ polygons, table, degenerate input
from meshgen import degenerate_variants  # noqa: E402


def test_face_groups_keep_each_polygon_in_one_part():
    V, F = grid(12, 6, 120.0)  # two triangles per square: group them as quads
    groups = np.arange(len(F)) // 2
    seg = print_segmentation(V, F, 3, rng=0, face_groups=groups)
    for g in np.unique(groups):
        assert len(np.unique(seg.labels[groups == g])) == 1
    _assert_parts_edge_connected(MeshTopology(V, F), seg.labels)
    with pytest.raises(BolusError, match="face groups must be one per triangle"):
        print_segmentation(V, F, 3, face_groups=groups[:-1])
    with pytest.raises(BolusError, match="the mesh has 2 faces, fewer than the 3 parts asked"):
        print_segmentation(V, F, 3, face_groups=np.arange(len(F)) * 2 // len(F))


def test_table_and_count_note():
    V, F = graded_strip()
    t = MeshTopology(V, F)
    seg = print_segmentation(V, F, 2, rng=0, topo=t)
    assert seg.count_note() is None
    tab = seg.table(V, F, t)
    assert tab["method"] == "abcut" and tab["requested"] == 2
    assert [r["part"] for r in tab["parts"]] == [0, 1]
    assert sum(r["area_mm2"] for r in tab["parts"]) == pytest.approx(t.areas.sum())
    assert tab["area_balance"] == pytest.approx(area_balance(seg.labels, t.areas))
    seg.requested = 3
    assert seg.count_note().startswith("2 parts instead of the 3 asked") and "5 %" in seg.count_note()


@pytest.mark.parametrize("name", ["coincident", "collinear", "nan", "inf", "needle", "nonmanifold"])
def test_print_segmentation_on_degenerate_meshes(name):
    """NaN/inf refused naming the vertex; zero-area, needle triangles and non-manifold edges
    are sound (area-floored in F^-1/2, no weight in the mixture; the dual graph joins the
    faces around an edge in turn): finite embedding, edge-connected parts."""
    V, F = grid(10, 10, 100.0)
    Vd, Fd, says = degenerate_variants(V, F)[name]
    if name in ("nan", "inf"):
        for call in (lambda: print_segmentation(Vd, Fd, 3), lambda: dual_graph_weights(MeshTopology(Vd, Fd))):
            with pytest.raises(BolusError, match=says):
                call()
        return
    t = MeshTopology(Vd, Fd)
    for method in ("abcut", "ratiocut"):
        seg = print_segmentation(Vd, Fd, 3, method=method, rng=0, topo=t)
        assert np.isfinite(seg.embedding).all() and np.isfinite(seg.eigenvalues).all()
        assert seg.part_count >= 2
        if name != "collinear":  # its sliver touches the grid at one vertex only: a separate piece
            _assert_parts_edge_connected(t, seg.labels)
    stats = part_stats(Vd, Fd, seg.labels)
    assert sum(s.faces for s in stats) == len(Fd)
