"""Learned print segmentation (seed 6.4): sub-graphs (6.4.1), eq. 3-14 similarity, affinity
propagation (Algorithm 6-2) and the parts."""
import numpy as np
import pytest
from meshgen import box, grid, icosphere, torus

from test_core_print_segmentation import _assert_parts_edge_connected

from bolus_addon.core.errors import BolusError
from bolus_addon.core.printing.learned import affinity_propagation, learned_segmentation, load_default_sae, similarity
from bolus_addon.core.printing.segmentation import print_segmentation
from bolus_addon.core.printing.subgraphs import build_subgraphs, minmax, print_features, subgraph_rows
from bolus_addon.core.mesh.topology import MeshTopology


def _two_shapes():
    """A sphere and a torus 400 mm apart: one mesh, two components."""
    V1, F1 = icosphere(3, 40.0)
    V2, F2 = torus(50.0, 18.0, 40, 16)
    V2 = V2 + np.array([400.0, 0.0, 0.0])
    return np.r_[V1, V2], np.r_[F1, F2 + len(V1)], len(F1)


def test_subgraphs_are_connected_in_search_order_and_use_most_triangles():
    V, F = icosphere(4, 60.0)
    t = MeshTopology(V, F)
    sg = build_subgraphs(t)
    assert sg.usage_rate >= 0.93  # the seed's Table 6-3 figure
    assert sg.count >= 0.93 * t.m / 30 - 1
    A = t.face_adjacency.tolil()
    for row in sg.faces[:50]:
        got = row[row >= 0]
        assert len(set(got.tolist())) == len(got)
        # search order: every triangle after the first touches one before it (breadth-first growth)
        for i in range(1, len(got)):
            assert any(A[got[i], got[j]] for j in range(i)), "triangle not adjacent to an earlier one"
    # owner and faces agree; every sub-graph has at least min_fill = 15 triangles
    for i, row in enumerate(sg.faces):
        got = row[row >= 0]
        assert (sg.owner[got] == i).all()
        assert len(got) >= 15
    assert (sg.owner >= 0).sum() == sg.fill.sum()


def test_subgraphs_keep_polygons_whole():
    V, F = grid(12, 12, 100.0)
    m = len(F) // 2
    groups = np.r_[np.arange(m), np.arange(m)]  # triangle i and i + m form one quad
    t = MeshTopology(V, F)
    sg = build_subgraphs(t, face_groups=groups)
    for g in range(m):
        assert sg.owner[g] == sg.owner[g + m]


def test_subgraph_rows_follow_figure_6_15():
    V, F = box((40.0, 30.0, 20.0), 6)
    t = MeshTopology(V, F)
    fe = print_features(V, F, [0.0, 0.0, 1.0], t)
    assert fe.shape == (t.m, 3) and fe.min() >= 0.0 and fe.max() <= 1.0
    # on a box with b = +z: the top and bottom are cusp-free... no: |n.b| = 1 there, 0 on the sides
    top = t.face_normals[:, 2] > 0.9
    side = np.abs(t.face_normals[:, 2]) < 0.1
    assert np.allclose(fe[top, 0], 1.0) and np.allclose(fe[side, 0], 0.0)
    bottom = t.face_normals[:, 2] < -0.9  # overhangs at the plate: the support column is 0 long
    assert np.allclose(fe[bottom, 1], 0.0)
    sg = build_subgraphs(t, size=30, min_fill=5)
    X = subgraph_rows(fe, sg)
    assert X.shape == (sg.count, 90)
    i = int(np.argmin(sg.fill))
    row = sg.faces[i]
    assert np.allclose(X[i, 0:3], fe[row[0]]) and np.allclose(X[i, 3:6], fe[row[1]])
    k = int(sg.fill[i])
    assert np.all(X[i, 3 * k:] == 0.0)  # zero-padded


def test_minmax_is_eq_6_6():
    assert np.allclose(minmax([2.0, 4.0, 3.0]), [0.0, 1.0, 0.5])
    assert np.all(minmax([5.0, 5.0]) == 0.0)


def test_similarity_eq_3_14():
    rng = np.random.default_rng(1)
    g, pf = rng.normal(size=(20, 3)), rng.uniform(size=(20, 20))
    Sg = similarity(g)
    S = similarity(g, pf)
    assert np.allclose(S, S.T) and np.allclose(Sg, Sg.T)
    assert np.allclose(np.diag(Sg), 1.0) and np.allclose(np.diag(S), 2.0)
    assert (Sg > 0).all() and (Sg <= 1.0).all()
    # nearer centres are more similar; so are likelier features (the seed's '+' read as a kernel)
    d = ((g[0] - g) ** 2).sum(axis=1)
    assert np.all(np.diff(Sg[0][np.argsort(d)]) <= 1e-12)
    f = ((pf[0] - pf) ** 2).sum(axis=1)
    assert np.all(np.diff((S - Sg)[0][np.argsort(f)]) <= 1e-12)


def test_affinity_propagation_finds_the_number_of_groups():
    rng = np.random.default_rng(0)
    centres = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0]], float)
    g = np.concatenate([c + rng.normal(scale=3.0, size=(30, 3)) for c in centres])
    lab, ex, it = affinity_propagation(similarity(g), rng=0, preference="min")
    assert len(ex) == 3 and it > 0
    for k in range(3):
        assert len(np.unique(lab[30 * k:30 * (k + 1)])) == 1


def test_two_separated_shapes_give_clusters_that_never_mix_or_split_a_subgraph():
    V, F, m1 = _two_shapes()
    seg = learned_segmentation(V, F, rng=0)
    t = MeshTopology(V, F)
    sg = seg.subgraphs
    assert seg.ap_clusters >= 2
    assert sg.usage_rate >= 0.93
    # no sub-graph split: all its triangles share the part and the cluster
    for row in sg.faces:
        got = row[row >= 0]
        assert len(np.unique(seg.labels[got])) == 1 and len(np.unique(seg.clusters[got])) == 1
    # no cluster spans both shapes
    for c in np.unique(seg.clusters):
        on = np.nonzero(seg.clusters == c)[0]
        assert (on < m1).all() or (on >= m1).all()
    _assert_parts_edge_connected(t, seg.labels)
    assert seg.hidden.shape == (sg.count, 20)
    tab = seg.table(V, F)
    assert tab["requested"] is None and tab["ap_clusters"] == seg.ap_clusters and tab["subgraphs"] == sg.count


def test_fixed_seed_gives_the_same_parts_twice_and_dispatch_matches():
    V, F = icosphere(4, 60.0)
    V = V * np.array([1.6, 1.0, 0.7])
    a = learned_segmentation(V, F, rng=3)
    b = learned_segmentation(V, F, rng=3)
    assert np.array_equal(a.labels, b.labels) and np.array_equal(a.hidden, b.hidden)
    c = print_segmentation(V, F, parts=99, method="learned", rng=3)  # parts is not used
    assert np.array_equal(a.labels, c.labels)
    note = c.count_note()
    assert (note is None) == (c.part_count <= 6)
    if note:
        assert note.startswith(f"the learned split made {c.part_count} parts (from {c.ap_clusters} clusters)")
    _assert_parts_edge_connected(MeshTopology(V, F), a.labels)


def test_geometric_similarity_is_the_seeds_comparison():
    V, F = icosphere(4, 60.0)
    seg = learned_segmentation(V, F, similarity_kind="geometric")
    assert seg.hidden is None and seg.ap_clusters >= 1
    _assert_parts_edge_connected(MeshTopology(V, F), seg.labels)


def test_large_sets_cluster_a_spread_sample_then_join_exemplars():
    V, F = icosphere(4, 60.0)
    t = MeshTopology(V, F)
    full = learned_segmentation(V, F, rng=0, topo=t)
    part = learned_segmentation(V, F, rng=0, topo=t, max_exemplar_set=60)
    assert full.subgraphs.count > 60
    assert part.ap_clusters >= 1 and (part.clusters >= 0).all()
    for row in part.subgraphs.faces:
        got = row[row >= 0]
        assert len(np.unique(part.labels[got])) == 1
    _assert_parts_edge_connected(t, part.labels)


def test_refusals():
    V, F = icosphere(1, 10.0)  # 80 triangles: sub-graphs, but check a smaller one
    with pytest.raises(BolusError, match="unknown similarity"):
        learned_segmentation(V, F, similarity_kind="colour")
    with pytest.raises(BolusError, match="too small for the learned split"):
        learned_segmentation(V[:3], np.array([[0, 1, 2]]))
    with pytest.raises(BolusError, match="unknown print segmentation method"):
        print_segmentation(V, F, method="magic")


def test_shipped_auto_encoder_has_the_seeds_shape():
    sae = load_default_sae()
    assert tuple(sae.sizes) == (90, 120, 50, 20)
    assert sae.meta.get("script") == "scripts/train_print_sae.py"
    assert sae.meta.get("rows") == 3000
    X = np.random.default_rng(0).uniform(size=(5, 90))
    H = sae.encode(X)
    assert H.shape == (5, 20) and np.isfinite(H).all()


def test_equal_similarities_make_one_cluster():
    lab, ex, it = affinity_propagation(np.array([[2.0, 0.7], [0.7, 2.0]]))
    assert lab.tolist() == [0, 0] and len(ex) == 1 and it == 0
    V, F = grid(5, 5, 50.0)  # 50 triangles: two sub-graphs at most
    seg = learned_segmentation(V, F)
    assert seg.subgraphs.count <= 2 and seg.part_count >= 1


def test_shipped_layers_reconstruct_unseen_subgraphs_better_than_their_start():
    """Sub-graph rows of a shape the network never saw (a stretched torus): every trained layer
    reconstructs its input better than a random start of the same size does."""
    from bolus_addon.core.printing.autoencoder import init_autoencoder, reconstruction_error

    V, F = torus(55.0, 21.0, 48, 20)
    V = V * np.array([1.0, 0.6, 1.3])
    t = MeshTopology(V, F)
    X = subgraph_rows(print_features(V, F, [0.3, 0.2, 0.93], t), build_subgraphs(t))
    sae = load_default_sae()
    for k, (layer, inp) in enumerate(zip(sae.layers, sae.layer_inputs(X))):
        start = init_autoencoder(layer.n_in, layer.n_hidden, rng=k)
        assert reconstruction_error(layer, inp) < 0.5 * reconstruction_error(start, inp), f"layer {k + 1}"
    held = sae.meta["held_back_error"]
    assert len(held) == 3 and all(np.isfinite(held))
