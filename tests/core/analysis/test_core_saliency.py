"""Flattenability and saliency, eqs. 4-1..4-4, and the analysis smoothing."""
import numpy as np
import pytest
from meshgen import cylinder_piece, grid, height_field, icosphere

from bolus_addon.core.errors import BolusError
from bolus_addon.core.analysis.saliency import analyse, flattenability_value, smooth_for_analysis
from bolus_addon.core.mesh.topology import MeshTopology


def test_gauss_bonnet_on_closed_genus0_mesh():
    for sub in (1, 3):
        V, F = icosphere(sub, radius=37.0)
        t = MeshTopology(V, F)
        assert t.interior_vertices.all()
        assert (2 * np.pi - t.angle_sums).sum() == pytest.approx(4 * np.pi, abs=1e-9)


def test_flat_grid_has_zero_flattenability_and_boundary_is_zero():
    V, F = grid(12, 9, jitter=0.3)
    r = analyse(V, F)
    t = MeshTopology(V, F)
    assert np.abs(r.varpi[t.interior_vertices]).max() < 1e-12
    assert r.sum_varpi < 1e-10 and r.flv == pytest.approx(10.0)
    assert (r.varpi[t.boundary_vertices] == 0).all()


def test_unrolled_cylinder_is_developable():
    V, F = cylinder_piece(radius=40.0, angle=1.5 * np.pi)
    r = analyse(V, F)
    assert r.varpi.max() < 1e-12
    # and a raw sphere is not
    Vs, Fs = icosphere(2, 40.0)
    assert analyse(Vs, Fs).varpi.min() > 0


def test_saliency_only_where_angle_sum_exceeds_two_pi():
    # saddle z = (x^2 - y^2)/k: angle sums above 2 pi (eq. 4-4 positive)
    V, F = height_field(lambda x, y: (x**2 - y**2) / 60.0, nx=16, ny=16)
    r = analyse(V, F)
    t = MeshTopology(V, F)
    inner = t.interior_vertices
    assert (r.theta[inner] > 2 * np.pi).all() and (r.saliency[inner] > 0).all()
    np.testing.assert_allclose(r.saliency[inner], r.theta[inner] - 2 * np.pi)
    # dome z = -(x^2 + y^2)/k: angle sums below 2 pi: flattenability > 0 but saliency 0
    V2, F2 = height_field(lambda x, y: -(x**2 + y**2) / 60.0, nx=16, ny=16)
    r2 = analyse(V2, F2)
    inner2 = MeshTopology(V2, F2).interior_vertices
    assert (r2.varpi[inner2] > 0).all() and (r2.saliency == 0).all()


def test_sum_and_flv_follow_eqs_4_2_and_4_3():
    V, F = icosphere(2, 30.0)
    r = analyse(V, F)
    assert r.sum_varpi == pytest.approx(np.abs(r.theta - 2 * np.pi).sum())
    assert r.flv == pytest.approx(10 * 0.5**r.sum_varpi)
    assert flattenability_value(0.0) == 10.0 and flattenability_value(1.0) == 5.0


def _noisy_cap(noise_mm, rng=1):
    V, F = height_field(lambda x, y: 20.0 * np.exp(-(x**2 + y**2) / 800.0), nx=40, ny=40, size=100.0)
    t = MeshTopology(V, F)
    g = np.random.default_rng(rng)
    V = V + (g.normal(0, noise_mm, (len(V), 1)) * t.vertex_normals) * t.interior_vertices[:, None]
    return V, F


def test_smoothing_removes_scanner_noise_but_never_moves_the_mesh():
    V, F = _noisy_cap(0.3)
    V0 = V.copy()
    raw = analyse(V, F, 0.0)
    smooth = analyse(V, F, 3.0)
    clean = analyse(*_noisy_cap(0.0), 0.0)
    np.testing.assert_array_equal(V, V0)  # input untouched
    # noise drowns the signal (44x the clean sum) and smoothing at 3 mm takes 90 % of it
    # away again (figures measured 2026-12, pinned at +-15 %)
    assert raw.sum_varpi / clean.sum_varpi == pytest.approx(44.0, rel=0.15)
    assert smooth.sum_varpi / raw.sum_varpi == pytest.approx(0.094, rel=0.15)
    # smoothing keeps boundary vertices where they are and maps 1:1 to the input
    t = MeshTopology(V, F)
    np.testing.assert_array_equal(smooth.V_analysis[t.boundary_vertices], V[t.boundary_vertices])
    assert smooth.varpi.shape == (len(V),)


def test_smoothing_zero_is_raw_and_flat_stays_flat():
    V, F = _noisy_cap(0.2)
    a, b = analyse(V, F, 0.0), analyse(V, F, 0)
    np.testing.assert_array_equal(a.varpi, b.varpi)
    np.testing.assert_array_equal(a.V_analysis, V)
    Vg, Fg = grid(10, 10, jitter=0.3)
    assert analyse(Vg, Fg, 5.0).sum_varpi < 1e-9  # a plane stays a plane


def test_smoothing_scale_is_in_mm():
    """The same surface in mm and in 10x finer units: same result for the same scale in mm."""
    V, F = _noisy_cap(0.3)
    a = analyse(V, F, 3.0).varpi
    Vs = smooth_for_analysis(MeshTopology(V * 10.0, F), 30.0) / 10.0
    np.testing.assert_allclose(Vs, analyse(V, F, 3.0).V_analysis, atol=1e-9)
    assert a.sum() > 0


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_bad_smoothing_scale(bad):
    V, F = grid(3, 3)
    with pytest.raises(BolusError, match="smoothing"):
        analyse(V, F, bad)


def test_analysis_key_changes_with_anything_the_analysis_depends_on():
    """segment reuses a preview only under an equal key: the key follows
    the exact coordinates, the triangles and the smoothing, not the array types."""
    from bolus_addon.core.analysis.saliency import analysis_key

    V, F = _noisy_cap(0.1)
    k = analysis_key(V, F, 3.0)
    assert k == analysis_key(V.copy(), F.astype(np.int32), 3)  # same values, other dtypes
    V2 = V.copy()
    V2[7, 2] = np.nextafter(V2[7, 2], np.inf)
    F2 = F.copy()
    F2[0] = F2[0, [1, 2, 0]]  # same triangle, other first corner: other bytes, a new analysis
    assert len({k, analysis_key(V2, F, 3.0), analysis_key(V, F2, 3.0), analysis_key(V, F, 2.0),
                analysis_key(V[:-1], F[:-1], 3.0)}) == 5


def test_lumped_mass_from_a_topology_is_the_same():
    from bolus_addon.core.analysis.saliency import lumped_mass

    V, F = _noisy_cap(0.1)
    np.testing.assert_array_equal(lumped_mass(V, F, MeshTopology(V, F)), lumped_mass(V, F))
