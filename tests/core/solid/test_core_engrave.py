"""Engraved labels and L / R markers (core/engrave.py)."""
import numpy as np
import pytest

import manifold3d as m3
from bolus_addon.core.solid.engrave import LABEL_HEIGHTS, TextOutline, engrave_labels, engrave_text, strings_needed
from bolus_addon.core.errors import BolusError
from bolus_addon.core.solid.manifold import SIDE_CUT, SIDE_INNER, SIDE_OUTER, SIDE_RIM, closed_report, from_manifold
from meshgen import box, degenerate_variants

DEPTH = 0.6
#: an "L" (bar on the left, foot to the right): mirrored text shows the foot on the left
GLYPH_L = [np.array([[0, 0], [0.7, 0], [0.7, 0.2], [0.2, 0.2], [0.2, 1], [0, 1]], float)]
#: an "O" with its hole (clockwise)
GLYPH_O = [np.array([[0, 0], [0.8, 0], [0.8, 1], [0, 1]], float),
           np.array([[0.2, 0.2], [0.2, 0.8], [0.6, 0.8], [0.6, 0.2]], float)]
AREA_L = 0.7 * 0.2 + 0.2 * 0.8
AREA_O = 0.8 - 0.4 * 0.6


def text(*glyphs, gap=0.2):
    """A TextOutline of glyphs set side by side (cap height 1)."""
    polys, x = [], 0.0
    for g in glyphs:
        polys += [p + [x, 0.0] for p in g]
        x += max(p[:, 0].max() for p in g) + gap
    return TextOutline(polys, x - gap)


LO = text(GLYPH_L, GLYPH_O)
AREA_LO = AREA_L + AREA_O


def slab(size=(60.0, 40.0, 8.0), n=20, offset=(0.0, 0.0, 0.0)):
    """A box whose top is the outer face, bottom the inner face, sides the rim."""
    V, F = box(size, n=n)
    V = V + offset
    C = V[F].mean(axis=1)
    side = np.full(len(F), SIDE_RIM, np.int8)
    side[C[:, 2] > offset[2] + size[2] - 1e-6] = SIDE_OUTER
    side[C[:, 2] < offset[2] + 1e-6] = SIDE_INNER
    return V, F, side


def radial_sides(V, F, centre_axis):
    """Sides of a shell about the origin: outer where the normal points away from ``centre_axis``
    (a function giving the outward radial unit vector at points), inner where towards, else rim."""
    C = V[F].mean(axis=1)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n /= np.linalg.norm(n, axis=1)[:, None]
    radial = np.einsum("ij,ij->i", n, centre_axis(C))
    side = np.full(len(F), SIDE_RIM, np.int8)
    side[radial > 0.9] = SIDE_OUTER
    side[radial < -0.9] = SIDE_INNER
    return side


def cylinder_shell(R=60.0, r=50.0, length=80.0, seg=256):
    M = m3.Manifold.cylinder(length, R, R, seg) - m3.Manifold.cylinder(length, r, r, seg)
    M = M.trim_by_plane((0, 1, 0), 0.0)
    V, F = from_manifold(M)
    return V, F, radial_sides(V, F, lambda C: C * [1, 1, 0] / np.hypot(C[:, 0], C[:, 1])[:, None])


def sphere_shell(R=60.0, r=50.0, seg=192):
    M = (m3.Manifold.sphere(R, seg) - m3.Manifold.sphere(r, seg)).trim_by_plane((0, 0, 1), 0.0)
    V, F = from_manifold(M)
    return V, F, radial_sides(V, F, lambda C: C / np.linalg.norm(C, axis=1)[:, None])


def volume(V, F):
    return closed_report(V, F)["volume_mm3"]


def test_strings_needed():
    assert strings_needed("") == [] and strings_needed("  ", 3) == []
    assert strings_needed("PAT7") == ["PAT7", "L", "R"]
    assert strings_needed("PAT7", 3) == ["PAT7 0", "PAT7 1", "PAT7 2", "L", "R"]


def test_flat_slab_depth_volume_and_sides():
    V, F, side = slab()
    h = 6.0
    V2, F2, s2, note = engrave_text(V, F, side, LO, height_mm=h, up=(0, 1, 0))
    assert note is None
    rep = closed_report(V2, F2)
    assert rep["closed"] and rep["components"] == 1 and rep["genus"] == 0
    removed = volume(V, F) - volume(V2, F2)
    assert removed == pytest.approx(AREA_LO * h * h * DEPTH, rel=0.10)
    # the letters' floors lie exactly DEPTH below the top (z = 8), nothing deeper
    inside = (V2[:, 0] > 1) & (V2[:, 0] < 59) & (V2[:, 1] > 1) & (V2[:, 1] < 39) & (V2[:, 2] > 1)
    assert V2[inside, 2].min() == pytest.approx(8 - DEPTH, abs=1e-9)
    floor = np.abs(V2[F2].mean(axis=1)[:, 2] - (8 - DEPTH)) < 1e-6
    assert floor.sum() > 0 and np.all(s2[floor] == SIDE_OUTER)
    # rays straight down over the letters: the first hit is DEPTH below the top
    C = V2[F2[floor]].mean(axis=1)
    M = m3.Manifold(m3.Mesh64(vert_properties=np.array(V2), tri_verts=np.array(F2, dtype=np.uint64)))
    for c in C[:: max(1, len(C) // 20)]:
        hit = M.ray_cast((c[0], c[1], 20.0), (c[0], c[1], -1.0))[0]
        assert hit.position[2] == pytest.approx(8 - DEPTH, abs=1e-6)
    # the inner face and the rim are untouched: same area per class
    def area(Vx, Fx, mask):
        T = Vx[Fx[mask]]
        return 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1).sum()
    for s in (SIDE_INNER, SIDE_RIM):
        assert area(V2, F2, s2 == s) == pytest.approx(area(V, F, side == s), rel=1e-9)
    # placed where there is most room: the middle of the top
    assert C[:, 0].mean() == pytest.approx(30.0, abs=3.0) and C[:, 1].mean() == pytest.approx(20.0, abs=3.0)


@pytest.mark.parametrize("up, right", [((0, 1, 0), (1, 0, 0)), ((1, 0, 0), (0, -1, 0)), ((0, -1, 0), (-1, 0, 0))])
def test_not_mirrored_seen_from_outside(up, right):
    """Seen from above (outside of the top face) with `up` pointing up, the L's foot points to the
    viewer's right, which is up x n (n = +z)."""
    V, F, side = slab((60.0, 60.0, 8.0))
    V2, F2, s2, note = engrave_text(V, F, side, TextOutline(GLYPH_L, 0.7), height_mm=10.0, up=up)
    assert note is None
    C = V2[F2].mean(axis=1)
    floor = C[np.abs(C[:, 2] - (8 - DEPTH)) < 1e-6]
    up, right = np.array(up, float), np.array(right, float)
    assert np.allclose(np.cross(up, [0, 0, 1]), right)
    y, x = floor @ up, floor @ right
    # the bar (upper half of the letter) lies on the left of the letter's middle, the foot reaches right
    top = y > y.min() + 0.5 * (y.max() - y.min())
    assert x[top].mean() < x.mean() - 1.0
    assert x[~top].max() > x[top].max() + 3.0


def test_underside_is_read_from_below():
    """On a face looking down (-z) the text reads correctly seen from below: x = up x (-z)."""
    V, F, side = slab((60.0, 60.0, 8.0))
    C = V[F].mean(axis=1)
    side = np.where(C[:, 2] < 1e-6, SIDE_OUTER, np.where(C[:, 2] > 8 - 1e-6, SIDE_INNER, SIDE_RIM)).astype(np.int8)
    V2, F2, s2, note = engrave_text(V, F, side, TextOutline(GLYPH_L, 0.7), height_mm=10.0, up=(0, 1, 0))
    assert note is None
    Cf = V2[F2].mean(axis=1)
    floor = Cf[np.abs(Cf[:, 2] - DEPTH) < 1e-6]
    y, x = floor[:, 1], -floor[:, 0]  # the viewer below sees +x on his left
    top = y > y.min() + 0.5 * (y.max() - y.min())
    assert x[top].mean() < x.mean() - 1.0


def test_cylinder_shell_bends_with_the_surface():
    V, F, side = cylinder_shell()
    h = 8.0
    V2, F2, s2, note = engrave_text(V, F, side, LO, height_mm=h, up=(0, 0, 1))
    assert note is None
    rep = closed_report(V2, F2)
    assert rep["closed"] and rep["components"] == 1
    assert volume(V, F) - volume(V2, F2) == pytest.approx(AREA_LO * h * h * DEPTH, rel=0.10)
    rad = np.hypot(V2[:, 0], V2[:, 1])
    sag = 60.0 * (1 - np.cos(np.pi / 256))  # the faceted surface lies up to this much inside R
    below = rad[(rad > 55.0) & (rad < 60.0 - sag - 1e-6)]
    assert len(below) > 50
    depth = 60.0 - below
    assert depth.max() <= DEPTH + sag + 0.02  # not much more
    # floors: faces looking outward below the surface; depth >= DEPTH everywhere on them
    Cf = V2[F2].mean(axis=1)
    n = np.cross(V2[F2[:, 1]] - V2[F2[:, 0]], V2[F2[:, 2]] - V2[F2[:, 0]])
    n /= np.linalg.norm(n, axis=1)[:, None]
    radial = Cf * [1, 1, 0] / np.hypot(Cf[:, 0], Cf[:, 1])[:, None]
    floor = (np.einsum("ij,ij->i", n, radial) > 0.9) & (np.hypot(Cf[:, 0], Cf[:, 1]) < 59.9)
    assert floor.sum() > 10 and np.all(s2[floor] == SIDE_OUTER)
    fv = np.unique(F2[floor])
    d_floor = 60.0 * np.cos(np.pi / 256) - np.hypot(V2[fv, 0], V2[fv, 1])  # below the facets' inner reach
    assert d_floor.min() >= DEPTH - 0.01 and (60.0 - np.hypot(V2[fv, 0], V2[fv, 1])).max() <= DEPTH + 0.02


def test_sphere_shell_depth_at_least_depth():
    V, F, side = sphere_shell()
    h = 6.0
    V2, F2, s2, note = engrave_text(V, F, side, LO, height_mm=h)
    assert note is None
    rep = closed_report(V2, F2)
    assert rep["closed"] and rep["components"] == 1
    assert volume(V, F) - volume(V2, F2) == pytest.approx(AREA_LO * h * h * DEPTH, rel=0.10)
    # rays from outside towards the centre through the letters' floors: the floor is >= DEPTH
    # below the (faceted) sphere and not much more
    Cf = V2[F2].mean(axis=1)
    rc = np.linalg.norm(Cf, axis=1)
    floor = (rc > 58.0) & (rc < 59.7)
    n = np.cross(V2[F2[:, 1]] - V2[F2[:, 0]], V2[F2[:, 2]] - V2[F2[:, 0]])
    floor &= np.einsum("ij,ij->i", n / np.linalg.norm(n, axis=1)[:, None], Cf / rc[:, None]) > 0.9
    assert floor.sum() > 10
    orig = m3.Manifold(m3.Mesh64(vert_properties=np.array(V), tri_verts=np.array(F, dtype=np.uint64)))
    new = m3.Manifold(m3.Mesh64(vert_properties=np.array(V2), tri_verts=np.array(F2, dtype=np.uint64)))
    for c in Cf[floor][:: max(1, floor.sum() // 25)]:
        d = c / np.linalg.norm(c)
        a, b = tuple(d * 70.0), tuple(d * 55.0)
        top = np.linalg.norm(orig.ray_cast(a, b)[0].position)
        bottom = np.linalg.norm(new.ray_cast(a, b)[0].position)
        assert DEPTH - 0.01 <= top - bottom <= DEPTH + 0.05


def test_too_small_face_gives_a_note_and_the_solid_unchanged():
    V, F, side = slab((12.0, 10.0, 8.0), n=4)
    V2, F2, s2, note = engrave_text(V, F, side, LO, height_mm=6.0)
    assert note is not None and "not engraved" in note and "mm" in note
    assert V2 is V and F2 is F and s2 is side


def test_thin_wall_is_refused_with_its_figure():
    V, F, side = slab((60.0, 40.0, 1.0))
    V2, F2, s2, note = engrave_text(V, F, side, LO, height_mm=6.0)
    assert note is not None and "wall" in note and "1.00 mm" in note and "1.20 mm" in note
    assert V2 is V


def test_at_places_near_the_point():
    V, F, side = slab((100.0, 40.0, 8.0))
    V2, F2, s2, note = engrave_text(V, F, side, LO, height_mm=6.0, at=(80.0, 20.0, 8.0), up=(0, 1, 0))
    assert note is None
    C = V2[F2].mean(axis=1)
    floor = C[np.abs(C[:, 2] - (8 - DEPTH)) < 1e-6]
    assert floor[:, 0].mean() == pytest.approx(80.0, abs=4.0)


def test_labels_and_markers_on_parts():
    """Two parts side by side along x (left = +x): part 1 holds the patient's left end."""
    Va, Fa, sa = slab((70.0, 40.0, 8.0))
    Vb, Fb, sb = slab((70.0, 40.0, 8.0), offset=(75.0, 0.0, 0.0))
    sa[(Va[Fa].mean(axis=1)[:, 0] > 70 - 1e-6)] = SIDE_CUT
    sb[(Vb[Fb].mean(axis=1)[:, 0] < 75 + 1e-6)] = SIDE_CUT
    V = np.r_[Va, Vb]
    F = np.r_[Fa, Fb + len(Va)]
    side = np.r_[sa, sb]
    parts = np.r_[np.zeros(len(Fa), int), np.ones(len(Fb), int)]
    outlines = {"P 0": LO, "P 1": text(GLYPH_O, GLYPH_O), "L": TextOutline(GLYPH_L, 0.7), "R": text(GLYPH_O)}
    seen = []
    V2, F2, s2, lab2, warnings = engrave_labels(V, F, side, outlines, "P", (1.0, 0.0, 0.0), part_labels=parts,
                                                return_labels=True, progress=lambda f, t: seen.append(f))
    assert warnings == []
    assert seen == sorted(seen) and seen[0] == 0.0 and seen[-1] == 1.0
    h = LABEL_HEIGHTS[0]
    for i, area in ((0, AREA_LO + AREA_O), (1, 2 * AREA_O + AREA_L)):  # part 0: "P 0" + "R"; part 1: "P 1" + "L"
        Fi = F2[lab2 == i]
        rep = closed_report(V2, Fi)
        assert rep["closed"] and rep["components"] == 1
        removed = volume(V, F[parts == i]) - volume(V2, Fi)
        assert removed == pytest.approx(area * h * h * DEPTH, rel=0.10)
    # "L" sits at the +x end of part 1 (its floor right of the label's)
    C = V2[F2].mean(axis=1)
    floor1 = C[(lab2 == 1) & (np.abs(C[:, 2] - (8 - DEPTH)) < 1e-6)]
    assert floor1[:, 0].max() > 75 + 70 - 15
    # the 4-tuple call of the contract
    out = engrave_labels(V, F, side, outlines, "P", (1.0, 0.0, 0.0), part_labels=parts)
    assert len(out) == 4 and len(out[1]) == len(F2)


def test_labels_without_parts_and_empty_label():
    V, F, side = slab((90.0, 50.0, 8.0))
    outlines = {"AB": LO, "L": TextOutline(GLYPH_L, 0.7), "R": text(GLYPH_O)}
    V2, F2, s2, warnings = engrave_labels(V, F, side, outlines, "AB", (-1.0, 0.0, 0.0))
    assert warnings == [] and closed_report(V2, F2)["closed"]
    h = LABEL_HEIGHTS[0]
    assert volume(V, F) - volume(V2, F2) == pytest.approx((AREA_LO + AREA_L + AREA_O) * h * h * DEPTH, rel=0.10)
    # left = -x: the "L" marker (the only floor with an L's area near x = 0) sits at the -x end
    C = V2[F2].mean(axis=1)
    floor = C[np.abs(C[:, 2] - (8 - DEPTH)) < 1e-6]
    assert floor[:, 0].min() < 15.0 and floor[:, 0].max() > 75.0
    out = engrave_labels(V, F, side, outlines, "", (1.0, 0.0, 0.0))
    assert out[0] is V and out[3] == []
    with pytest.raises(BolusError, match="no text outline"):
        engrave_labels(V, F, side, {"AB": LO}, "AB", (1.0, 0.0, 0.0))


def test_labels_that_do_not_fit_are_reported():
    V, F, side = slab((14.0, 12.0, 8.0), n=4)
    wide = text(*([GLYPH_O] * 8))
    V2, F2, s2, warnings = engrave_labels(V, F, side, {"X": wide, "L": TextOutline(GLYPH_L, 0.7), "R": text(GLYPH_O)},
                                          "X", (1.0, 0.0, 0.0))
    assert any("'X' not engraved" in w for w in warnings)


def test_bad_arguments():
    V, F, side = slab()
    with pytest.raises(BolusError, match="side classes"):
        engrave_text(V, F, side[:-1], LO)
    with pytest.raises(BolusError, match="up"):
        engrave_text(V, F, side, LO, up=(0, 0, 0))
    with pytest.raises(BolusError, match="at must be"):
        engrave_text(V, F, side, LO, at=(np.inf, 0, 0))
    with pytest.raises(BolusError, match="positive"):
        engrave_text(V, F, side, LO, depth_mm=0.0)
    with pytest.raises(BolusError, match="outline"):
        engrave_text(V, F, side, TextOutline([], 0.0))
    with pytest.raises(BolusError, match="left"):
        engrave_labels(V, F, side, {"A": LO, "L": LO, "R": LO}, "A", (np.nan, 0, 0))
    with pytest.raises(BolusError, match="not a closed solid"):
        engrave_text(V, F[:-1], side[:-1], LO)


# ---------------------------------------------------------------- degenerate input

BOX = box((60.0, 40.0, 8.0), n=6)
CASES = degenerate_variants(*BOX)
#: every variant adds a triangle to (or breaks a vertex of) a closed box: what the refusal says
REFUSAL = {"coincident": "not a closed solid", "collinear": "not a closed solid", "needle": "not a closed solid",
           "nonmanifold": "non-manifold", "nan": "vertex", "inf": "vertex"}


@pytest.mark.parametrize("name", sorted(CASES))
def test_degenerate_input(name):
    V, F, _ = CASES[name]
    C = np.nan_to_num(V[F].mean(axis=1), nan=0.0, posinf=0.0)
    side = np.where(C[:, 2] > 8 - 1e-6, SIDE_OUTER, SIDE_RIM).astype(np.int8)
    with pytest.raises(BolusError, match=REFUSAL[name]):
        engrave_text(V, F, side, LO)
    with pytest.raises(BolusError, match=REFUSAL[name]):
        engrave_labels(V, F, side, {"A": LO, "L": LO, "R": LO}, "A", (1.0, 0.0, 0.0))


def test_zero_area_triangle_in_a_closed_solid_is_sound():
    """An edge split by a zero-area triangle (a T-junction closed by a sliver) is still a closed solid."""
    V, F, side = slab()
    top = np.nonzero(side == SIDE_RIM)[0][0]
    a, b, c = F[top]
    m = len(V)
    V = np.r_[V, [0.5 * (V[a] + V[b])]]
    F = np.r_[np.delete(F, top, axis=0), [[a, m, c], [m, b, c], [a, b, m]]]
    side = np.r_[np.delete(side, top), [SIDE_RIM] * 3].astype(np.int8)
    rep = closed_report(V, F)
    assert rep["closed"]
    V2, F2, s2, note = engrave_text(V, F, side, LO)
    assert note is None and closed_report(V2, F2)["closed"] and np.isfinite(V2).all()


@pytest.mark.parametrize("gap", [12.0, 3.0])
def test_overhang_does_not_split_the_letters(gap):
    """A roof ``gap`` mm over part of the top (a T-shaped solid): text asked at the roof's edge lands
    on one level only (the roof's top or the top below it), never half on each."""
    M = (m3.Manifold.cube((60.0, 40.0, 8.0)) + m3.Manifold.cube((10.0, 40.0, gap + 4)).translate((0.0, 0.0, 8.0))
         + m3.Manifold.cube((50.0, 40.0, 4.0)).translate((0.0, 0.0, 8.0 + gap)))
    V, F = from_manifold(M.refine_to_length(4.0))
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    nz = n[:, 2] / np.linalg.norm(n, axis=1)
    side = np.where(nz > 0.99, SIDE_OUTER, np.where(nz < -0.99, SIDE_INNER, SIDE_RIM)).astype(np.int8)
    notes = {}
    for at in ((50.0, 20.0, 8.0), (47.0, 20.0, 8.0), (53.0, 20.0, 8.0)):
        V2, F2, s2, notes[at] = engrave_text(V, F, side, LO, height_mm=6.0, at=at, up=(0, 1, 0))
        assert closed_report(V2, F2)["closed"]
        if notes[at] is None:
            Cf = V2[F2].mean(axis=1)
            up_faces = np.cross(V2[F2[:, 1]] - V2[F2[:, 0]], V2[F2[:, 2]] - V2[F2[:, 0]])[:, 2] > 0
            top = 8.0 + gap + 4.0
            levels = {z for z in (8 - DEPTH, top - DEPTH) if np.any(up_faces & (np.abs(Cf[:, 2] - z) < 1e-6))}
            assert len(levels) == 1
            assert volume(V, F) - volume(V2, F2) == pytest.approx(AREA_LO * 36 * DEPTH, rel=0.10)
    if gap > 10:  # a roof far above does not hide the top below it: engraved there (regression: the
        assert notes[(47.0, 20.0, 8.0)] is None  # letters were once bent up onto the roof, then refused)


def test_long_label_turns_along_a_narrow_strip():
    """A strip 18 mm wide across the reading direction: the label runs along the strip instead,
    still reading towards the patient's left (+x), i.e. its x axis has a positive x part."""
    V, F, side = slab((18.0, 120.0, 8.0), n=12)
    V = V @ np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    label = text(GLYPH_L, GLYPH_O, GLYPH_L, GLYPH_O)  # 4.5 caps wide: 27 mm at 6 mm, more than 18 mm
    outlines = {"X": label, "L": TextOutline(GLYPH_L, 0.7), "R": text(GLYPH_O)}
    V2, F2, s2, warnings = engrave_labels(V, F, side, outlines, "X", (1.0, 0.0, 0.0))
    assert not any("'X'" in w for w in warnings)
    C = V2[F2].mean(axis=1)
    floor = C[np.abs(C[:, 2] - (8 - DEPTH)) < 1e-6]
    # the label is the floor cluster near the middle of the strip (the markers sit at its ends)
    mid = floor[np.abs(floor[:, 1] - 60.0) < 20.0]
    assert np.ptp(mid[:, 1]) > 20.0 and np.ptp(mid[:, 0]) < 10.0
    removed = volume(V, F) - volume(V2, F2)
    assert removed >= 2 * (AREA_L + AREA_O) * LABEL_HEIGHTS[-1] ** 2 * DEPTH * 0.9


def test_no_outer_face_nothing_engraved():
    V, F, side = slab()
    side = np.full_like(side, SIDE_RIM)
    V2, F2, s2, warnings = engrave_labels(V, F, side, {"A": LO, "L": LO, "R": LO}, "A", (1.0, 0.0, 0.0))
    assert any("'A' not engraved" in w and "no spot on the outer face" in w for w in warnings)
    assert np.array_equal(V2, V) and np.array_equal(F2, F) and np.array_equal(s2, side)


def test_a_spoiling_text_is_left_out_and_the_others_kept(monkeypatch):
    """When the cut of one text comes out wrong (here: the "R" marker's solid replaced by a block
    through the whole slab), that text is reported and the others are still engraved."""
    import bolus_addon.core.solid.engrave as engrave  # noqa: PLC0415

    real = engrave._bent_prism

    def bent(surf, spot, text_, depth):
        if text_ is outlines["R"]:
            return m3.Manifold.cube((4.0, 4.0, 20.0)).translate(tuple(spot.p - [2.0, 2.0, 10.0])), 1.0
        return real(surf, spot, text_, depth)

    monkeypatch.setattr(engrave, "_bent_prism", bent)
    V, F, side = slab((90.0, 50.0, 8.0))
    outlines = {"AB": LO, "L": TextOutline(GLYPH_L, 0.7), "R": text(GLYPH_O)}
    V2, F2, s2, warnings = engrave_labels(V, F, side, outlines, "AB", (1.0, 0.0, 0.0))
    assert len(warnings) == 1 and warnings[0].startswith("'R' not engraved: the engraving came out wrong")
    assert closed_report(V2, F2)["genus"] == 0
    h = LABEL_HEIGHTS[0]
    assert volume(V, F) - volume(V2, F2) == pytest.approx((AREA_LO + AREA_L) * h * h * DEPTH, rel=0.10)
