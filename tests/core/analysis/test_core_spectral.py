"""Spectral segmentation, eqs. 3-3..3-8 and 4-5."""
import numpy as np
import pytest
import scipy.sparse as sp
from meshgen import grid, icosphere, sheet_with_dome

from bolus_addon.core.errors import BolusError
from bolus_addon.core.analysis.saliency import analyse
from bolus_addon.core.analysis.spectral import (
    affinity,
    connected_patches,
    faces_from_vertex_labels,
    graph_laplacian,
    segment,
    smallest_eigenvectors,
)
from bolus_addon.core.mesh.topology import MeshTopology


def _border_vertices(F, labels):
    p = labels.max() + 1
    inside = np.zeros((F.max() + 1, p), dtype=bool)
    for k in range(p):
        inside[F[labels == k].ravel(), k] = True
    return inside.sum(axis=1) > 1


def test_laplacian_is_symmetric_zero_row_sum_psd():
    V, F, _ = sheet_with_dome(n_sheet=8, n_dome=6, na=24)
    t = MeshTopology(V, F)
    sal = analyse(V, F, 3.0).saliency
    for eta in (0.0, 5.0):
        L = graph_laplacian(affinity(t, sal, eta=eta))
        assert abs(L - L.T).max() < 1e-14
        assert np.abs(np.asarray(L.sum(axis=1))).max() < 1e-12
        assert np.linalg.eigvalsh(L.toarray()).min() > -1e-10
        W = -L.toarray()
        np.fill_diagonal(W, 0)
        assert ((W >= 0) & (W <= 1)).all()
        assert ((W > 0) == (MeshTopology(V, F).vertex_adjacency.toarray() > 0)).all()  # eq. 3-4: edges only


def test_smallest_eigenvectors_sparse_matches_dense():
    V, F = icosphere(3, 20.0)  # 642 vertices: sparse shift-invert path
    L = graph_laplacian(affinity(MeshTopology(V, F), np.zeros(len(V)), eta=0.0))
    vals, U = smallest_eigenvectors(L, 4, rng=0)
    dense = np.linalg.eigvalsh(L.toarray())[:4]
    np.testing.assert_allclose(vals, dense, atol=1e-8)
    assert abs(vals[0]) < 1e-9
    np.testing.assert_allclose(U.T @ U, np.eye(4), atol=1e-8)
    np.testing.assert_allclose(L @ U, U * vals, atol=1e-7)


def test_segmentation_is_deterministic_for_a_seed():
    V, F, _ = sheet_with_dome(n_sheet=10, n_dome=8, na=32)
    a = segment(V, F, 3, smoothing_mm=3.0, rng=7)
    b = segment(V, F, 3, smoothing_mm=3.0, rng=7)
    np.testing.assert_array_equal(a.face_labels, b.face_labels)
    np.testing.assert_array_equal(a.vertex_clusters, b.vertex_clusters)


@pytest.mark.parametrize("k", [2, 3, 5])
def test_every_patch_is_edge_connected_and_numbered(k):
    V, F = icosphere(3, 50.0)
    seg = segment(V, F, k, smoothing_mm=2.0, rng=0)
    t = MeshTopology(V, F)
    labels = seg.face_labels
    assert set(np.unique(labels)) == set(range(seg.patch_count))
    for p in range(seg.patch_count):
        n, comp = t.face_components(np.where(labels == p, 0, 1))
        assert len(np.unique(comp[labels == p])) == 1
    # numbered by decreasing area
    areas = np.bincount(labels, weights=t.areas)
    assert (np.diff(areas) <= 1e-9).all()


def test_cut_runs_along_the_junction_of_sheet_and_dome():
    """The saliency term (eq. 4-5) moves the cut to where the surface cannot lie flat."""
    V, F, geo = sheet_with_dome(R=30.0, R_out=60.0, n_sheet=20, n_dome=20, na=64)
    seg = segment(V, F, 2, eta=5.0, smoothing_mm=3.0, rng=0)
    border = _border_vertices(F, seg.face_labels)
    assert 109 <= border.sum() <= 147  # 128 measured (two rings of 64)
    assert np.abs(geo[border]).max() < 2.71  # mm from the junction circle (dome radius 30 mm; 2.36 measured)
    # plain spectral clustering (eta = 0) cuts elsewhere: the test is not trivially true
    plain = segment(V, F, 2, eta=0.0, smoothing_mm=3.0, rng=0)
    assert np.abs(geo[_border_vertices(F, plain.face_labels)]).mean() > 17.3  # 20.4 mm measured
    # and each patch flattens better than the whole (Table 4-1)
    assert max(p.sum_varpi for p in seg.patches) < seg.analysis.sum_varpi


def test_patch_table_counts():
    V, F, _ = sheet_with_dome(n_sheet=10, n_dome=8, na=32)
    seg = segment(V, F, 3, smoothing_mm=0.0, rng=0)
    for row in seg.patches:
        sub = F[seg.face_labels == row.patch]
        assert row.faces == len(sub)
        assert row.vertices == len(np.unique(sub))
        sides = np.concatenate([sub[:, :2], sub[:, 1:], sub[:, ::2]])
        assert row.edges == len(np.unique(np.sort(sides, axis=1), axis=0))
        assert row.sum_varpi < seg.analysis.sum_varpi
        assert row.flv == pytest.approx(10 * 0.5**row.sum_varpi)
    assert sum(r.faces for r in seg.patches) == len(F)
    assert sum(r.area_mm2 for r in seg.patches) == pytest.approx(MeshTopology(V, F).areas.sum())


def test_cluster_that_falls_apart_becomes_two_patches_and_crumbs_merge():
    V, F = grid(20, 4, size=100.0)
    t = MeshTopology(V, F)
    x = t.centroids[:, 0]
    labels = np.where((x < 30) | (x > 70), 0, 1)  # label 0 in two separate pieces
    out = connected_patches(t, labels)
    assert out.max() + 1 == 3
    # a crumb of label 2 inside piece 1 (2 triangles) is merged into its surroundings
    labels2 = labels.copy()
    labels2[np.argmin(np.abs(x - 50) + np.abs(t.centroids[:, 1] - 50))] = 2
    out2 = connected_patches(t, labels2, min_area=0.02 * t.areas.sum())
    assert out2.max() + 1 == 3
    np.testing.assert_array_equal(out2, out)


def test_face_labels_majority_and_polygon_groups():
    F = np.array([[0, 1, 2], [1, 2, 3]])
    vl = np.array([0, 0, 1, 1])
    np.testing.assert_array_equal(faces_from_vertex_labels(F, vl), [0, 1])
    # the two triangles form one quad: one label for both, the larger one's
    np.testing.assert_array_equal(faces_from_vertex_labels(F, vl, np.array([1.0, 3.0]), np.array([5, 5])), [1, 1])


def test_border_vertices_are_shared_by_neighbouring_patches():
    V, F, _ = sheet_with_dome(n_sheet=10, n_dome=8, na=32)
    seg = segment(V, F, 2, rng=0)
    b = _border_vertices(F, seg.face_labels)
    assert b.any()
    for p in range(2):
        verts = np.unique(F[seg.face_labels == p])
        assert np.isin(np.nonzero(b)[0], verts).all()  # both patches hold the common boundary


def test_bad_requests():
    V, F = grid(2, 1)
    with pytest.raises(BolusError, match="fewer than"):
        segment(V, F, 5)
    with pytest.raises(BolusError, match="at least 1"):
        segment(V, F, 0)
    V2 = np.vstack([V, V + [500, 0, 0]])
    F2 = np.vstack([F, F + len(V)])
    with pytest.raises(BolusError, match="separate parts"):
        segment(V2, F2, 2)
    with pytest.raises(BolusError, match="eta"):
        segment(*grid(4, 4), 2, eta=-1)
    with pytest.raises(BolusError, match="method"):
        segment(*grid(4, 4), 2, method="dbscan")


def test_gmm_clustering_also_gives_connected_patches():
    V, F, _ = sheet_with_dome(n_sheet=10, n_dome=8, na=32)
    seg = segment(V, F, 3, method="gmm", rng=1)
    assert seg.patch_count >= 2
    t = MeshTopology(V, F)
    for p in range(seg.patch_count):
        _, comp = t.face_components(np.where(seg.face_labels == p, 0, 1))
        assert len(np.unique(comp[seg.face_labels == p])) == 1


# ------------------------------------------------------------ the one clustering step
from meshgen import degenerate_variants  # noqa: E402

from bolus_addon.core.analysis import clustering  # noqa: E402
from bolus_addon.core.analysis.spectral import cluster_rows, vote_groups  # noqa: E402


def _blobs(seed=0):
    rng = np.random.default_rng(seed)
    centres = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    lab = np.repeat(np.arange(3), [200, 100, 50])
    return centres[lab] + 0.08 * rng.standard_normal((len(lab), 2)), lab


@pytest.mark.parametrize("method", ["kmeans", "gmm"])
def test_cluster_rows_finds_blobs_at_any_scale(method):
    """The rows are standardised first, so the mixture's REG_COVAR means the same at every
    embedding scale (a unit eigenvector of n entries has entries ~ 1/sqrt(n))."""
    X, lab = _blobs()
    X = np.c_[X, np.full(len(X), 3.0)]  # a constant column (the trivial eigenvector) is dropped
    out = cluster_rows(X, 3, method=method, rng=0)
    for scale in (1e-4, 1e4):
        np.testing.assert_array_equal(cluster_rows(X * scale + 7.0, 3, method=method, rng=0), out)
    # the same partition as the truth (up to the names of the clusters)
    pairs = np.unique(np.c_[lab, out], axis=0)
    assert len(pairs) == 3
    np.testing.assert_array_equal(clustering.standardise_rows(X).shape, (len(X), 2))
    assert np.sqrt((clustering.standardise_rows(X) ** 2).mean()) == pytest.approx(1.0)


def test_kmeans_on_many_rows_is_seeded_on_a_sample_and_fits_every_row():
    """Above KMEANS_SAMPLE rows the restarts run on a sample and Lloyd's iterations on all rows:
    the same partition as the truth, and the same labels as k-means seeded on every row."""
    rng = np.random.default_rng(3)
    centres = np.array([[0.0, 0.0], [3.0, 0.5], [1.0, 2.5], [2.5, 3.0]])
    lab = rng.integers(0, 4, clustering.KMEANS_SAMPLE + 8000)
    X = centres[lab] + 0.3 * rng.standard_normal((len(lab), 2))
    out = cluster_rows(X, 4, rng=0)
    per_blob = [np.bincount(out[lab == b], minlength=4).max() / np.sum(lab == b) for b in range(4)]
    assert min(per_blob) > 0.97
    saved = clustering.KMEANS_SAMPLE
    clustering.KMEANS_SAMPLE = 10**9
    try:
        full = cluster_rows(X, 4, rng=0)
    finally:
        clustering.KMEANS_SAMPLE = saved
    # one partition up to the names of the clusters
    M = np.zeros((4, 4), dtype=int)
    np.add.at(M, (out, full), 1)
    assert M.max(axis=1).sum() / len(X) > 0.999


def test_cluster_rows_weights_and_bad_input():
    X, lab = _blobs(1)
    # weights: the mixture is fitted on rows drawn by weight; zero weight on a blob still labels its rows
    w = np.where(lab == 2, 0.0, 1.0)
    out = cluster_rows(X, 2, method="gmm", rng=0, weights=w)
    assert len(np.unique(out[lab == 0])) == 1 and len(np.unique(out[lab == 1])) == 1
    assert out[lab == 0][0] != out[lab == 1][0]
    kw = cluster_rows(X, 3, method="kmeans", rng=0, weights=np.ones(len(X)))
    np.testing.assert_array_equal(kw, cluster_rows(X, 3, method="kmeans", rng=0))
    bad = X.copy()
    bad[3, 0] = np.nan
    with pytest.raises(BolusError, match="NaN or infinite"):
        cluster_rows(bad, 3)
    with pytest.raises(BolusError, match="row weights"):
        cluster_rows(X, 3, weights=-w)
    with pytest.raises(BolusError, match="cannot make 5 clusters of 4 rows"):
        cluster_rows(X[:4], 5)
    with pytest.raises(BolusError, match="method"):
        cluster_rows(X, 3, method="dbscan")
    assert clustering.REG_COVAR == 1e-6


def test_vote_groups():
    lab = np.array([0, 1, 1, 2, 0])
    groups = np.array([7, 7, 7, 9, 9])
    np.testing.assert_array_equal(vote_groups(lab, groups), [1, 1, 1, 0, 0])  # ties: the smaller label
    np.testing.assert_array_equal(vote_groups(lab, groups, np.array([5.0, 1, 1, 3, 1])), [0, 0, 0, 2, 2])
    with pytest.raises(BolusError, match="one per triangle"):
        vote_groups(lab, groups[:-1])
    with pytest.raises(BolusError, match=">= 0"):
        vote_groups(lab - 1, groups)


@pytest.mark.parametrize("name", ["coincident", "collinear", "nan", "inf", "needle", "nonmanifold"])
def test_segment_on_degenerate_meshes(name):
    """segment refuses what its flattenability analysis cannot measure, by name; a needle
    triangle or a non-manifold edge is sound (the vertex graph is defined; the Blender
    operator refuses non-manifold regions itself)."""
    V, F = grid(8, 8, 80.0)
    Vd, Fd, says = degenerate_variants(V, F)[name]
    if says is None or name == "nonmanifold":
        seg = segment(Vd, Fd, 2, rng=0)
        assert np.isfinite(seg.embedding).all() and seg.patch_count >= 1
        return
    with pytest.raises(BolusError, match=says):
        segment(Vd, Fd, 2, rng=0)


def test_gaussian_weights_clip_and_regular_mesh():
    from bolus_addon.core.analysis.spectral import gaussian_weights

    d = np.array([0.0, 1.0, 2.0, 100.0])  # sigma = mean = 25.75; 100 > 3 sigma is clipped
    w = gaussian_weights(d)
    np.testing.assert_allclose(w[:3], np.exp(-(d[:3] ** 2) / (2 * 25.75**2)))
    assert w[3] == pytest.approx(np.exp(-4.5))  # the floor: the graph cannot fall apart numerically
    np.testing.assert_array_equal(gaussian_weights(np.zeros(5)), np.ones(5))
    assert gaussian_weights(np.zeros(0)).shape == (0,)


# ---------------------------------------------------------------- scale


def _matched_share(a, b, weights=None):
    """Share (by weight) of items whose labels agree after the best matching of labels."""
    from scipy.optimize import linear_sum_assignment

    w = np.ones(len(a)) if weights is None else weights
    p = int(max(a.max(), b.max())) + 1
    C = np.zeros((p, p))
    np.add.at(C, (a, b), w)
    r, c = linear_sum_assignment(-C)
    return C[r, c].sum() / w.sum()


@pytest.mark.parametrize("k", [2, 3, 5])
def test_patch_stats_on_matches_patch_stats(k):
    """The patch table from the region's flattenability equals the one measured on a
    mesh per patch (the path `segment` takes on a manifold region)."""
    from bolus_addon.core.analysis.spectral import patch_stats, patch_stats_on

    V, F, _ = sheet_with_dome(n_sheet=10, n_dome=8, na=32)
    ana = analyse(V, F, 3.0)
    labels = segment(V, F, k, smoothing_mm=3.0, rng=1).face_labels
    slow = patch_stats(ana.V_analysis, F, labels, V)
    fast = patch_stats_on(MeshTopology(V, F), labels, ana.varpi)
    assert len(slow) == len(fast) == labels.max() + 1
    for a, b in zip(slow, fast):
        assert (a.patch, a.vertices, a.edges, a.faces) == (b.patch, b.vertices, b.edges, b.faces)
        assert b.area_mm2 == pytest.approx(a.area_mm2, rel=1e-12)
        assert b.sum_varpi == pytest.approx(a.sum_varpi, rel=1e-9, abs=1e-12)
        assert b.flv == pytest.approx(a.flv, rel=1e-9)


@pytest.mark.parametrize("name", ["coincident", "collinear", "needle", "nonmanifold"])
def test_patch_stats_on_degenerate_meshes(name):
    """patch_stats_on takes no angles: sound (finite) on zero-area and needle triangles,
    a region with non-manifold vertices (the extra triangle of "nonmanifold" on an edge,
    of "collinear" hanging from one vertex) is refused by name (NaN/inf never reach it:
    MeshTopology refuses them)."""
    from bolus_addon.core.analysis.spectral import patch_stats_on

    V, F = grid(8, 8, 80.0)
    Vd, Fd, _ = degenerate_variants(V, F)[name]
    topo = MeshTopology(Vd, Fd)
    labels = (topo.centroids[:, 0] > 40.0).astype(np.int64)
    varpi = np.abs(np.sin(np.arange(topo.n)))
    if name in ("nonmanifold", "collinear"):
        assert topo.nonmanifold_vertices.any()
        with pytest.raises(BolusError, match="non-manifold"):
            patch_stats_on(topo, labels, varpi)
        return
    rows = patch_stats_on(topo, labels, varpi)
    assert len(rows) == 2 and all(np.isfinite([r.area_mm2, r.sum_varpi, r.flv]).all() for r in rows)
    assert sum(r.faces for r in rows) == len(Fd)


def test_segment_reuses_the_given_analysis():
    """segment(analysis=...) takes the preview instead of recomputing it: the same patches
    from the SaliencyResult or the stored (varpi, saliency) pair; a different saliency
    changes the result (it is used); wrong shapes and values are refused."""
    V, F, _ = sheet_with_dome(n_sheet=10, n_dome=8, na=32)
    ref = segment(V, F, 3, smoothing_mm=3.0, rng=0)
    ana = analyse(V, F, 3.0)
    for given in (ana, (ana.varpi, ana.saliency)):
        seg = segment(V, F, 3, smoothing_mm=3.0, rng=0, analysis=given)
        np.testing.assert_array_equal(seg.face_labels, ref.face_labels)
        for a, b in zip(ref.patches, seg.patches):
            assert b.sum_varpi == pytest.approx(a.sum_varpi, rel=1e-12)
    # float32 copies (what a Blender attribute holds) give the same spectrum, but on this
    # rotationally symmetric mesh (lambda_2 = lambda_3) k-means may cut the dome at another
    # angle: why the operator reuses the preview's float64 arrays, not its attributes
    f32 = segment(V, F, 3, smoothing_mm=3.0, rng=0, analysis=(ana.varpi.astype(np.float32),
                                                                ana.saliency.astype(np.float32)))
    np.testing.assert_allclose(f32.eigenvalues[1:], ref.eigenvalues[1:], rtol=1e-6)
    raw = analyse(V, F, 0.0)  # another smoothing: another saliency, other weights
    other = segment(V, F, 3, smoothing_mm=3.0, rng=0, analysis=(raw.varpi, raw.saliency))
    assert not np.allclose(other.embedding, ref.embedding, atol=1e-6)
    with pytest.raises(BolusError, match="one value per vertex"):
        segment(V, F, 3, analysis=(ana.varpi[:-1], ana.saliency[:-1]))
    bad = ana.saliency.copy()
    bad[3] = np.nan
    with pytest.raises(BolusError, match="finite"):
        segment(V, F, 3, analysis=(ana.varpi, bad))
    with pytest.raises(BolusError, match="pair"):
        segment(V, F, 3, analysis=ana.varpi)


def _salient_laplacian():
    V, F, _ = sheet_with_dome(n_sheet=40, n_dome=30, na=96)
    t = MeshTopology(V, F)
    return V, F, graph_laplacian(affinity(t, analyse(V, F, 3.0).saliency, eta=5.0))


def test_aggregates_are_connected_through_strong_edges():
    from scipy.sparse.csgraph import connected_components

    from bolus_addon.core.analysis.spectral import STRONG_WEIGHT, aggregate_vertices

    V, F, L = _salient_laplacian()
    nc, agg = aggregate_vertices(L, V)
    assert 10 < nc < len(V) / 8
    T = sp.triu(L, 1).tocoo()
    i, j, w = T.row, T.col, -T.data
    inner = (agg[i] == agg[j]) & (w >= STRONG_WEIGHT)
    G = sp.coo_matrix((np.ones(inner.sum()), (i[inner], j[inner])), shape=L.shape)
    assert connected_components(G, directed=False)[0] == nc  # each aggregate: one piece joined by strong edges


def test_multilevel_eigenvectors_match_shift_invert():
    from bolus_addon.core.analysis.spectral import multilevel_eigenvectors

    V, F, L = _salient_laplacian()
    exact_vals, exact = smallest_eigenvectors(L, 4, rng=0)
    vals, U = multilevel_eigenvectors(L, 4, V, rng=0)
    np.testing.assert_allclose(vals, exact_vals, rtol=1e-4, atol=1e-12)
    np.testing.assert_allclose(U.T @ U, np.eye(4), atol=1e-8)
    cos = np.linalg.svd(exact.T @ U, compute_uv=False)
    assert cos.min() > 1 - 1e-6  # the same subspace
    again = multilevel_eigenvectors(L, 4, V, rng=0)[1]
    np.testing.assert_array_equal(again, U)  # deterministic


def test_segment_coarse_to_fine_gives_the_same_patches(monkeypatch):
    """Above MULTILEVEL_MIN_VERTICES segment solves coarse to fine; on a mesh forced down
    that path the patches are those of the exact eigenvectors (on a stretched mesh: on a
    round one lambda_2 = lambda_3 and any rotation of the cut is as good)."""
    from bolus_addon.core.analysis import spectral

    V, F, _ = sheet_with_dome(n_sheet=40, n_dome=30, na=96)
    V = V * [1.4, 1.0, 1.0]
    exact = segment(V, F, 3, smoothing_mm=3.0, rng=0)
    monkeypatch.setattr(spectral, "MULTILEVEL_MIN_VERTICES", 1000)
    fast = segment(V, F, 3, smoothing_mm=3.0, rng=0)
    t = MeshTopology(V, F)
    assert _matched_share(exact.face_labels, fast.face_labels, t.areas) > 0.999
    np.testing.assert_allclose(fast.eigenvalues, exact.eigenvalues, rtol=1e-4, atol=1e-12)
