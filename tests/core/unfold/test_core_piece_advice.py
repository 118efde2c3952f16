"""core.piece_advice: angle deficit or excess decides the advice for a badly flattened piece.

The advice is checked against what really happens: a dome (deficit) cut into more
patches unfolds with less error; a nostril pocket of a held-out scan (excess) is told
to leave the cavity out, split it or print, not to segment into more patches.
"""
import numpy as np
import pytest
from paths import data_mesh
from meshgen import grid, height_field, spherical_cap

from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.objfile import load_obj
from bolus_addon.core.unfold.piece_advice import EXCESS_SHARE, diffused_defect, piece_advice
from bolus_addon.core.analysis.saliency import analyse
from bolus_addon.core.analysis.spectral import segment
from bolus_addon.core.mesh.topology import MeshTopology
from bolus_addon.core.unfold.unfold import unfold_patch


def submesh(V, F, sel):
    used, inv = np.unique(F[sel], return_inverse=True)
    return V[used], inv.reshape(-1, 3)


def ball_region(V, F, centre, radius):
    """Faces with all corners within `radius` of `centre`, the connected piece nearest to it."""
    d = np.linalg.norm(V - centre, axis=1)
    Vn, Fn = submesh(V, F, (d[F] <= radius).all(axis=1))
    _, comp = MeshTopology(Vn, Fn).face_components()
    near = int(np.argmin(np.linalg.norm(Vn - centre, axis=1)))
    return submesh(Vn, Fn, comp == comp[np.nonzero((Fn == near).any(axis=1))[0][0]])


def dimple(depth=6.0, width=4.0):
    """A flat 40 mm square with a Gaussian pocket in the middle (a cup with a saddle-shaped rim)."""
    return height_field(lambda x, y: -depth * np.exp(-(x * x + y * y) / (2 * width**2)), 30, 30, 40.0)


# ----------------------------------------------------------------- the figures
def test_excess_and_deficit_split_sum_varpi_and_keep_gauss_bonnet():
    V, F = dimple()
    raw = piece_advice(V, F, sigma_mm=0.0)
    res = analyse(V, F)
    # raw split: X = sum of s (eq. 4-4), X + D = sum varpi (eq. 4-2)
    assert raw.excess_rad == pytest.approx(res.saliency.sum(), rel=1e-12)
    assert raw.excess_rad + raw.deficit_rad == pytest.approx(res.sum_varpi, rel=1e-12)
    assert raw.sum_varpi == pytest.approx(res.sum_varpi) and raw.flv == pytest.approx(res.flv)
    # diffusion keeps the total curvature (D - X), shrinks both parts
    a = piece_advice(V, F, sigma_mm=3.0)
    assert a.deficit_rad - a.excess_rad == pytest.approx(raw.deficit_rad - raw.excess_rad, abs=1e-9)
    assert 0 < a.excess_rad < raw.excess_rad
    t = MeshTopology(V, F)
    K = 2 * np.pi - t.angle_sums
    K[~t.interior_vertices] = 0
    Kd = diffused_defect(t, K, 3.0)
    assert Kd.sum() == pytest.approx(K.sum(), abs=1e-9)
    assert a.worst_excess_vertex == int(np.argmin(Kd)) and a.worst_deficit_vertex == int(np.argmax(Kd))
    # the pocket's deepest point is its worst deficit, its rim the excess
    r = np.linalg.norm(V[:, :2], axis=1)
    assert r[a.worst_deficit_vertex] < 2.0 and 3.0 < r[a.worst_excess_vertex] < 12.0


def test_flat_sheet_is_flat_and_a_fine_piece_gets_no_advice():
    V, F = grid(8, 8, jitter=0.3)
    a = piece_advice(V, F, EL=0.2, EA=0.2)
    assert a.kind == "flat" and a.excess_rad == pytest.approx(0, abs=1e-9)
    assert a.distorted and "Refine lengths" in a.advice
    cap = spherical_cap(10.0, 120.0, 3)
    fine = piece_advice(*cap, EL=0.029, EA=0.029)
    assert not fine.distorted and fine.advice == "" and fine.short_advice == ""
    assert fine.kind == "deficit"  # the diagnosis is there, only no advice


@pytest.mark.parametrize("what, value", [("EL", 0.031), ("EA", 0.031), ("flipped", 1), ("overlaps", 2)])
def test_each_figure_above_the_threshold_makes_the_piece_distorted(what, value):
    V, F = spherical_cap(10.0, 60.0, 3)
    assert piece_advice(V, F, **{what: value}).distorted
    if what in ("EL", "EA"):
        assert not piece_advice(V, F, threshold=0.05, **{what: value}).distorted


def test_bad_input_is_refused():
    V, F = spherical_cap(10.0, 60.0, 2)
    with pytest.raises(BolusError, match="EL"):
        piece_advice(V, F, EL=float("nan"))
    with pytest.raises(BolusError, match="threshold"):
        piece_advice(V, F, threshold=-0.01)
    with pytest.raises(BolusError, match="no faces"):
        piece_advice(V, F[:0])
    bad = V.copy()
    bad[3, 1] = np.nan
    with pytest.raises(BolusError, match="non-finite"):
        piece_advice(bad, F)


# ----------------------------------------------------------------- deficit: domes
@pytest.mark.parametrize("noise_mm", [0.0, 0.15])
def test_cap_is_a_deficit_also_with_scanner_noise(noise_mm):
    V, F = spherical_cap(10.0, 120.0, 3)
    t = MeshTopology(V, F)
    V = V + t.vertex_normals * np.random.default_rng(0).normal(0, noise_mm, (len(V), 1))
    a = piece_advice(V, F, EL=0.15, EA=0.3)
    assert a.kind == "deficit" and a.excess_share < 0.05, a
    assert "more, smaller patches" in a.advice and "dart" in a.advice
    assert "printed bolus" not in a.advice
    if noise_mm:  # the raw angle sums would have called it a mixed piece
        assert piece_advice(V, F, sigma_mm=0.0).excess_share > 0.25


def test_more_patches_really_lower_the_error_of_a_dome():
    """The deficit advice holds: the 120 degree cap of 10 mm radius cut into 4 patches unfolds far better."""
    V, F = spherical_cap(10.0, 120.0, 3)
    whole = unfold_patch(V, F)
    a = piece_advice(V, F, whole.EL, whole.EA, whole.flipped, whole.overlaps)
    assert a.distorted and a.kind == "deficit" and whole.EL > 0.1
    seg = segment(V, F, 4, rng=0)
    worst = max(unfold_patch(*submesh(V, F, seg.face_labels == p)).EL for p in range(seg.patch_count))
    assert worst < 0.6 * whole.EL, (worst, whole.EL)


# ----------------------------------------------------------------- excess: pockets, saddles
def test_saddle_and_dimple_are_excess():
    V, F = height_field(lambda x, y: (x * x - y * y) / 300.0, 20, 20, 100.0)
    a = piece_advice(V, F, EL=0.05)
    assert a.kind == "excess" and a.excess_share == pytest.approx(1.0)
    d = piece_advice(*dimple(), EA=0.05)
    assert d.kind == "excess" and d.excess_share == pytest.approx(0.5, abs=0.02)
    for adv in (a.advice, d.advice):
        assert "more patches around a pocket make it worse" in adv
        assert "leave the cavity out" in adv and "printed bolus" in adv
        assert "split it into separate pieces along the groove" in adv
        assert "segment it into more" not in adv


NOSTRILS = [
    # nefertiti.obj is in mm (Y up, nose tip at (3.6, -8.3, 181.2)); the two nostril pockets below the tip
    pytest.param("nefertiti.obj", 1.0, (-5.0, -14.0, 169.0), 12.0, id="nefertiti_right"),
    pytest.param("nefertiti.obj", 1.0, (10.0, -13.0, 170.0), 10.0, id="nefertiti_left"),
]


@pytest.mark.parametrize("name, scale, centre, radius", NOSTRILS)
def test_nostril_pocket_of_a_held_out_scan_gets_the_excess_advice(name, scale, centre, radius):
    V, F, _ = load_obj(data_mesh(name), scale)
    Vp, Fp = ball_region(V, F, np.array(centre), radius)
    assert 80 < len(Fp) < 300, "test setup: a small piece around the pocket"
    u = unfold_patch(Vp, Fp)
    a = piece_advice(Vp, Fp, u.EL, u.EA, u.flipped, u.overlaps)
    assert u.EL > 0.03 or u.EA > 0.03, "test setup: the pocket does not lie flat"
    assert a.distorted and a.kind == "excess" and a.excess_share >= EXCESS_SHARE, a
    assert "leave the cavity out" in a.advice and "printed bolus" in a.advice


def test_more_patches_do_not_help_the_nostrils():
    """What the excess advice rests on: the nefertiti nose region at 6 patches has a worse
    worst piece than at 3, and that worst piece is diagnosed as excess."""
    V, F, _ = load_obj(data_mesh("nefertiti.obj"), 1.0)
    Vn, Fn = ball_region(V, F, np.array([3.6, -8.3, 181.2]), 30.0)
    worst = {}
    for k in (3, 6):
        seg = segment(Vn, Fn, k, rng=0)
        rows = []
        for p in range(seg.patch_count):
            Vp, Fp = submesh(Vn, Fn, seg.face_labels == p)
            u = unfold_patch(Vp, Fp)
            rows.append((u.EL, piece_advice(Vp, Fp, u.EL, u.EA, u.flipped, u.overlaps)))
        worst[k] = max(rows, key=lambda r: r[0])
    assert worst[6][0] > worst[3][0] > 0.03, (worst[3][0], worst[6][0])
    assert worst[3][1].kind == worst[6][1].kind == "excess"
