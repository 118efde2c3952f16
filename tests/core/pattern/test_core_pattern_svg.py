"""Pattern export: boundary loops, seam-allowance offset, the true-scale SVG."""
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from meshgen import grid

from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.geometry2d import cross2d
from bolus_addon.core.mesh.layout import pack_islands
from bolus_addon.core.pattern.export.svg import (
    SCALE_BAR_MM,
    offset_polygon,
    outline_loop_indices,
    outline_loops,
    pattern_svg,
    signed_area,
    svg_outline_paths,
)
from bolus_addon.core.pattern.polygon_offset import winding_numbers

NS = {"svg": "http://www.w3.org/2000/svg"}


def grid_with_hole(n=6, size=60.0, hole=(2, 4)):
    """Flat n x n grid (UV (n+1)^2 x 2, F) without the cells [hole[0], hole[1])^2."""
    V, F = grid(n, n, size)
    cell = np.concatenate([np.arange(n * n)] * 2)  # grid(): two triangles per cell, (i, j) -> i*n + j
    i, j = cell // n, cell % n
    inside = (i >= hole[0]) & (i < hole[1]) & (j >= hole[0]) & (j < hole[1])
    return V[:, :2], F[~inside]


def perimeter(P):
    return float(np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1).sum())


def point_segment_distance(X, P):
    """Distances (t,) of points X (t,2) to the closed polygon P (k,2)."""
    A, B = P, np.roll(P, -1, axis=0)
    R = B - A
    s = np.clip(np.einsum("tsk,sk->ts", X[:, None] - A[None], R) / np.einsum("sk,sk->s", R, R), 0, 1)
    return np.linalg.norm(X[:, None] - (A[None] + s[..., None] * R[None]), axis=2).min(axis=1)


def is_simple(P):
    """No two non-neighbouring edges of the closed polygon P touch or cross."""
    k = len(P)
    A, B = P, np.roll(P, -1, axis=0)
    for i in range(k):
        for j in range(i + 2, k):
            if i == 0 and j == k - 1:
                continue
            d1, d2 = B[i] - A[i], B[j] - A[j]
            den = cross2d(d1, d2)
            if abs(den) <= 1e-12 * np.linalg.norm(d1) * np.linalg.norm(d2):  # parallel: touching ends?
                ends_j = point_segment_distance(np.array([A[j], B[j]]), np.array([A[i], B[i]]))
                ends_i = point_segment_distance(np.array([A[i], B[i]]), np.array([A[j], B[j]]))
                if min(ends_i.min(), ends_j.min()) < 1e-9:
                    return False
                continue
            q = A[j] - A[i]
            t = cross2d(q, d2) / den
            u = cross2d(q, d1) / den
            if -1e-12 <= t <= 1 + 1e-12 and -1e-12 <= u <= 1 + 1e-12:
                return False
    return True


def star(k=160, seed=0):
    g = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    r = 30 + 12 * np.sin(5 * t) + g.uniform(-1.5, 1.5, k)
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=1)


# ------------------------------------------------------------------ outline loops
def test_outline_of_grid_with_hole_has_outer_ccw_and_hole_cw():
    UV, F = grid_with_hole()
    loops = outline_loops(UV, F)
    assert len(loops) == 2
    outer, hole = loops
    assert signed_area(outer) == pytest.approx(60.0**2)
    assert signed_area(hole) == pytest.approx(-(20.0**2))
    assert len(outer) == 4 * 6 and len(hole) == 4 * 2
    assert perimeter(outer) == pytest.approx(240.0) and perimeter(hole) == pytest.approx(80.0)
    # the loops walk real boundary edges: consecutive indices share exactly one triangle
    for L in outline_loop_indices(UV, F):
        for a, b in zip(L, np.roll(L, -1)):
            assert np.sum(np.isin(F, [a, b]).sum(axis=1) == 2) == 1


def test_outline_orientation_does_not_depend_on_triangle_order():
    UV, F = grid_with_hole()
    outer, hole = outline_loops(UV, F[:, ::-1])  # clockwise triangles
    assert signed_area(outer) > 0 and signed_area(hole) < 0


def test_outline_of_triangles_touching_at_a_vertex_is_two_loops():
    UV = np.array([[0.0, 0], [10, 0], [10, 10], [-10, 0], [-10, -10]])
    F = np.array([[0, 1, 2], [0, 3, 4]])
    loops = outline_loop_indices(UV, F)
    assert sorted(map(len, loops)) == [3, 3]
    assert all(signed_area(UV[L]) > 0 for L in loops)


@pytest.mark.parametrize("seed", range(4))
def test_outline_of_ragged_cell_patches_adds_up_to_their_area(seed):
    """Random cells of a grid: several parts, holes, cells touching at a corner only."""
    g = np.random.default_rng(seed)
    V, F = grid(10, 10, 100.0, jitter=0.2 * (seed % 2), rng=seed)
    UV = V[:, :2]
    cell = np.concatenate([np.arange(100)] * 2)
    F = F[(g.random(100) < 0.6)[cell] & (g.random(len(F)) < 0.93)]
    area = 0.5 * cross2d(UV[F[:, 1]] - UV[F[:, 0]], UV[F[:, 2]] - UV[F[:, 0]]).sum()
    loops = outline_loops(UV, F)
    assert sum(signed_area(L) for L in loops) == pytest.approx(area, rel=1e-12)  # outer +, holes -
    assert signed_area(loops[0]) > 0
    assert len(loops) > 3  # several parts, some touching at a corner


def test_outline_rejects_bad_input():
    UV, F = grid_with_hole()
    with pytest.raises(BolusError):
        outline_loops(UV, F[:0])
    with pytest.raises(BolusError):
        outline_loops(UV, F + len(UV))
    with pytest.raises(BolusError):
        outline_loops(np.c_[UV, UV[:, :1]], F)


# ------------------------------------------------------------------ offset
def test_offset_square_is_exact():
    sq = np.array([[0.0, 0], [10, 0], [10, 10], [0, 10]])
    out = offset_polygon(sq, 2.0)
    np.testing.assert_allclose(out, [[-2, -2], [12, -2], [12, 12], [-2, 12]], atol=1e-12)
    np.testing.assert_allclose(offset_polygon(sq[::-1], 2.0), out, atol=1e-12)  # clockwise in, same out
    inner = offset_polygon(sq, -2.0)
    assert signed_area(inner) == pytest.approx(36.0)
    assert {tuple(p) for p in np.round(inner, 12)} == {(2, 2), (8, 2), (8, 8), (2, 8)}
    assert len(offset_polygon(sq, -6.0)) == 0  # shrunk away
    np.testing.assert_allclose(offset_polygon(sq, 0.0), sq)


def test_offset_circle_area():
    r, d, n = 30.0, 3.0, 64
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    out = offset_polygon(np.stack([r * np.cos(t), r * np.sin(t)], 1), d)
    assert len(out) == n
    apothem = r * np.cos(np.pi / n) + d  # a regular n-gon again, every side pushed out by d
    assert signed_area(out) == pytest.approx(n * apothem**2 * np.tan(np.pi / n), rel=1e-12)
    assert signed_area(out) == pytest.approx(np.pi * (r + d) ** 2, rel=2e-3)


def test_offset_L_shape_concave_corner():
    L = np.array([[0.0, 0], [20, 0], [20, 10], [10, 10], [10, 20], [0, 20]])
    out = offset_polygon(L, 2.0)
    np.testing.assert_allclose(out, [[-2, -2], [22, -2], [22, 12], [12, 12], [12, 22], [-2, 22]], atol=1e-12)
    assert is_simple(out)
    inner = offset_polygon(L, -2.0)
    assert {tuple(p) for p in np.round(inner, 12)} == {(2, 2), (18, 2), (18, 8), (8, 8), (8, 18), (2, 18)}


def test_offset_closes_a_narrow_notch():
    U = np.array([[0.0, 0], [30, 0], [30, 30], [16, 30], [16, 5], [14, 5], [14, 30], [0, 30]])
    np.testing.assert_allclose(offset_polygon(U, 2.0), [[-2, -2], [32, -2], [32, 32], [-2, 32]], atol=1e-12)
    assert is_simple(offset_polygon(U, 0.5))


def ragged_outlines():
    UV, F = ragged_patch()
    return {"star": star(), "patch": outline_loops(UV, F)[0]}


@pytest.mark.parametrize("shape", ["star", "patch"])
@pytest.mark.parametrize("d", [0.3, 3.0, 10.0, -0.5, -3.0])
def test_offset_of_ragged_outlines_is_simple_and_at_the_right_distance(shape, d):
    from bolus_addon.core.pattern.polygon_offset import winding_numbers as _winding

    P = ragged_outlines()[shape]
    out = offset_polygon(P, d)
    assert is_simple(out) and signed_area(out) > 0
    # sampled along its edges, the offset is never closer than |d| to the outline, and the
    # miter limit keeps it within sqrt(5) |d| (a corner cut square at 2 |d|)
    s = np.linspace(0, 1, 7)[:-1]
    samples = (out[:, None] + s[None, :, None] * (np.roll(out, -1, axis=0) - out)[:, None]).reshape(-1, 2)
    dist = point_segment_distance(samples, P)
    assert dist.min() >= abs(d) * (1 - 1e-9)
    assert dist.max() <= np.sqrt(5) * abs(d) * (1 + 1e-9)
    if d > 0:  # the outline lies inside the grown polygon
        assert np.all(_winding(P, out, np.roll(out, -1, axis=0)) == 1)
        assert signed_area(out) > signed_area(P)
    else:  # the shrunk polygon lies inside the outline
        assert np.all(_winding(out, P, np.roll(P, -1, axis=0)) == 1)


def test_offset_sharp_corner_is_cut_square_at_the_miter_limit():
    P = np.array([[0.0, 0], [100, 0], [0, 5]])  # about 2.9 degrees at (100, 0)
    d = 2.0
    out = offset_polygon(P, d)
    assert is_simple(out)
    e1, e2 = np.array([-1.0, 0]), (P[2] - P[1]) / np.linalg.norm(P[2] - P[1])  # unit edges leaving the tip
    u = -(e1 + e2) / np.linalg.norm(e1 + e2)
    reach = (out - P[1]) @ u
    assert np.sort(reach)[-2:] == pytest.approx([2 * d, 2 * d])  # two corners on the cut at 2 d
    assert point_segment_distance(out, P).min() >= d * (1 - 1e-9)


def test_offset_rejects_degenerate_polygons():
    with pytest.raises(BolusError):
        offset_polygon(np.array([[0.0, 0], [1, 1], [2, 2]]), 1.0)
    with pytest.raises(BolusError):
        offset_polygon(np.zeros((4, 3)), 1.0)


# ------------------------------------------------------------------ SVG
def ragged_patch():
    """A jittered grid cut along triangle edges by a wavy curve: a zig-zag outline of ~250 corners."""
    V, F = grid(80, 80, 200.0, jitter=0.3)
    c = V[F].mean(axis=1)[:, :2] - 100
    r, th = np.hypot(c[:, 0], c[:, 1]), np.arctan2(c[:, 1], c[:, 0])
    return V[:, :2], F[r < 70 + 15 * np.sin(4 * th)]


def three_islands():
    UV, F = grid_with_hole()
    V2, F2 = grid(5, 3, 40.0, jitter=0.2, rng=1)
    UV3 = np.array([[0.0, 0], [37.3, 3.1], [11.7, 21.9]])
    UV4, F4 = ragged_patch()
    islands = [UV, V2[:, :2] * [1.0, 0.6], UV3, UV4]
    moved = pack_islands(islands, gap_mm=8.0)
    return [
        {"UV": moved[0], "F": F, "label": "1", "EL": 0.0123, "EA": 0.0234},
        {"UV": moved[1], "F": F2, "label": "nose tip", "EL": 0.001, "EA": 0.5},
        {"UV": moved[2], "F": np.array([[0, 1, 2]]), "label": "3"},
        {"UV": moved[3], "F": F4, "label": "4", "EL": 0.0, "EA": 0.0},
    ]


def parse(svg):
    root = ET.fromstring(svg)
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    return root


def test_svg_is_true_scale_and_outlines_read_back():
    islands = three_islands()
    svg = pattern_svg(islands, title="test face")
    root = parse(svg)
    W, H = root.get("width"), root.get("height")
    assert W.endswith("mm") and H.endswith("mm")
    x0, y0, vw, vh = map(float, root.get("viewBox").split())
    assert (x0, y0) == (0, 0) and float(W[:-2]) == vw and float(H[:-2]) == vh
    # the scale bar is 50 user units = 50 mm on paper
    bar = root.find(".//svg:line[@id='scale-bar']", NS)
    assert float(bar.get("x2")) - float(bar.get("x1")) == SCALE_BAR_MM == 50.0
    assert float(bar.get("y2")) == float(bar.get("y1"))
    texts = [t.text for t in root.iter("{http://www.w3.org/2000/svg}text")]
    assert "50 mm" in texts and "print at 100 % (no fit-to-page)" in texts and "test face" in texts
    assert {"1", "nose tip", "3", "4"} <= set(texts)
    assert "EL 1.23 % · EA 2.34 %" in texts and "EL 0.10 % · EA 50.00 %" in texts
    # one group per patch, holding its cut lines and its label
    groups = root.findall(".//svg:g[@class='patch']", NS)
    assert [g.get("id") for g in groups] == ["patch-1", "patch-nose_tip", "patch-3", "patch-4"]
    cuts = [g.findall("svg:path[@class='cut']", NS) for g in groups]
    assert list(map(len, cuts)) == [2, 1, 1, 1]
    assert len(groups[2].findall("svg:text", NS)) == 1  # no EL/EA given: label only
    for p in root.iter("{http://www.w3.org/2000/svg}path"):
        assert p.get("fill") == "none" and p.get("stroke-width") == "0.300" and p.get("d").endswith("Z")
    # read back: same loops, same places, same perimeters (even of the ragged 250-corner outline)
    expected = [L for isl in islands for L in outline_loops(isl["UV"], isl["F"])]
    back = svg_outline_paths(svg)
    assert len(back) == len(expected) == 5 and len(expected[-1]) > 200
    for P, Q in zip(back, expected):
        assert P.shape == Q.shape
        np.testing.assert_allclose(P, Q, atol=1e-5)
        assert perimeter(P) == pytest.approx(perimeter(Q), abs=1e-3)
    # outline coordinates rounded to 1 um still land within 1 um
    for P, Q in zip(svg_outline_paths(pattern_svg(islands, path_decimals=3)), expected):
        np.testing.assert_allclose(P, Q, atol=1e-3)
    # every drawn point is on the page, inside the margin
    for p in root.iter("{http://www.w3.org/2000/svg}path"):
        xy = np.array(p.get("d").replace("M", "").replace("L", "").replace("Z", "").split(), float).reshape(-1, 2)
        assert xy.min() >= 10.0 - 1e-3 and xy[:, 0].max() <= vw - 10 + 1e-3 and xy[:, 1].max() <= vh


def test_svg_is_seen_from_above():
    """+y of the pattern is up on paper, and a counter-clockwise outline stays counter-clockwise on paper."""
    UV = np.array([[0.0, 0], [40, 0], [0, 20]])
    svg = pattern_svg([{"UV": UV, "F": np.array([[0, 1, 2]]), "label": "a"}], margin_mm=10.0)
    d = parse(svg).find(".//svg:path[@class='cut']", NS).get("d")
    xy = np.array(d.replace("M", "").replace("L", "").replace("Z", "").split(), float).reshape(-1, 2)
    top = xy[np.argmin(xy[:, 1])]  # smallest paper y = highest on the page
    np.testing.assert_allclose(top, [10, 10])  # the corner (0, 20) of the pattern
    paper = xy * [1, -1]  # paper y points down: as seen on the page
    assert signed_area(paper) > 0


def test_svg_seam_allowance_is_dashed_and_outside():
    islands = three_islands()
    d = 5.0
    root = parse(pattern_svg(islands, seam_allowance_mm=d))
    seams = root.findall(".//svg:path[@class='seam']", NS)
    assert len(seams) == 5 and all(s.get("stroke-dasharray") for s in seams)
    back_cut = svg_outline_paths(pattern_svg(islands, seam_allowance_mm=d))
    back_seam = svg_outline_paths(pattern_svg(islands, seam_allowance_mm=d), kind="seam")
    outer_cut, outer_seam = back_cut[0], back_seam[0]
    np.testing.assert_allclose(outer_seam.min(axis=0), outer_cut.min(axis=0) - d, atol=1e-3)
    hole_cut, hole_seam = back_cut[1], back_seam[1]  # the hole shrinks by d on every side
    assert signed_area(hole_seam) == pytest.approx(-((20 - 2 * d) ** 2), abs=0.05)
    assert signed_area(hole_cut) == pytest.approx(-(20.0**2), abs=0.05)
    assert not parse(pattern_svg(islands)).findall(".//svg:path[@class='seam']", NS)


def test_svg_labels_are_escaped_and_ids_unique():
    UV = np.array([[0.0, 0], [40, 0], [0, 30]])
    isl = {"UV": UV, "F": np.array([[0, 1, 2]]), "label": "<nose> & ear"}
    root = parse(pattern_svg([isl, dict(isl, UV=UV + [60, 0])], title='a "b" <c>'))
    ids = [g.get("id") for g in root.findall(".//svg:g[@class='patch']", NS)]
    assert ids == ["patch-_nose____ear", "patch-_nose____ear-2"]
    texts = [t.text for t in root.iter("{http://www.w3.org/2000/svg}text")]
    assert texts.count("<nose> & ear") == 2 and 'a "b" <c>' in texts


def test_svg_path_reader_handles_relative_and_axis_commands():
    svg = (
        '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 50" width="100mm" height="50mm">'
        '<path class="cut" d="m 10,10 h 20 v 10 l -20,0 z M 50 40 L 60 40 L 55 30 Z"/></svg>')
    P, Q = svg_outline_paths(svg)
    np.testing.assert_allclose(P, [[10, 40], [30, 40], [30, 30], [10, 30]])  # flipped about the page height
    np.testing.assert_allclose(Q, [[50, 10], [60, 10], [55, 20]])
    with pytest.raises(BolusError):
        svg_outline_paths(svg.replace("h 20", "c 1 2 3 4 5 6"))


def test_svg_bad_input():
    with pytest.raises(BolusError):
        pattern_svg([])
    UV, F = grid_with_hole()
    with pytest.raises(BolusError):
        pattern_svg([{"UV": UV, "label": "x"}])
    with pytest.raises(BolusError):
        pattern_svg([{"UV": UV, "F": F}], seam_allowance_mm=-1)
    with pytest.raises(BolusError):
        svg_outline_paths("<svg")


# ------------------------------------------------------------------ degenerate input
def test_outline_with_coincident_vertices_and_needles_is_sound():
    """Collapsed and needle triangles do not change the outline: its area is the pattern's."""
    UV, F = grid_with_hole()
    for gap in (0.0, 1e-3):  # coincident (two zero-area triangles), then needles
        W = UV.copy()
        W[8] = W[1] + [gap, 0.0]  # an interior vertex moved onto / next to a border vertex
        loops = outline_loops(W, F)
        area = 0.5 * cross2d(W[F[:, 1]] - W[F[:, 0]], W[F[:, 2]] - W[F[:, 0]]).sum()
        assert len(loops) == 2 and sum(signed_area(L) for L in loops) == pytest.approx(area, rel=1e-12)
        assert all(np.isfinite(L).all() for L in loops)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_pattern_is_refused_by_name(bad):
    UV, F = grid_with_hole()
    UV = UV.copy()
    UV[10, 0] = bad
    for fn in (outline_loops, outline_loop_indices):
        with pytest.raises(BolusError, match="non-finite.*vertex 10"):
            fn(UV, F)
    with pytest.raises(BolusError, match="non-finite.*vertex 10"):
        pattern_svg([{"UV": UV, "F": F, "label": "x"}])
    P = np.array([[0.0, 0], [10, 0], [10, 10], [0, 10]])
    P[2, 1] = bad
    with pytest.raises(BolusError, match="corner 2 is not finite"):
        offset_polygon(P, 1.0)
    with pytest.raises(BolusError, match="offset distance is not finite"):
        offset_polygon(P[[0, 1, 3]], bad)
    with pytest.raises(BolusError, match="point 1 is not finite"):
        winding_numbers(P[[0, 2]], P[[0, 1]], P[[1, 3]])
    with pytest.raises(BolusError, match="margin must be a length"):
        pattern_svg([{"UV": UV[:3] * 0 + [[0, 0], [1, 0], [0, 1]], "F": [[0, 1, 2]]}], margin_mm=bad)


def test_non_manifold_pattern_and_closed_piece_are_refused():
    UV = np.array([[0.0, 0], [10, 0], [5, 8], [5, -8], [4, 6]])
    with pytest.raises(BolusError, match="shared by more than two faces"):
        outline_loops(UV, [[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    V = np.array([[0.0, 0], [1, 0], [0, 1], [1, 1]])
    with pytest.raises(BolusError, match="no boundary"):  # a tetrahedron's faces, flattened
        outline_loops(V, [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])


def test_offset_of_polygons_with_coincident_corners_and_needle_spikes():
    sq = np.array([[0.0, 0], [10, 0], [10, 0], [10, 10], [0, 10], [0, 10]])  # two corners given twice
    np.testing.assert_allclose(offset_polygon(sq, 2.0), [[-2, -2], [12, -2], [12, 12], [-2, 12]], atol=1e-12)
    # a needle spike (1 um wide, 20 mm long) out of a square: the miter is cut square, the result simple
    spike = np.array([[0.0, 0], [10, 0], [10, 5], [30, 5.0005], [10, 5.001], [10, 10], [0, 10]])
    out = offset_polygon(spike, 1.0)
    assert is_simple(out) and signed_area(out) > signed_area(spike)
    assert out[:, 0].max() <= 30 + 2.0 * 1.0 + 1e-9  # never past MITER_LIMIT * d from the tip
