"""Matching marks of a cut pattern: seams between pieces, joins and darts within one."""
import numpy as np
import pytest
from meshgen import degenerate_variants, grid

from bolus_addon.core.errors import BolusError
from bolus_addon.core.pattern.marks import pattern_marks


def explode(V2, F, piece, gap=15.0):
    """The pattern of a flat source mesh (V2 (n,2), F) cut into pieces along their borders:
    every piece gets its own vertices, shifted right by gap * piece.  (UV, F', piece, source_vertex)."""
    UV, Fp, sv = [], np.empty_like(F), []
    base = 0
    for p in np.unique(piece):
        tri = np.flatnonzero(piece == p)
        verts, local = np.unique(F[tri], return_inverse=True)
        Fp[tri] = local.reshape(-1, 3) + base
        UV.append(V2[verts] + [gap * p, 0.0])
        sv.append(verts)
        base += len(verts)
    return np.concatenate(UV), Fp, np.asarray(piece), np.concatenate(sv)


def cone_pattern(rings=4, k=24, share=0.8, step=10.0):
    """A cone (apex source vertex 0, rings of k vertices) cut from its rim to the apex and
    laid flat as a sector of share * 2 pi: the cut's two sides are pattern columns 0 and k."""
    UV, sv = [[0.0, 0.0]], [0]
    for i in range(1, rings + 1):
        for j in range(k + 1):
            a = share * 2 * np.pi * j / k
            UV.append([i * step * np.cos(a), i * step * np.sin(a)])
            sv.append(1 + (i - 1) * k + j % k)
    pid = lambda i, j: 1 + (i - 1) * (k + 1) + j  # noqa: E731
    F = [[0, pid(1, j), pid(1, j + 1)] for j in range(k)]
    for i in range(1, rings):
        for j in range(k):
            F += [[pid(i, j), pid(i + 1, j), pid(i + 1, j + 1)], [pid(i, j), pid(i + 1, j + 1), pid(i, j + 1)]]
    return np.array(UV), np.array(F), np.zeros(len(F), dtype=int), np.array(sv), pid


def test_two_squares_sharing_an_edge_get_one_seam_numbered_on_both_sides():
    V, F = grid(2, 1, 40.0)  # two 20 x 40 cells side by side: the edge x = 20 is shared
    V2 = V[:, :2]
    piece = (V2[F].mean(axis=1)[:, 0] > 20).astype(int)
    UV, Fp, piece, sv = explode(V2, F, piece)
    m = pattern_marks(UV, Fp, piece, sv)
    assert len(m.seams) == 1 and not m.darts
    s = m.seams[0]
    assert (s.number, s.piece_a, s.piece_b, s.is_join) == (1, 0, 1, False)
    assert len(s.chain_a) == len(s.chain_b) == 2
    np.testing.assert_array_equal(sv[s.chain_a], sv[s.chain_b])
    assert set(sv[s.chain_a]) == set(np.flatnonzero(np.isclose(V2[:, 0], 20.0)))
    # the tick sits at the middle of the shared edge on both pieces, its number inside each
    np.testing.assert_allclose(s.mid_a, [20.0, 20.0], atol=1e-9)
    np.testing.assert_allclose(s.mid_b, [35.0, 20.0], atol=1e-9)
    np.testing.assert_allclose(s.normal_a, [-1.0, 0.0], atol=1e-12)  # into piece 0 (left of its edge)
    np.testing.assert_allclose(s.normal_b, [1.0, 0.0], atol=1e-12)
    np.testing.assert_array_equal(m.UV, UV)


def test_strip_split_in_three_numbers_its_two_seams_in_order():
    V, F = grid(6, 2, 60.0)
    V2 = V[:, :2] * [1.0, 0.5]
    piece = (V2[F].mean(axis=1)[:, 0] // 20).astype(int)  # columns of cells 0-1, 2-3, 4-5
    UV, Fp, piece, sv = explode(V2, F, piece)
    rng = np.random.default_rng(3)
    order = rng.permutation(len(Fp))  # the triangles' order does not change the numbers
    for FF, pp in ((Fp, piece), (Fp[order], piece[order])):
        m = pattern_marks(UV, FF, pp, sv)
        assert [(s.number, s.piece_a, s.piece_b) for s in m.seams] == [(1, 0, 1), (2, 1, 2)]
        for s, x in zip(m.seams, (20.0, 40.0)):
            assert len(s.chain_a) == 3  # two edges along the cut, one chain
            np.testing.assert_array_equal(sv[s.chain_a], sv[s.chain_b])
            np.testing.assert_allclose(V2[sv[s.chain_a], 0], x)
            assert np.all(pp[np.isin(FF, s.chain_a).any(axis=1)] == s.piece_a)
            assert np.all(pp[np.isin(FF, s.chain_b).any(axis=1)] == s.piece_b)
        assert not m.darts


def test_cone_cut_to_its_apex_gives_one_dart_with_the_apex():
    UV, F, piece, sv, pid = cone_pattern()
    m = pattern_marks(UV, F, piece, sv)
    assert not m.seams and len(m.darts) == 1
    d = m.darts[0]
    assert d.piece == 0 and d.apex == 0 and d.leg_a[-1] == d.leg_b[-1] == 0
    np.testing.assert_array_equal(sv[d.leg_a], sv[d.leg_b])
    legs = {tuple(d.leg_a), tuple(d.leg_b)}
    assert legs == {tuple(pid(i, 0) for i in (4, 3, 2, 1)) + (0,), tuple(pid(i, 24) for i in (4, 3, 2, 1)) + (0,)}


def test_tube_cut_open_is_a_join_not_a_dart():
    k, L = 16, 5
    u, v = np.meshgrid(np.arange(k + 1) * 5.0, np.arange(L + 1) * 8.0, indexing="ij")
    UV = np.stack([u.ravel(), v.ravel()], 1)
    idx = np.arange((k + 1) * (L + 1)).reshape(k + 1, L + 1)
    sv = (idx % ((k) * (L + 1))).ravel()  # column k is column 0 of the tube
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    m = pattern_marks(UV, F, np.zeros(len(F), dtype=int), sv)
    assert not m.darts and len(m.seams) == 1
    s = m.seams[0]
    assert s.is_join and s.number == 1 and len(s.chain_a) == L + 1
    assert {tuple(np.sort(s.chain_a)), tuple(np.sort(s.chain_b))} == {tuple(idx[0]), tuple(idx[k])}
    assert {round(s.normal_a[0]), round(s.normal_b[0])} == {1, -1}  # each side's number inside the strip


def test_seams_darts_and_joins_together_in_one_pattern():
    """A cone piece with its dart beside a strip of two pieces: numbering covers only the seams."""
    UV1, F1, p1, sv1, _ = cone_pattern()
    V, F = grid(4, 1, 40.0)
    UV2, F2, p2, sv2 = explode(V[:, :2] * [1, 0.5], F, (V[:, 0][F].mean(1) > 20).astype(int))
    UV = np.r_[UV1, UV2 + [100.0, 0]]
    Fall = np.r_[F1, F2 + len(UV1)]
    m = pattern_marks(UV, Fall, np.r_[p1, p2 + 1], np.r_[sv1, sv2 + sv1.max() + 1])
    assert [(s.number, s.piece_a, s.piece_b) for s in m.seams] == [(1, 1, 2)]
    assert len(m.darts) == 1 and m.darts[0].piece == 0


def test_pattern_without_shared_edges_has_no_marks():
    V, F = grid(3, 3, 30.0)
    m = pattern_marks(V[:, :2], F, np.zeros(len(F), dtype=int), np.arange(len(V)))
    assert m.seams == [] and m.darts == []


def test_bad_input_is_refused_by_name():
    V, F = grid(2, 1, 40.0)
    UV, piece, sv = V[:, :2], np.zeros(len(F), dtype=int), np.arange(len(V))
    with pytest.raises(BolusError, match="one integer piece per triangle"):
        pattern_marks(UV, F, piece[:-1], sv)
    with pytest.raises(BolusError, match="one integer source vertex per vertex"):
        pattern_marks(UV, F, piece, sv[:-1])
    with pytest.raises(BolusError, match="one integer source vertex per vertex"):
        pattern_marks(UV, F, piece, sv.astype(float))


@pytest.mark.parametrize("name", ["coincident", "collinear", "nan", "inf", "needle", "nonmanifold"])
def test_degenerate_patterns(name):
    """NaN / inf are refused naming the vertex; coincident, collinear and needle triangles and a
    non-manifold fin give sound marks (the pattern's outline is read as it is)."""
    V, F = grid(4, 2, 40.0)
    piece = (V[F].mean(axis=1)[:, 0] > 20).astype(int)
    UV, Fp, piece, sv = explode(V[:, :2], F, piece)
    Vd, Fd, says = degenerate_variants(np.c_[UV, np.zeros(len(UV))], Fp)[name]
    pd = np.r_[piece, np.zeros(len(Fd) - len(Fp), dtype=int)]
    svd = np.r_[sv, sv.max() + 1 + np.arange(len(Vd) - len(UV))]
    UVd = Vd[:, :2] + Vd[:, 2:]  # z is 0 but where the variant made it inf
    if name in ("nan", "inf"):
        with pytest.raises(BolusError, match=f"non-finite.*{says}"):
            pattern_marks(UVd, Fd, pd, svd)
        return
    m = pattern_marks(UVd, Fd, pd, svd)
    assert len(m.seams) == 1 and m.seams[0].number == 1 and not m.darts
    s = m.seams[0]
    assert np.isfinite(s.mid_a).all() and np.isfinite(s.normal_a).all()
    np.testing.assert_array_equal(svd[s.chain_a], svd[s.chain_b])


# ------------------------------------------------------------------ with the darts and splits of sheet_pieces
def sheet_pattern(res):
    """The pattern mesh of a `sheet_pieces` result as the pattern object stores it: every piece's
    unfolding side by side, the piece of every triangle, the source vertex of every pattern vertex."""
    UV, F, piece, sv, base, x = [], [], [], [], 0, 0.0
    for j, u in enumerate(res.unfoldings):
        P = u.UV - u.UV.min(axis=0) + [x, 0.0]
        x = P[:, 0].max() + 20.0
        UV.append(P)
        F.append(u.F + base)
        piece.append(np.full(len(u.F), j))
        sv.append(u.vert_origin)
        base += len(P)
    return np.concatenate(UV), np.concatenate(F), np.concatenate(piece), np.concatenate(sv)


def test_the_dart_of_sheet_pieces_on_a_cone_is_found_with_its_apex():
    from meshgen import cone

    from bolus_addon.core.unfold.sheet_pieces import sheet_pieces

    res = sheet_pieces(*cone(rings=15, na=40), 0.02)
    assert len(res.darts) == 1 and not res.splits
    UV, F, piece, sv = sheet_pattern(res)
    m = pattern_marks(UV, F, piece, sv)
    assert not m.seams and len(m.darts) == 1
    d = m.darts[0]
    assert sv[d.apex] == res.darts[0].path[-1]
    np.testing.assert_array_equal(sv[d.leg_a], res.darts[0].path)
    np.testing.assert_array_equal(sv[d.leg_b], res.darts[0].path)
    assert d.leg_a[0] != d.leg_b[0]  # opened: the cut's two sides part at the outline


def test_the_split_of_sheet_pieces_on_a_saddle_is_one_seam_on_both_pieces():
    from meshgen import saddle

    from bolus_addon.core.unfold.sheet_pieces import sheet_pieces

    res = sheet_pieces(*saddle(), 0.02)
    assert len(res.splits) == 1 and len(res.unfoldings) == 2
    UV, F, piece, sv = sheet_pattern(res)
    m = pattern_marks(UV, F, piece, sv)
    assert not m.darts and [(s.number, s.piece_a, s.piece_b) for s in m.seams] == [(1, 0, 1)]
    s = m.seams[0]
    assert sorted(sv[s.chain_a]) == sorted(res.splits[0].path) and list(sv[s.chain_a]) == list(sv[s.chain_b])


def test_seam_tick_keeps_off_corners_and_sits_at_the_same_source_place_on_both_sides():
    """A seam along two sides of a piece (an L-shaped cut) turns 90 degrees at its middle: the
    tick goes beside the corner, not on it, at the same source position on both pieces."""
    V, F = grid(4, 4, 40.0)
    c = V[F].mean(axis=1)
    piece = ((c[:, 0] > 20) & (c[:, 1] > 20)).astype(int)  # one quarter cut out along an L
    V2 = V[:, :2].copy()
    V2[:, 0] *= 1.0 + 0.01 * V2[:, 1] / 40  # a little shear: the two sides differ in shape, not in topology
    UV, Fp, piece, sv = explode(V2, F, piece)
    UV[np.unique(Fp[piece == 1])] *= 1.02  # piece 1 is 2 % larger
    m = pattern_marks(UV, Fp, piece, sv)
    assert len(m.seams) == 1
    s = m.seams[0]
    corner_a = UV[s.chain_a][np.argmin(np.abs(np.linalg.norm(V2[sv[s.chain_a]] - [20, 20], axis=1)))]
    assert np.linalg.norm(s.mid_a - corner_a) >= 5.0 - 1e-9  # a quarter of the 20 mm chain away, or 8 mm
    # the same place along the source chain on both sides: the same edge, the same share of it
    share = []
    for mid, chain in ((s.mid_a, s.chain_a), (s.mid_b, s.chain_b)):
        P = UV[chain]
        seg = P[1:] - P[:-1]
        t = np.einsum("ij,ij->i", mid - P[:-1], seg) / np.einsum("ij,ij->i", seg, seg)
        off = np.linalg.norm(P[:-1] + np.clip(t, 0, 1)[:, None] * seg - mid, axis=1)
        i = int(np.argmin(off))
        assert off[i] < 1e-9
        share.append((i, round(float(t[i]), 9)))
    assert share[0] == share[1]
