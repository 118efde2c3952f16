"""Mid-surface of a thick sheet, region size check and sheet-or-print advice."""
import numpy as np
import pytest

from bolus_addon.core.errors import BolusError
from bolus_addon.core.unfold.mid_surface import (
    CLAMP_FRACTION,
    MIN_AREA_RATIO,
    SHEET_RADIUS_FACTOR,
    check_sheet_thickness,
    folded_triangles,
    mid_surface,
    piece_bending,
    principal_curvatures,
    region_width,
)
from bolus_addon.core.unfold.piece_advice import DEFAULT_WARN_FRACTION
from bolus_addon.core.mesh.topology import MeshTopology
from bolus_addon.core.unfold.unfold import unfold_patch
from meshgen import cylinder_piece, degenerate_variants, grid, height_field, icosphere, ring_surface
from meshgen import spherical_cap


def tube(R=30.0, length=60.0, na=128, nl=8):
    """Closed tube (open ends) around z, outward normals; ring (n,) the ring of each vertex."""
    prof = np.stack([np.full(nl + 1, R), np.linspace(0.0, length, nl + 1)], 1)
    V, F, ring = ring_surface(prof, na=na, pole=False)
    topo = MeshTopology(V, F)
    assert np.einsum("ij,ij->i", topo.face_normals, topo.centroids * [1, 1, 0]).min() > 0  # outward
    return V, F, ring


def signed_area_ratio(V0, V1, F):
    c0 = np.cross(V0[F[:, 1]] - V0[F[:, 0]], V0[F[:, 2]] - V0[F[:, 0]])
    c1 = np.cross(V1[F[:, 1]] - V1[F[:, 0]], V1[F[:, 2]] - V1[F[:, 0]])
    return np.einsum("ij,ij->i", c0, c1) / np.einsum("ij,ij->i", c0, c0)


def ring_width(u, ring, k):
    """Length in the pattern of the vertex ring k of a tube: its edges' lengths summed."""
    on = ring[u.vert_origin] == k
    E = np.unique(np.sort(np.concatenate([u.F[:, [0, 1]], u.F[:, [1, 2]], u.F[:, [2, 0]]]), axis=1), axis=0)
    E = E[on[E[:, 0]] & on[E[:, 1]]]
    return float(np.linalg.norm(u.UV[E[:, 0]] - u.UV[E[:, 1]], axis=1).sum()), len(E)


# ------------------------------------------------------------------------------------- mid_surface


@pytest.mark.parametrize("t", [0.0, 10.0])
def test_cylinder_mid_surface_pattern_has_width_2pi_r_plus_half_t(t):
    """The pattern of the mid-surface of a tube of radius R is 2 pi (R + t/2) wide."""
    R, na = 30.0, 128
    V, F, ring = tube(R, na=na)
    ms = mid_surface(V, F, t)
    assert not ms.clamped.any()
    np.testing.assert_allclose(np.linalg.norm(ms.V[:, :2], axis=1), R + t / 2, rtol=1e-5)
    np.testing.assert_allclose(ms.V[:, 2], V[:, 2], atol=1e-6)
    u = unfold_patch(ms.V, F)  # the closed tube is cut to a disk along a generator
    assert u.cut and u.flipped == 0 and u.overlaps == 0
    for k in (0, 4, 8):
        w, edges = ring_width(u, ring, k)
        assert edges == na
        assert abs(w / (2 * np.pi * (R + t / 2)) - 1) < 1e-3, (k, w)
    # the skin's pattern is narrower by exactly the ratio of the radii
    if t:
        skin = unfold_patch(V, F)
        np.testing.assert_allclose(ring_width(u, ring, 4)[0] / ring_width(skin, ring, 4)[0], (R + t / 2) / R,
                                   rtol=1e-4)


@pytest.mark.parametrize("sigma", [0.0, 3.0])
def test_plane_moves_every_vertex_by_half_t(sigma):
    V, F = grid(12, 9, 80.0, jitter=0.2)
    ms = mid_surface(V, F, 6.0, sigma_mm=sigma)
    assert not ms.clamped.any()
    np.testing.assert_allclose(ms.offset, 3.0)
    np.testing.assert_allclose(ms.V - V, np.tile([0.0, 0.0, 3.0], (len(V), 1)), atol=1e-9)
    # the side the face normals point to
    ms = mid_surface(V, F[:, ::-1], 6.0, sigma_mm=sigma)
    np.testing.assert_allclose(ms.V[:, 2], -3.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(ms.V - V, axis=1), 3.0)


def test_open_cylinder_mid_surface_right_up_to_the_border():
    """Normals fitted linearly keep their change across the region's border: the mid-surface of
    an open cylinder piece is (R + t/2) / R longer around, also on its border (heat-diffused
    normals left the border edges 12 % short)."""
    R, t = 30.0, 10.0
    V, F = cylinder_piece(R, 1.5 * np.pi, 40.0, 108, 8)
    ms = mid_surface(V, F, t)
    assert not ms.clamped.any()
    E = MeshTopology(V, F).edges
    around = np.abs(V[E[:, 0], 2] - V[E[:, 1], 2]) < 1e-9
    E = E[around]
    ratio = np.linalg.norm(ms.V[E[:, 0]] - ms.V[E[:, 1]], axis=1) / np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    np.testing.assert_allclose(ratio, (R + t / 2) / R, rtol=0.01)


def test_noisy_cap():
    """0.15 mm of scanner-like noise: the mid-surface carries the skin's noise without amplifying
    it and R_min stays near the cap's radius."""
    R = 40.0
    V, F = spherical_cap(R, 50, 5)  # 1.5 mm edges
    V = V * (1 + np.random.default_rng(1).normal(0, 0.15, len(V)) / R)[:, None]
    ms = mid_surface(V, F, 6.0)
    assert not folded_triangles(V, ms.V, F).any() and not ms.clamped.any()
    r = np.linalg.norm(ms.V, axis=1)
    assert abs(r.mean() - (R + 3.0)) < 0.05 and r.std() < 0.17
    (pb,) = piece_bending(V, F, np.zeros(len(F), dtype=int), 4.0, [0.0], 0.02)
    assert 0.85 * R < pb.R_min_mm < 1.02 * R


def test_zero_thickness_is_a_copy():
    V, F = height_field(lambda x, y: 0.003 * x * y, 8, 8)
    ms = mid_surface(V, F, 0.0)
    np.testing.assert_array_equal(ms.V, V)
    assert ms.V is not V and not ms.offset.any() and not ms.clamped.any()
    np.testing.assert_allclose(np.linalg.norm(ms.normals, axis=1), 1.0)


def test_sphere_mid_surface_radius_both_sides():
    R, t = 50.0, 10.0
    V, F = icosphere(4, R)
    out = mid_surface(V, F, t)
    np.testing.assert_allclose(np.linalg.norm(out.V, axis=1), R + t / 2, rtol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(out.V - V, axis=1), t / 2)  # a true distance in mm
    assert not out.clamped.any()
    inward = mid_surface(V, F[:, ::-1], t)
    np.testing.assert_allclose(np.linalg.norm(inward.V, axis=1), R - t / 2, rtol=1e-5)
    assert not inward.clamped.any()


def test_open_cap_concave_side():
    R, t = 50.0, 8.0
    V, F = spherical_cap(R, 50, 4)
    ms = mid_surface(V, F[:, ::-1], t)
    np.testing.assert_allclose(np.linalg.norm(ms.V, axis=1), R - t / 2, rtol=2e-3)


@pytest.mark.parametrize("make", ["sphere", "cylinder"])
def test_concave_offset_beyond_the_radius_is_clamped_without_flips(make):
    R, t = 10.0, 30.0  # t/2 = 15 mm > R: the offset towards the centre would fold
    if make == "sphere":
        V, F = icosphere(3, R)
        F = F[:, ::-1]
    else:
        V, F = cylinder_piece(R, 1.5 * np.pi, 40.0, 36, 8)
        topo = MeshTopology(V, F)
        if np.einsum("ij,ij->i", topo.face_normals, topo.centroids * [1, 1, 0]).mean() > 0:
            F = F[:, ::-1]  # normals towards the axis
    ms = mid_surface(V, F, t)
    interior = MeshTopology(V, F).interior_vertices
    assert ms.clamped[interior].all()
    assert ms.offset.max() <= CLAMP_FRACTION * R * 1.1  # limited to half the local radius (curvature at sigma)
    assert ms.offset[interior].min() > 0.3 * R  # but not dropped
    ratio = signed_area_ratio(V, ms.V, F)
    assert ratio.min() > MIN_AREA_RATIO and not folded_triangles(V, ms.V, F).any()  # none flipped or collapsed
    np.testing.assert_allclose(np.linalg.norm(ms.V - V, axis=1), ms.offset, atol=1e-9)
    # the same mesh seen from outside is not clamped
    out = mid_surface(V, F[:, ::-1], t)
    assert not out.clamped.any()


@pytest.mark.parametrize("make", ["sphere", "trough"])
def test_flip_check_alone_leaves_no_flipped_triangle(make, monkeypatch):
    """The safety net for folds the curvature at sigma does not see: with the curvature
    clamp switched off, the flip check alone keeps every offset triangle the right way up."""
    import bolus_addon.core.unfold.mid_surface as mod

    monkeypatch.setattr(mod, "CLAMP_FRACTION", 1e6)
    if make == "sphere":
        V, F = icosphere(3, 10.0)
        F, t = F[:, ::-1], 30.0
    else:  # a 10 mm round trough in a plane, normals up: concave towards the offset side
        V, F = height_field(lambda x, y: -np.sqrt(np.maximum(100.0 - x**2, 0.0)), 80, 6, 60.0)
        t = 30.0
    flat = V + 0.5 * t * principal_curvatures(V, F).normals
    assert folded_triangles(V, flat, F).any()  # the full offset folds
    ms = mid_surface(V, F, t)
    assert not folded_triangles(V, ms.V, F).any()
    assert signed_area_ratio(V, ms.V, F).min() > MIN_AREA_RATIO
    assert ms.clamped.any() and ms.offset.min() >= 0
    if make == "trough":
        assert not ms.clamped[np.abs(V[:, 0]) > 25].any()  # away from the trough: the full t/2


# ---------------------------------------------------------------------------------- curvature


@pytest.mark.parametrize("sigma", [0.0, 3.0])
def test_principal_curvatures_sphere_and_cylinder(sigma):
    V, F = icosphere(4, 40.0)
    c = principal_curvatures(V, F, sigma)
    np.testing.assert_allclose(1 / np.median(c.k1), 40.0, rtol=0.02)
    np.testing.assert_allclose(1 / np.median(c.k2), 40.0, rtol=0.02)
    c = principal_curvatures(V, F[:, ::-1], sigma)  # inward normals: concave, negative
    assert c.k1.max() < 0
    V, F = cylinder_piece(30.0, np.pi, 100.0, 48, 12)
    c = principal_curvatures(V, F, sigma)
    k = np.sort(np.abs(np.c_[c.k1, c.k2]), axis=1)
    np.testing.assert_allclose(1 / np.median(k[:, 1]), 30.0, rtol=0.02)
    assert np.median(k[:, 0]) < 1e-3 / 30


# ------------------------------------------------------------------------------- piece_bending


@pytest.mark.parametrize("shape", ["sphere", "cylinder"])
def test_piece_bending_radius_and_strain(shape):
    R, t = 40.0, 4.0
    if shape == "sphere":
        V, F = spherical_cap(R, 60, 4)
    else:
        V, F = cylinder_piece(R, np.pi, 100.0, 48, 12)
    (pb,) = piece_bending(V, F, np.zeros(len(F), dtype=int), t, [0.005], 0.02)
    assert abs(pb.R_min_mm / R - 1) < 0.03, pb
    np.testing.assert_allclose(pb.strain, t / (2 * pb.R_min_mm))
    assert pb.advice == "sheet" and pb.reason == ""
    # advice flips to print where R < 5 t
    (thin,) = piece_bending(V, F, np.zeros(len(F), dtype=int), R / SHEET_RADIUS_FACTOR * 0.97, [0.005], 0.02)
    (thick,) = piece_bending(V, F, np.zeros(len(F), dtype=int), R / SHEET_RADIUS_FACTOR * 1.1, [0.005], 0.02)
    assert thin.advice == "sheet"
    assert thick.advice == "print" and "radius of 40 mm" in thick.reason and "5 x" in thick.reason


def test_piece_bending_per_piece_el_and_zero_thickness():
    R = 30.0
    Vp, Fp = grid(16, 16, 120.0)  # piece 0: a flat sheet beside piece 1: a cap of radius R
    Vc, Fc = spherical_cap(R, 60, 4)
    V, F = np.r_[Vp, Vc + [200.0, 0, 0]], np.r_[Fp, Fc + len(Vp)]
    piece = np.r_[np.zeros(len(Fp), dtype=int), np.ones(len(Fc), dtype=int)]
    piece[:10] = -1  # a few triangles in no piece
    res = piece_bending(V, F, piece, 7.0, [0.01, 0.01], 0.02)
    assert res[0].R_min_mm > 10 * R and res[0].advice == "sheet"
    assert abs(res[1].R_min_mm / R - 1) < 0.05 and res[1].advice == "print"
    np.testing.assert_allclose(res[1].strain, 7.0 / (2 * res[1].R_min_mm))
    # EL above max_el: print, with the reason
    res = piece_bending(V, F, piece, 1.0, [0.025, 0.01], 0.02)
    assert [r.advice for r in res] == ["print", "sheet"]
    assert "EL 2.5 %" in res[0].reason and "radius" not in res[0].reason
    # max_el 0: the EL test uses the warn fraction
    res = piece_bending(V, F, piece, 1.0, [DEFAULT_WARN_FRACTION * 0.9, DEFAULT_WARN_FRACTION * 1.1], 0.0)
    assert [r.advice for r in res] == ["sheet", "print"]
    # thickness 0: strain 0, advice from EL only
    res = piece_bending(V, F, piece, 0.0, [0.01, 0.03], 0.02)
    assert [r.strain for r in res] == [0.0, 0.0] and [r.advice for r in res] == ["sheet", "print"]
    assert abs(res[1].R_min_mm / R - 1) < 0.05


def test_piece_bending_flat_piece_is_infinite_radius():
    V, F = grid(6, 6, 50.0)
    (pb,) = piece_bending(V, F, np.zeros(len(F), dtype=int), 8.0, [0.0], 0.02)
    assert pb.R_min_mm == np.inf and pb.strain == 0.0 and pb.advice == "sheet"
    import json

    assert json.loads(json.dumps(pb.as_dict(), allow_nan=False))["R_min_mm"] is None


def test_curvatures_shared():
    """mid_surface and piece_bending take curvatures computed once; the results are the same."""
    V, F = spherical_cap(40.0, 60, 3)
    curv = principal_curvatures(V, F)
    a, b = mid_surface(V, F, 6.0), mid_surface(V, F, 6.0, curvatures=curv)
    np.testing.assert_array_equal(a.V, b.V)
    piece = np.zeros(len(F), dtype=int)
    assert piece_bending(V, F, piece, 6.0, [0.0], 0.02) == piece_bending(V, F, piece, 6.0, [0.0], 0.02,
                                                                           curvatures=curv)
    with pytest.raises(BolusError, match="not those of this region"):
        mid_surface(V[:-1], F[(F < len(V) - 1).all(axis=1)], 6.0, curvatures=curv)


def test_piece_bending_refuses_bad_input():
    V, F = grid(4, 4, 40.0)
    piece = np.zeros(len(F), dtype=int)
    with pytest.raises(BolusError, match="sheet thickness"):
        piece_bending(V, F, piece, -1.0, [0.0], 0.02)
    with pytest.raises(BolusError, match="EL"):
        piece_bending(V, F, piece, 1.0, [np.nan], 0.02)
    with pytest.raises(BolusError, match="EL"):
        piece_bending(V, F, piece, 1.0, [], 0.02)
    with pytest.raises(BolusError, match="max_el"):
        piece_bending(V, F, piece, 1.0, [0.0], -0.01)
    with pytest.raises(BolusError, match="each of the 32 triangles"):
        piece_bending(V, F, piece[:-1], 1.0, [0.0], 0.02)
    with pytest.raises(BolusError, match="piece 2, but EL gives 1"):
        piece_bending(V, F, np.r_[piece[:-1], 2], 1.0, [0.0], 0.02)
    with pytest.raises(BolusError, match="piece 1 has no triangles"):
        piece_bending(V, F, piece, 1.0, [0.0, 0.0], 0.02)
    for sigma in (-1, np.nan, None, "three"):
        with pytest.raises(BolusError, match="smoothing scale"):
            piece_bending(V, F, piece, 1.0, [0.0], 0.02, sigma_mm=sigma)
        with pytest.raises(BolusError, match="smoothing scale"):
            mid_surface(V, F, 1.0, sigma_mm=sigma)


# ------------------------------------------------------------------------------ thickness check


@pytest.mark.parametrize("bad", [-1.0, np.nan, np.inf, "thick", None])
def test_bad_thickness_refused(bad):
    V, F = grid(4, 4, 40.0)
    with pytest.raises(BolusError, match="sheet thickness"):
        mid_surface(V, F, bad)
    with pytest.raises(BolusError, match="sheet thickness"):
        check_sheet_thickness(V, F, bad)


def test_thickness_larger_than_the_region_refused():
    V, F = grid(20, 4, 100.0)  # a 100 x 100 mm square
    V[:, 1] *= 0.2  # -> 100 x 20 mm strip
    w = region_width(V, F)
    assert 20.0 <= w < 20.0 * 1.1
    check_sheet_thickness(V, F, 0.0)
    check_sheet_thickness(V, F, 15.0)
    with pytest.raises(BolusError, match=r"thickness 25 mm is larger than the region, which is about 2\d\.\d mm"):
        check_sheet_thickness(V, F, 25.0)
    # a strip one triangle wide (every vertex on the border) is as wide as it is
    Vs, Fs = grid(20, 1, 100.0)
    Vs[:, 1] *= 0.1  # 100 x 10 mm, 5 mm cells: rungs 10 mm, diagonals 11.2 mm
    assert 10.0 <= region_width(Vs, Fs) <= 11.2
    check_sheet_thickness(Vs, Fs, 9.0)
    with pytest.raises(BolusError, match="about 11.2 mm"):
        check_sheet_thickness(Vs, Fs, 12.0)
    # one triangle: its inscribed circle
    tri = np.array([[0.0, 0, 0], [3, 0, 0], [0, 4, 0]])
    np.testing.assert_allclose(region_width(tri, [[0, 1, 2]]), 2.0)  # 2 area / semi-perimeter = 1
    # a closed region: its smallest extent
    Vs, Fs = icosphere(2, 10.0)
    assert 19.0 < region_width(Vs, Fs) <= 20.0
    with pytest.raises(BolusError, match="choose a thickness below"):
        check_sheet_thickness(Vs, Fs, 21.0)


# ------------------------------------------------------------------------------ degenerate input

BASE = height_field(lambda x, y: 0.002 * (x**2 + y**2), nx=8, ny=8)
CASES = degenerate_variants(*BASE)


@pytest.mark.parametrize("name", sorted(CASES))
def test_degenerate_input(name):
    V, F, says = CASES[name]
    piece = np.zeros(len(F), dtype=int)
    calls = {
        "mid_surface": lambda: mid_surface(V, F, 4.0),
        "principal_curvatures": lambda: principal_curvatures(V, F),
        "piece_bending": lambda: piece_bending(V, F, piece, 4.0, [0.01], 0.02),
        "check_sheet_thickness": lambda: check_sheet_thickness(V, F, 4.0),
    }
    if says in (None, "non-manifold"):  # sound: finite results
        ms = calls["mid_surface"]()
        assert np.isfinite(ms.V).all() and np.isfinite(ms.offset).all()
        assert signed_area_ratio(V, ms.V, F).min() > MIN_AREA_RATIO
        c = calls["principal_curvatures"]()
        assert np.isfinite(c.k1).all() and np.isfinite(c.k2).all()
        (pb,) = calls["piece_bending"]()
        assert np.isfinite(pb.strain) and pb.R_min_mm > 0
        calls["check_sheet_thickness"]()
        return
    for name_, call in calls.items():
        if says == "zero-area" and name_ == "check_sheet_thickness":
            calls[name_]()  # the width is a distance: zero-area triangles do not hurt it
            continue
        with pytest.raises(BolusError, match=says):
            call()
