"""core.pattern_mesh: the unfold/export operators' numbers without Blender."""
import json

import numpy as np
import pytest
from meshgen import cylinder_piece, grid

from bolus_addon.core.errors import BolusError
from bolus_addon.core.pattern.pattern_mesh import (
    build_pattern,
    collect_pieces,
    diagnose_pieces,
    patch_islands,
    pattern_messages,
    pattern_polygons,
    piece_rows,
    piece_warning,
    stored_positions,
    svg_pieces,
    table_rows,
)
from bolus_addon.core.pattern.export.svg import outline_loops
from bolus_addon.core.unfold.unfold import Unfolding, iter_unfold_patches


def quads(nx, ny):
    """Blender-style polygons of meshgen.grid(nx, ny): quad k = triangles k and k + nx*ny, corners a b c d."""
    _, F = grid(nx, ny)
    c = nx * ny
    tri_poly = np.r_[np.arange(c), np.arange(c)]
    loop_vert = np.stack([F[:c, 0], F[:c, 1], F[:c, 2], F[c:, 2]], axis=1).ravel()
    return F, tri_poly, 4 * np.arange(c), np.full(c, 4), loop_vert


def two_patch_cylinder(na=6, nl=4):
    """A half cylinder (developable), columns i < na/2 patch 0, the rest patch 1; quads as polygons."""
    V, F = cylinder_piece(na=na, nl=nl)
    F, tri_poly, ls, lt, lv = quads(na, nl)
    poly_labels = (np.arange(na * nl) // nl >= na // 2).astype(np.int64)
    return V, F, tri_poly, ls, lt, lv, poly_labels


def unfold_all(V, F, isl):
    return [u for _, _, u in iter_unfold_patches(V, F, isl.islands)]


# ------------------------------------------------------------------ islands
def test_islands_split_a_patch_in_two_pieces_and_count_the_faces_left_out():
    V, F = grid(6, 2)
    _, tri_poly, *_ = quads(6, 2)
    col = (np.r_[np.arange(12), np.arange(12)] // 2)  # the quad's column 0..5
    labels = np.select([col < 2, col < 4, col == 4], [0, 1, -1], 0)  # patch 0 in columns 0-1 and 5
    isl = patch_islands(V, F, labels, face_groups=tri_poly)
    assert isl.count == 3 and isl.island_patch.tolist() == [0, 1, 0]
    assert isl.left_out == 2  # the two quads of column 4, not their four triangles
    assert np.all(isl.islands[labels < 0] == -1)
    assert patch_islands(V, F, labels).left_out == 4  # no face groups: triangles


def test_islands_refuse_bad_labels_and_a_region_with_no_patch():
    V, F = grid(2, 2)
    with pytest.raises(BolusError, match="none of the region's faces belongs to a patch"):
        patch_islands(V, F, np.full(len(F), -1))
    with pytest.raises(BolusError, match=r"one integer per triangle \(8\)"):
        patch_islands(V, F, np.zeros(3, dtype=int))
    with pytest.raises(BolusError, match="one integer per triangle"):
        patch_islands(V, F, np.zeros(len(F)))


def test_islands_degenerate_input():
    V, F = grid(3, 3)
    labels = np.zeros(len(F), dtype=int)
    W = V.copy()
    W[5] = W[6]  # two coincident vertices: the triangles between them have no area
    with pytest.raises(BolusError, match=r"the region has 2 zero-area triangle\(s\), e.g. triangle 1 "
                                         r"\(vertices 1, 5, 6\)"):
        patch_islands(W, F, labels)
    with pytest.raises(BolusError, match=r"e.g. the triangle on vertices 101, 105, 106: coincident"):
        patch_islands(W, F, labels, vert_ids=np.arange(len(V)) + 100)  # the user's (Blender's) indices
    W = V.copy()
    W[7, 1] = np.nan
    with pytest.raises(BolusError, match="non-finite.*vertex 7"):
        patch_islands(W, F, labels)
    W = V.copy()
    W[5] = W[6] + [0, -1e-2, 0]  # needles, not zero area: a sound result
    assert patch_islands(W, F, labels).count == 1
    # a non-manifold edge (a third triangle on edge 0-1): islands are still edge-connected pieces
    Vn = np.r_[V, [[10.0, 0.0, 20.0]]]
    Fn = np.r_[F, [[0, 4, len(V)]]]
    isl = patch_islands(Vn, Fn, np.r_[labels, 1])
    assert isl.count == 2 and isl.island_patch.tolist() == [0, 1]


# ------------------------------------------------------------------ polygons
def test_polygon_corners_map_to_the_pattern_vertex_of_their_own_triangles():
    V, F, tri_poly, ls, lt, lv, poly_labels = two_patch_cylinder()
    isl = patch_islands(V, F, poly_labels[tri_poly])
    F_pat = np.arange(3 * len(F)).reshape(-1, 3)  # every corner its own pattern vertex
    pp = pattern_polygons(tri_poly, isl.islands, F, F_pat, np.arange(len(V)), ls, lt, lv)
    assert pp.polys.tolist() == list(range(24)) and pp.sizes.tolist() == [4] * 24
    assert np.array_equal(pp.corner_src, lv)
    # corner c of quad k uses a corner of triangle k or k + 24 at the same source vertex
    k = np.repeat(pp.polys, 4)
    tri_of_pat = pp.corner_pat // 3
    assert np.all((tri_of_pat == k) | (tri_of_pat == k + 24))
    assert np.array_equal(F.ravel()[pp.corner_pat], pp.corner_src)
    assert np.array_equal(pp.loop_starts, 4 * np.arange(24))


def test_polygons_with_a_triangle_outside_the_islands_are_left_out():
    V, F, tri_poly, ls, lt, lv, _ = two_patch_cylinder()
    tri_island = np.zeros(len(F), dtype=int)
    tri_island[[0, 24 + 5]] = -1  # one triangle of quad 0, one of quad 5
    pp = pattern_polygons(tri_poly, tri_island, F, np.arange(3 * len(F)).reshape(-1, 3), np.arange(len(V)),
                          ls, lt, lv)
    assert sorted(set(range(24)) - set(pp.polys.tolist())) == [0, 5]
    with pytest.raises(BolusError, match="not a vertex of the region"):
        pattern_polygons(tri_poly, tri_island, F, F, np.arange(len(V) - 1), ls, lt, lv)


def test_stored_positions_are_float32_scene_units_and_the_mm_they_mean():
    UV = np.array([[0.1, 1e4 / 3], [12.3456789, -7.0]])
    co, back = stored_positions(UV, 1000.0)  # metres
    assert co.dtype == np.float32 and co.shape == (2, 3) and np.all(co[:, 2] == 0)
    assert np.array_equal(back, co[:, :2].astype(np.float64) * 1000.0)
    assert np.abs(back - UV).max() < 1e-3 and not np.array_equal(back, UV)
    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(BolusError, match="unit scale"):
            stored_positions(UV, bad)
    with pytest.raises(BolusError, match="finite"):
        stored_positions([[0.0, np.inf]], 1.0)
    with pytest.raises(BolusError, match=r"\(n, 2\)"):
        stored_positions(np.zeros((3, 3)), 1.0)


# ------------------------------------------------------------------ the whole pattern
@pytest.fixture(scope="module")
def cylinder_pattern():
    V, F, tri_poly, ls, lt, lv, poly_labels = two_patch_cylinder()
    isl = patch_islands(V, F, poly_labels[tri_poly], face_groups=tri_poly)
    done = unfold_all(V, F, isl)
    b = build_pattern(V, F, tri_poly, np.arange(len(V)), isl, done, poly_labels, ls, lt, lv,
                      mm_per_unit=1.0, gap_mm=10.0)
    return V, F, isl, done, b


def test_pattern_of_a_developable_cylinder_is_true_scale(cylinder_pattern):
    V, F, isl, done, b = cylinder_pattern
    assert len(b.co) == 40  # 35 source vertices, the 5 on the cut between the patches twice
    assert b.poly_patch.tolist() == [0] * 12 + [1] * 12
    # every pattern quad has its source quad's side lengths (the mapping is right)
    P = b.UV[b.polygons.corner_pat.reshape(-1, 4)]
    S = V[b.polygons.corner_src.reshape(-1, 4)]
    side = lambda X: np.linalg.norm(X - np.roll(X, -1, axis=1), axis=2)  # noqa: E731
    assert np.abs(side(P) - side(S)).max() < 0.05  # mm, on sides of 26 and 25 mm
    el, ea, flipped = b.errors[None]
    # a developable piece unfolds exactly (1e-16); what is measured is the stored float32
    # pattern, whose rounding leaves EL 5.2e-8, EA 1.0e-7 today
    assert max(max(u.EL, u.EA) for u in done) < 1e-12
    assert 1e-9 < el < 1e-6 and 1e-9 < ea < 1e-6
    assert flipped == 0 and np.abs(b.area_error).max() < 1e-6
    assert [r["name"] for r in b.rows] == ["patch 0", "patch 1"] and [r["faces"] for r in b.rows] == [24, 24]
    # the two patches were laid out apart
    pieces = svg_pieces(b.UV, np.r_[b.polygons.corner_pat.reshape(-1, 4)[:, :3],
                                    b.polygons.corner_pat.reshape(-1, 4)[:, [0, 2, 3]]],
                        np.r_[np.arange(24), np.arange(24)], b.poly_patch, table_rows(json.dumps({"islands": b.rows})))
    assert [p["label"] for p in pieces] == ["Patch 0", "Patch 1"] and pieces[0]["EL"] == b.rows[0]["EL"]
    (a0,), (a1,) = (outline_loops(p["UV"], p["F"]) for p in pieces)
    apart = [a0[:, k].max() + 10.0 <= a1[:, k].min() + 1e-9 or a1[:, k].max() + 10.0 <= a0[:, k].min() + 1e-9
             for k in (0, 1)]
    assert any(apart)  # 10 mm gap


def test_diagnosis_of_flat_pieces_and_the_messages(cylinder_pattern):
    V, F, isl, done, b = cylinder_pattern
    rows = [dict(r) for r in b.rows]
    diagnose_pieces(V, F, isl, done, rows, warn_fraction=0.03, sigma_mm=3.0)
    for r in rows:
        assert r["kind"] == "flat" and r["warn"] is False
        assert r["area_ratio"] == pytest.approx(1.0, abs=0.01)
    msgs = pattern_messages(done, rows, b.errors, 3.0, "skin_pattern")
    assert [lvl for lvl, _ in msgs] == ["INFO"] * 3
    assert msgs[0][1].startswith("Unfolded 2 islands into 'skin_pattern': EL ")
    assert msgs[1][1].startswith("Patch 0: 24 triangles, EL ")
    # a threshold below the figures: every piece warns, the summary comes last
    diagnose_pieces(V, F, isl, done, rows, warn_fraction=1e-9, sigma_mm=3.0)
    msgs = pattern_messages(done, rows, b.errors, 1e-7, "skin_pattern")
    assert [lvl for lvl, _ in msgs][-3:] == ["WARNING"] * 3
    assert msgs[-1][1].startswith("2 of 2 pattern pieces are not fit to cut (EL or EA above 1e-07 %")
    assert msgs[-2][1] == piece_warning(rows[1], 1e-7) and "do not cut it as it is" in msgs[-2][1]


def fake_unfolding(warnings=(), cut=""):
    return Unfolding(np.zeros((3, 2)), np.array([[0, 1, 2]]), np.arange(3), 0.01, 0.02, 1, 2, 5, 0.0, 0.5, "lbfgs",
                     cut, list(warnings))


def test_messages_pass_the_cores_warnings_as_they_are_no_text_filter():
    """The core's warnings are data: every one is passed on verbatim (the old regex filter is gone)."""
    us = [fake_unfolding(["3 triangles remain flipped after the overlap correction",
                          "the pattern overlaps itself (12 triangles)"], cut="cut along 1 path"),
          fake_unfolding()]
    rows = [{"name": "patch 0 piece 1/2", "cut": "cut along 1 path", "faces": 1, "EL": 0.01, "EA": 0.02,
             "flipped": 1, "overlaps": 2, "seconds": 0.5, "area_ratio": 0.9, "warn": True, "advice": "split it"},
            {"name": "patch 0 piece 2/2", "cut": "", "faces": 1, "EL": 0.0, "EA": 0.0, "flipped": 0,
             "overlaps": 0, "seconds": 0.1, "area_ratio": 1.0, "warn": False, "advice": ""}]
    msgs = pattern_messages(us, rows, {None: (0.01, 0.02, 1)}, 3.0, "p")
    assert msgs[:3] == [("WARNING", "patch 0 piece 1/2: 3 triangles remain flipped after the overlap correction"),
                        ("WARNING", "patch 0 piece 1/2: the pattern overlaps itself (12 triangles)"),
                        ("INFO", "patch 0 piece 1/2: not a disk, cut along 1 path")]
    assert msgs[-1] == ("WARNING", "1 of 2 pattern pieces are not fit to cut (EL or EA above 3 %, or folded over): "
                                   "patch 0 piece 1/2; see the advice above")


def test_piece_rows_name_the_pieces_of_a_split_patch():
    isl = patch_islands(*grid(6, 1), np.r_[[0, 0, 1, 1, 0, 0], [0, 0, 1, 1, 0, 0]])
    # errors are per piece (island): piece 2 measured, the others fall back to their unfolding's own
    rows = piece_rows(isl, [fake_unfolding()] * 3, {2: (0.1, 0.2, 0)})
    assert [r["name"] for r in rows] == ["patch 0 piece 1/2", "patch 1", "patch 0 piece 2/2"]
    assert [r["EL"] for r in rows] == [0.01, 0.01, 0.1] and [r["faces"] for r in rows] == [4, 4, 4]
    assert [(r["piece_in_patch"], r["pieces_in_patch"]) for r in rows] == [(1, 2), (1, 1), (2, 2)]


def _sheet(piece, darts=(), splits=(), met=True, reason=""):
    from types import SimpleNamespace  # noqa: PLC0415
    k = int(np.max(piece)) + 1
    return SimpleNamespace(piece=np.asarray(piece), unfoldings=[fake_unfolding()] * k, darts=list(darts),
                           splits=list(splits), met=met, reason=reason)


def test_collect_pieces_numbers_the_pieces_of_every_island_in_turn():
    from types import SimpleNamespace  # noqa: PLC0415
    isl = patch_islands(*grid(6, 1), np.r_[[0, 0, 1, 1, 0, 0], [0, 0, 1, 1, 0, 0]])
    # island 0 (4 triangles) split in two with a dart in its second piece; islands 1, 2 one piece each
    dart = SimpleNamespace(piece=1, path=np.array([3, 4]), defect=0.5)
    split = SimpleNamespace(pieces=(0, 1), path=np.array([1, 8]), excess=0.2)
    res = [_sheet([0, 1, 1, 0], [dart], [split]), _sheet([0, 0, 0, 0]), _sheet([0, 0, 0, 0], met=False,
                                                                                 reason="piece 1: EL 5 %")]
    lay = collect_pieces(isl, res)
    rows0 = np.nonzero(isl.islands == 0)[0]
    assert lay.islands.islands[rows0].tolist() == [0, 1, 1, 0]
    assert set(lay.islands.islands[isl.islands == 1].tolist()) == {2}
    assert set(lay.islands.islands[isl.islands == 2].tolist()) == {3}
    assert lay.islands.island_patch.tolist() == [0, 0, 1, 0] and len(lay.unfoldings) == 4
    assert lay.darts_of(1) == 1 and lay.darts_of(0) == 0 and lay.splits_of(0) == 1 and lay.splits_of(1) == 0
    assert lay.unmet == [(0, "piece 1: EL 5 %")]
    rows = piece_rows(lay.islands, lay.unfoldings, {})
    assert [r["name"] for r in rows] == ["patch 0 piece 1/3", "patch 0 piece 2/3", "patch 1", "patch 0 piece 3/3"]
    with pytest.raises(BolusError, match="do not cover"):
        collect_pieces(isl, [_sheet([0, 1, 1]), res[1], res[2]])


def test_a_polygon_torn_between_two_pieces_is_refused():
    V, F, tri_poly, ls, lt, lv, _ = two_patch_cylinder()
    tri_island = np.zeros(len(F), dtype=int)
    tri_island[24 + 3] = 1  # the second triangle of quad 3 in another piece
    with pytest.raises(BolusError, match="polygon 3 lies in two pattern pieces"):
        pattern_polygons(tri_poly, tri_island, F, np.arange(3 * len(F)).reshape(-1, 3), np.arange(len(V)),
                         ls, lt, lv)


def test_table_rows_and_svg_pieces_bad_input():
    assert table_rows(None) == {} and table_rows("{not json") == {} and table_rows('{"x": 1}') == {}
    assert table_rows(json.dumps({"islands": [{"patch": 2, "EL": 1}, {"patch": 2, "EL": 9}]})) == {2: {"patch": 2,
                                                                                                      "EL": 1}}
    P, F = grid(2, 2)
    tri_poly, poly_patch = np.arange(8), np.zeros(8, dtype=int)
    assert len(svg_pieces(P, F, tri_poly, poly_patch)) == 1
    bad = P.copy()
    bad[4, 0] = np.inf
    with pytest.raises(BolusError, match="vertex 4"):
        svg_pieces(bad, F, tri_poly, poly_patch)
    with pytest.raises(BolusError, match="outside the vertex array"):
        svg_pieces(P, F + 100, tri_poly, poly_patch)
    with pytest.raises(BolusError, match="one polygon per triangle"):
        svg_pieces(P, F, tri_poly[:3], poly_patch)
