"""Solid print parts with SVM common planes and connectors (core.solid_parts, core.connectors;
seed 6.3-6.4.3, eqs. 6-38..6-40).

Test solids are built with manifold3d directly: a thick hemispherical cap (sphere(70) -
sphere(60) above z = 0) on the skin of the inner sphere, and a strongly curved C-shaped
shell (340 degrees of a thick cylinder) where a joint plane crosses the shell twice."""
import numpy as np
import pytest

import manifold3d as m3

from bolus_addon.core.solid import connectors as conn
from bolus_addon.core.solid import parts as sp
from bolus_addon.core.errors import BolusError
from bolus_addon.core.printing.segmentation import print_segment
from bolus_addon.core.solid.manifold import (
    SIDE_CONNECTOR,
    SIDE_CUT,
    SIDE_INNER,
    SIDE_OUTER,
    SIDE_RIM,
    closed_report,
    from_manifold,
    to_manifold,
)
from bolus_addon.core.solid.parts import skin_neighbours, split_solid, svm_plane
from meshgen import cylinder_piece, degenerate_variants, ring_surface


# ----------------------------------------------------------------------------- test solids

def cap_solid(r_in=60.0, r_out=70.0, seg=96):
    """Thick hemispherical cap: V, F, side (inner / outer by the radius of the face centroid, rim at z = 0)."""
    S = (m3.Manifold.sphere(r_out, seg) - m3.Manifold.sphere(r_in, seg)).trim_by_plane((0, 0, 1), 0.0)
    V, F = from_manifold(S)
    r = np.linalg.norm(V[F].mean(axis=1), axis=1)
    side = np.where(r < 0.5 * (r_in + r_out), SIDE_INNER, SIDE_OUTER).astype(np.int8)
    side[np.all(np.abs(V[F][:, :, 2]) < 1e-9, axis=1)] = SIDE_RIM
    return V, F, side


def cap_skin(r=60.0, nr=30, na=96):
    """The inner cap surface (z >= 0) as a triangle mesh, normals pointing away from the centre."""
    t = np.linspace(0, np.pi / 2, nr, endpoint=False)
    V, F, _ = ring_surface(np.stack([r * np.cos(t), r * np.sin(t)], 1), na=na, pole=True)
    V[-1] = [0, 0, r]
    C = V[F].mean(axis=1)
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    if np.mean(np.einsum("ij,ij->i", N, C)) < 0:
        F = F[:, ::-1]
    return V, F


def sectors(V, F, k, phase=0.3):
    """Skin labels: k equal angular sectors around z."""
    C = V[F].mean(axis=1)
    a = (np.arctan2(C[:, 1], C[:, 0]) - phase) % (2 * np.pi)
    return np.minimum((a / (2 * np.pi / k)).astype(int), k - 1)


def c_shell(r_in=40.0, r_out=50.0, angle_deg=340.0, length=60.0, seg=180):
    """A thick cylindrical shell over ``angle_deg`` around z (a C): V, F, side."""
    tube = (m3.Manifold.cylinder(length, r_out, circular_segments=seg)
            - m3.Manifold.cylinder(length + 20, r_in, circular_segments=seg).translate((0, 0, -10)))
    t = np.linspace(0, np.radians(angle_deg), 64)
    R = 3 * r_out
    wedge = m3.CrossSection([np.r_[[[0.0, 0.0]], np.stack([R * np.cos(t), R * np.sin(t)], 1)]])
    V, F = from_manifold(tube ^ wedge.extrude(length + 20).translate((0, 0, -10)))
    C = V[F].mean(axis=1)
    r = np.linalg.norm(C[:, :2], axis=1)
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    N /= np.linalg.norm(N, axis=1)[:, None]
    radial = np.abs(np.einsum("ij,ij->i", N[:, :2], C[:, :2] / r[:, None])) > 0.9
    side = np.full(len(F), SIDE_RIM, np.int8)
    side[radial & (r < 0.5 * (r_in + r_out))] = SIDE_INNER
    side[radial & (r > 0.5 * (r_in + r_out))] = SIDE_OUTER
    return V, F, side


def c_skin(r=40.0, angle_deg=340.0, length=60.0):
    V, F = cylinder_piece(radius=r, angle=np.radians(angle_deg), length=length, na=170, nl=30)
    C = V[F].mean(axis=1)
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    if np.mean(np.einsum("ij,ij->i", N[:, :2], C[:, :2])) < 0:
        F = F[:, ::-1]
    return V, F


def angle_labels(V, F, cuts_deg):
    a = np.degrees(np.arctan2(*V[F].mean(axis=1)[:, [1, 0]].T)) % 360
    return np.searchsorted(np.asarray(cuts_deg), a)


CAP = cap_solid()
SKIN = cap_skin()


@pytest.fixture(scope="module")
def two():
    return split_solid(*CAP, *SKIN, sectors(*SKIN, 2))


@pytest.fixture(scope="module")
def three():
    return split_solid(*CAP, *SKIN, sectors(*SKIN, 3))


def connector_volume_change(res, q):
    """What the connectors add to part q: its pegs' protruding length minus its holes."""
    dv = 0.0
    for J in res.joints:
        for c in J.connectors:
            if c.parts[0] == q:
                dv += conn.polygon_area(c.peg_radius) * c.peg_length
            if c.parts[1] == q:
                dv -= conn.polygon_area(c.hole_radius) * c.hole_depth
    return dv


def assert_closed_parts(res, k):
    assert res.part_count == k
    assert set(np.unique(res.labels)) == set(range(k))
    for q in range(k):
        V, F = res.part(q)
        rep = closed_report(V, F)
        assert rep["closed"], (q, rep)  # every edge two faces, running in opposite directions
        assert rep["components"] == 1, (q, rep)
        assert rep["volume_mm3"] == pytest.approx(res.volumes_mm3[q], rel=1e-9)
        assert to_manifold(V, F).status() == m3.Error.NoError


def main_joints(res):
    return [J for J in res.joints if not (J.note or "").startswith("a second")]


# ----------------------------------------------------------------------------- planes

def test_svm_plane_is_the_maximum_margin_plane():
    g = np.random.default_rng(3)
    X0 = np.c_[g.uniform(-6, -1, 120), g.uniform(-20, 20, (120, 2))]
    X1 = np.c_[g.uniform(3, 9, 80), g.uniform(-20, 20, (80, 2))]
    corners = np.array([[20, 20], [20, -20], [-20, 20], [-20, -20]], dtype=float)
    X0[:4] = np.c_[np.full(4, -1.0), corners]  # the closest faces of the two hulls face each other:
    X1[:4] = np.c_[np.full(4, 3.0), corners]  # the hard-margin plane is x = 1 (eq. 6-38)
    n, off, wrong = svm_plane(X0 + 100.0, X1 + 100.0)  # far from the origin: the intercept is not biased
    assert wrong == 0.0
    assert n @ [1, 0, 0] > np.cos(np.radians(1.0))
    assert -off / n[0] == pytest.approx(101.0, abs=0.05)
    # the dual of eq. 6-39 (libsvm) finds the same plane
    from sklearn.svm import SVC
    svc = SVC(kernel="linear", C=1e6).fit(np.vstack([X0, X1]) + 100.0, np.r_[-np.ones(120), np.ones(80)])
    w = svc.coef_.ravel()
    assert n @ (w / np.linalg.norm(w)) > np.cos(np.radians(1.0))
    assert -svc.intercept_[0] / w[0] == pytest.approx(-off / n[0], abs=0.05)


def test_svm_plane_refuses_an_empty_side():
    with pytest.raises(BolusError, match="both parts"):
        svm_plane(np.zeros((0, 3)), np.ones((4, 3)))


def test_skin_neighbours():
    lab = sectors(*SKIN, 3)
    pairs = skin_neighbours(SKIN[1], lab)
    assert [(i, j) for i, j, _ in pairs] == [(0, 1), (0, 2), (1, 2)]
    assert all(n > 0 for _, _, n in pairs)


def test_connector_sizes():
    r, L, need = conn.connector_size(10.0, 0.2)
    assert (r, L, need) == pytest.approx((2.0, 6.0, 7.4))  # 40 % of 10 mm, 1.5 x diameter, 2 (r + c + 1.5)
    r, L, need = conn.connector_size(4.0, 0.2)
    assert (r, L, need) == pytest.approx((1.0, 3.0, 5.4))  # the 2 mm minimum peg


def test_fit_in_wall_centres_the_hole_in_the_wall():
    n = np.array([1.0, 0, 0])
    s = np.array([0, 0, 1.0])  # the wall is 0 <= z <= 10, the plane x = 0 meets it square
    shift, L, u = conn.fit_in_wall(n, n, s, 1.0, 10.0, 2.0, 0.2, 6.0)
    assert L == 6.0 and u @ s == pytest.approx(1.0) and 1.0 + shift == pytest.approx(5.0)
    # an oblique plane: the hole drifts across the wall; the fit keeps hole + walls inside
    n2 = np.array([np.cos(0.5), 0, np.sin(0.5)])
    shift, L, u = conn.fit_in_wall(n2, n2, s, 5.0, 10.0, 2.0, 0.2, 6.0)
    h = 5.0 + shift * (u @ s)
    D = L + 0.2 + conn.WALL_MIN
    rho = 2.0 + 0.2 + conn.WALL_MIN
    sn = np.sqrt(1 - (n2 @ s) ** 2)
    assert h - rho * sn >= 0 and h + D * (n2 @ s) + rho * sn <= 10.0
    assert conn.fit_in_wall(n2, n2, s, 5.0, 5.0, 2.0, 0.2, 6.0) is None  # too thin


# ----------------------------------------------------------------------------- parts

def test_two_parts_are_closed_and_add_up(two):
    res = two
    assert_closed_parts(res, 2)
    solid = closed_report(*CAP[:2])["volume_mm3"]
    assert res.solid_volume_mm3 == pytest.approx(solid, rel=1e-9)
    assert res.plain_volumes_mm3.sum() == pytest.approx(solid, rel=1e-9)  # cutting keeps volume exactly
    assert res.plain_volumes_mm3.sum() == pytest.approx(solid, rel=5e-3)
    for q in range(2):  # the connectors add and remove a known volume
        assert res.volumes_mm3[q] - res.plain_volumes_mm3[q] == pytest.approx(connector_volume_change(res, q),
                                                                              abs=1e-6 * solid)
    assert res.warnings == []


def area_by_side(V, F, side, s):
    F = F[side == s]
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()


def test_two_parts_faces_keep_their_side(two):
    res = two
    V, F, side = CAP
    for s in (SIDE_INNER, SIDE_OUTER):  # the cut and the connectors leave the skin side and the outer face whole
        assert area_by_side(res.V, res.F, res.side, s) == pytest.approx(area_by_side(V, F, side, s), rel=1e-6)
    (J,) = res.joints
    cut = res.F[res.side == SIDE_CUT]
    d = res.V[cut] @ J.normal + J.offset
    assert np.abs(d).max() < 1e-6  # cut faces lie on the joint plane
    assert (res.side == SIDE_CONNECTOR).sum() > 0
    # rim faces: only those of the solid (at z = 0)
    assert np.abs(res.V[res.F[res.side == SIDE_RIM]][:, :, 2]).max() < 1e-6


def test_joint_plane_separates_the_parts(two):
    res = two
    (J,) = res.joints
    assert J.parts == (0, 1) and np.linalg.norm(J.normal) == pytest.approx(1.0)
    for q, sgn in ((0, -1), (1, 1)):
        V, F = res.part(q)
        V = V[np.isin(np.arange(len(V)), F[res.side[res.labels == q] != SIDE_CONNECTOR])]
        assert np.all(sgn * (V @ J.normal + J.offset) >= -1e-6)
    assert J.thickness_mm == pytest.approx(10.0, abs=0.2)
    assert J.area_mm2 == pytest.approx(0.5 * np.pi * (70**2 - 60**2), rel=0.02)  # a half annulus


def _slice_across(M, centre, axis, z):
    """Polygons (list of (k,2)) of M cut square to ``axis`` at ``z`` mm from ``centre``,
    in a frame with the axis point at the origin."""
    _, U = conn.plane_frame(axis, 0.0)
    R = np.stack([U[0], U[1], axis])  # rows: the local frame
    T = np.column_stack([R, -R @ centre])
    return M.transform(T.tolist()).slice(z).to_polygons()


def _ring_radius(polys, tol=0.6):
    """Circumradius of the regular polygon centred on the origin (a peg's or a hole's section:
    its corners, plus where the slice crosses the side's triangle diagonals), or None."""
    for P in polys:
        d = np.linalg.norm(P, axis=1)
        regular = d.min() >= d.max() * np.cos(np.pi / conn.SEGMENTS) - 1e-6
        if np.linalg.norm(P.mean(axis=0)) < tol and len(P) >= conn.SEGMENTS and regular:
            return float(d.max())
    return None


def test_each_peg_matches_its_hole(two):
    res = two
    (J,) = res.joints
    assert len(J.connectors) == 2 and J.note is None
    # one peg and one hole on each part (seed: "one is convex and the other is concave")
    assert sorted(c.parts for c in J.connectors) == [(0, 1), (1, 0)]
    for c in J.connectors:
        assert c.hole_radius == pytest.approx(c.peg_radius + 0.2)
        assert c.hole_depth == pytest.approx(c.peg_length + 0.2)
        assert c.peg_radius == pytest.approx(0.2 * J.thickness_mm, rel=1e-6)  # 40 % of the wall
        assert abs(c.centre @ J.normal + J.offset) < 1e-6
        peg_part = to_manifold(*res.part(c.parts[0]))
        hole_part = to_manifold(*res.part(c.parts[1]))
        mid = 0.5 * c.peg_length
        assert _ring_radius(_slice_across(peg_part, c.centre, c.axis, mid)) == pytest.approx(c.peg_radius, rel=1e-6)
        assert _ring_radius(_slice_across(hole_part, c.centre, c.axis, mid)) == pytest.approx(c.hole_radius, rel=1e-6)
        # the peg ends at its length, the hole at its depth
        assert _ring_radius(_slice_across(peg_part, c.centre, c.axis, c.peg_length - 0.05)) is not None
        assert _ring_radius(_slice_across(peg_part, c.centre, c.axis, c.peg_length + 0.05)) is None
        assert _ring_radius(_slice_across(hole_part, c.centre, c.axis, c.hole_depth - 0.05)) is not None
        assert _ring_radius(_slice_across(hole_part, c.centre, c.axis, c.hole_depth + 0.05)) is None
        # the peg fits its hole: nothing of the peg part inside the other part
        assert (peg_part ^ hole_part).volume() < 1e-6


def test_connectors_near_the_two_ends(two):
    (J,) = two.joints
    a, b = (c.centre for c in J.connectors)
    assert np.linalg.norm(a - b) > 100.0  # the joint runs rim - pole - rim, 2 x 94 mm along the shell
    for c in J.connectors:
        assert c.centre[2] < 20.0  # near the rim, not at the pole


def test_three_parts(three):
    res = three
    assert_closed_parts(res, 3)
    assert res.plain_volumes_mm3.sum() == pytest.approx(res.solid_volume_mm3, rel=1e-9)
    pairs = sorted({J.parts for J in main_joints(res)})
    assert pairs == [(0, 1), (0, 2), (1, 2)]
    for J in main_joints(res):
        assert len(J.connectors) >= 1
    for q in range(3):
        assert res.volumes_mm3[q] - res.plain_volumes_mm3[q] == pytest.approx(connector_volume_change(res, q),
                                                                              abs=1e-6 * res.solid_volume_mm3)


def test_parts_from_print_segmentation():
    lab = print_segment(*SKIN, 3)
    res = split_solid(*CAP, *SKIN, lab)
    assert_closed_parts(res, 3)
    assert res.plain_volumes_mm3.sum() == pytest.approx(res.solid_volume_mm3, rel=5e-3)
    assert sum(len(J.connectors) for J in res.joints) >= 4
    for J in res.joints:  # planes from the SVM are oblique on the dome: connectors stay inside the wall anyway
        for c in J.connectors:
            assert c.axis @ (J.normal if c.parts[0] == J.parts[0] else -J.normal) >= np.cos(np.radians(60))


def test_a_too_thin_joint_stays_plain():
    V, F, side = cap_solid(60.0, 64.0)  # a 4 mm wall: a 2 mm peg with walls needs 5.4 mm
    res = split_solid(V, F, side, *SKIN, sectors(*SKIN, 2))
    assert_closed_parts(res, 2)
    (J,) = res.joints
    assert J.connectors == [] and J.note.startswith("too thin")
    assert "4.0 mm" in J.note and "5.4 mm" in J.note
    assert any(w.startswith("joint between parts 0 and 1 left plain") for w in res.warnings)
    np.testing.assert_allclose(res.volumes_mm3, res.plain_volumes_mm3)
    assert (res.side == SIDE_CONNECTOR).sum() == 0


def test_three_parts_on_the_c_shell_with_two_planes_crossing_twice():
    V, F, side = c_shell()
    sV, sF = c_skin()
    res = split_solid(V, F, side, sV, sF, angle_labels(sV, sF, [120.0, 230.0]))
    assert_closed_parts(res, 3)
    assert res.plain_volumes_mm3.sum() == pytest.approx(res.solid_volume_mm3, rel=1e-9)
    np.testing.assert_allclose(res.plain_volumes_mm3 / res.solid_volume_mm3, np.array([120, 110, 110]) / 340,
                               atol=0.02)
    assert sorted(J.parts for J in main_joints(res)) == [(0, 1), (1, 2)]
    assert all(len(J.connectors) == 2 for J in main_joints(res))


def test_plane_crossing_the_shell_twice_still_gives_connected_parts():
    V, F, side = c_shell()
    sV, sF = c_skin()
    lab = angle_labels(sV, sF, [100.0])
    res = split_solid(V, F, side, sV, sF, lab)
    # the premise: the joint plane (through the axis at 100 degrees) also crosses the C at 280 degrees
    M = to_manifold(V, F)
    n, off = res.planes[0, :3], res.planes[0, 3]
    assert sum(len(p.decompose()) for p in M.split_by_plane(tuple(n), -off)) == 3
    assert_closed_parts(res, 2)
    assert res.plain_volumes_mm3.sum() == pytest.approx(res.solid_volume_mm3, rel=1e-9)
    assert len(res.planes) == 2 and any("extra cutting plane" in w for w in res.warnings)
    # part 1 (100..340 degrees) is the larger: 240 of 340 degrees
    assert res.plain_volumes_mm3[1] / res.solid_volume_mm3 == pytest.approx(240 / 340, abs=0.02)
    (J,) = main_joints(res)
    assert J.parts == (0, 1) and len(J.connectors) == 2


def test_plane_crossing_twice_without_extra_planes_warns(monkeypatch):
    monkeypatch.setattr(sp, "MAX_EXTRA_PLANES", 0)
    V, F, side = c_shell()
    sV, sF = c_skin()
    res = split_solid(V, F, side, sV, sF, angle_labels(sV, sF, [100.0]), connectors=False)
    assert res.plain_volumes_mm3.sum() == pytest.approx(res.solid_volume_mm3, rel=1e-9)
    assert any("goes with part" in w for w in res.warnings)
    assert any("falls into 2 pieces" in w for w in res.warnings)


def test_without_connectors_and_one_part():
    res = split_solid(*CAP, *SKIN, sectors(*SKIN, 2), connectors=False)
    np.testing.assert_allclose(res.volumes_mm3, res.plain_volumes_mm3)
    assert all(J.connectors == [] and J.note == "connectors not asked for" for J in res.joints)
    one = split_solid(*CAP, *SKIN, np.zeros(len(SKIN[1]), int))
    assert one.joints == [] and one.part_count == 1
    assert one.volumes_mm3[0] == pytest.approx(one.solid_volume_mm3, rel=1e-12)
    np.testing.assert_array_equal(np.sort(one.side), np.sort(CAP[2]))


def test_progress_reports_in_order():
    seen = []
    split_solid(*CAP, *SKIN, sectors(*SKIN, 2), connectors=False, progress=lambda f, t: seen.append(f))
    assert seen[0] == 0.0 and seen[-1] == 1.0 and seen == sorted(seen)


# ----------------------------------------------------------------------------- bad input

def test_open_or_broken_solid_is_refused():
    V, F, side = CAP
    with pytest.raises(BolusError, match="not a closed solid"):
        split_solid(V, F[1:], side[1:], *SKIN, sectors(*SKIN, 2))
    Vn = V.copy()
    Vn[F[5, 1], 2] = np.nan
    with pytest.raises(BolusError, match=f"vertex {F[5, 1]}"):
        split_solid(Vn, F, side, *SKIN, sectors(*SKIN, 2))
    with pytest.raises(BolusError, match="one per triangle"):
        split_solid(V, F, side[1:], *SKIN, sectors(*SKIN, 2))


@pytest.mark.parametrize("labels, says", [
    (lambda lab: lab[1:], "one per skin triangle"),
    (lambda lab: lab - 1, "0 or more"),
    (lambda lab: lab * 2, "skip part"),
    (lambda lab: lab + 0.5, "whole numbers"),
])
def test_bad_labels_are_refused(labels, says):
    with pytest.raises(BolusError, match=says):
        split_solid(*CAP, *SKIN, labels(sectors(*SKIN, 2)))


def test_bad_clearance_is_refused():
    with pytest.raises(BolusError, match="clearance"):
        split_solid(*CAP, *SKIN, sectors(*SKIN, 2), clearance=-0.1)


def _interior_first(V, F):
    """The skin with an interior triangle first (degenerate_variants breaks triangle 0)."""
    i = len(F) // 2
    order = np.r_[i, np.delete(np.arange(len(F)), i)]
    return V, F[order], order


@pytest.mark.parametrize("name", sorted(degenerate_variants(*cap_skin(nr=8, na=24)).keys()))
def test_degenerate_skin(name):
    V0, F0, order = _interior_first(*SKIN)
    lab0 = sectors(*SKIN, 2)[order]
    V, F, says = degenerate_variants(V0, F0)[name]
    lab = np.r_[lab0, np.full(len(F) - len(F0), lab0[0])]
    if says in (None, "zero-area", "non-manifold"):  # the skin only guides the cut: sound
        res = split_solid(*CAP, V, F, lab, connectors=False)
        assert_closed_parts(res, 2)
        assert res.plain_volumes_mm3.sum() == pytest.approx(res.solid_volume_mm3, rel=1e-9)
        return
    with pytest.raises(BolusError, match=says):
        split_solid(*CAP, V, F, lab)


@pytest.mark.parametrize("name", ["coincident", "collinear", "needle", "nonmanifold"])
def test_degenerate_solid_is_refused_as_not_closed(name):
    V, F, side = CAP
    i = int(np.argmax(side == SIDE_OUTER))
    order = np.r_[i, np.delete(np.arange(len(F)), i)]
    V2, F2, _ = degenerate_variants(V, F[order])[name]
    side2 = np.r_[side[order], np.full(len(F2) - len(F), SIDE_OUTER)]
    with pytest.raises(BolusError, match="not a closed solid"):
        split_solid(V2, F2, side2, *SKIN, sectors(*SKIN, 2))


def test_a_crumb_of_the_solid_is_left_out_with_a_warning():
    V, F, side = CAP
    cV, cF = from_manifold(m3.Manifold.cube((0.5, 0.5, 0.5)).translate((0.0, 0.0, 80.0)))
    V2, F2 = np.vstack([V, cV]), np.vstack([F, cF + len(V)])
    side2 = np.r_[side, np.full(len(cF), SIDE_OUTER)]
    res = split_solid(V2, F2, side2, *SKIN, sectors(*SKIN, 2), connectors=False)
    assert any("1 separate crumb" in w and "0.125 mm³" in w for w in res.warnings)
    assert_closed_parts(res, 2)
    assert res.solid_volume_mm3 == pytest.approx(closed_report(V, F)["volume_mm3"] + 0.125, rel=1e-9)
    assert res.plain_volumes_mm3.sum() == pytest.approx(res.solid_volume_mm3 - 0.125, rel=1e-9)
    assert area_by_side(res.V, res.F, res.side, SIDE_INNER) == pytest.approx(area_by_side(V, F, side, SIDE_INNER),
                                                                            rel=1e-6)  # the faces keep their side


def test_cells_cut_off_from_their_part_join_the_part_they_touch():
    # cells 0-1-2 in a row, 3 touches only 2: voted to part 0 (the skin under its outer face), it goes to part 1
    owners = sp._connected_owners([0, 0, 1, 0], [10.0, 10.0, 10.0, 0.5], {(0, 1): 5.0, (1, 2): 5.0, (2, 3): 1.0})
    assert owners == [0, 0, 1, 1]
    # a group with no neighbour stays where the skin put it
    assert sp._connected_owners([0, 1, 0], [10.0, 10.0, 1.0], {(0, 1): 5.0}) == [0, 1, 0]


# ----------------------------------------------------------------------------- connector helpers

def test_sections_and_inscribed_circle():
    T = np.array([[[0, 0], [100, 0], [100, 10]], [[0, 0], [0, 10], [100, 10]],  # one counter-clockwise, one not
                  [[5, 5], [5, 5], [6, 5]]], dtype=float)  # zero area: dropped
    cs = conn.section_of_triangles(T)
    assert cs.area() == pytest.approx(1000.0)
    assert conn.inscribed_radius(cs) == pytest.approx(5.0, abs=0.03)
    assert conn.section_of_triangles(np.zeros((0, 3, 2))).is_empty()
    assert conn.inscribed_radius(m3.CrossSection()) == 0.0


def test_place_centres_near_the_two_ends():
    strip = m3.CrossSection([np.array([[0, 0], [100, 0], [100, 10], [0, 10]], dtype=float)])
    r, c = 2.0, 0.2
    cands = conn.place_centres(strip, r, c)
    assert len(cands) == 2
    need = r + c + conn.WALL_MIN
    a, b = sorted((cand[0] for cand in cands), key=lambda p: p[0])
    assert need <= a[0] < need + 1.0 and 100 - need - 1.0 < b[0] <= 100 - need  # close to the ends
    for p in (a, b):
        assert need - 1e-6 <= p[1] <= 10 - need + 1e-6
    short = m3.CrossSection([np.array([[0, 0], [12, 0], [12, 10], [0, 10]], dtype=float)])
    assert len(conn.place_centres(short, r, c)) == 1  # too short for two holes and a wall between
    narrow = m3.CrossSection([np.array([[0, 0], [100, 0], [100, 7], [0, 7]], dtype=float)])
    assert conn.place_centres(narrow, r, c) == []  # 7 mm < 2 (2 + 0.2 + 1.5)


def test_cylinder_geometry():
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    C = conn.cylinder([1.0, 2.0, 3.0], axis, 2.5, -1.0, 4.0)
    assert C.volume() == pytest.approx(conn.polygon_area(2.5) * 5.0, rel=1e-9)
    V, _ = from_manifold(C)
    s = (V - [1.0, 2.0, 3.0]) @ axis
    assert s.min() == pytest.approx(-1.0) and s.max() == pytest.approx(4.0)
    radial = np.linalg.norm((V - [1.0, 2.0, 3.0]) - np.outer(s, axis), axis=1)
    np.testing.assert_allclose(radial, 2.5, rtol=1e-9)


def test_a_twisted_border_warns_that_the_plane_cannot_follow_it():
    V, F = SKIN
    C = V[F].mean(axis=1)
    twisted = ((np.arctan2(C[:, 1], C[:, 0]) + np.pi * C[:, 2] / 60.0) % (2 * np.pi) < np.pi).astype(int)
    res = split_solid(*CAP, V, F, twisted, connectors=False)
    assert any(w.startswith("the joint plane between parts 0 and 1 leaves") and "far from straight" in w
               for w in res.warnings)
    assert_closed_parts(res, 2)  # still two closed parts, split by the best plane
    straight = split_solid(*CAP, V, F, sectors(V, F, 2), connectors=False)
    assert not any("far from straight" in w for w in straight.warnings)
