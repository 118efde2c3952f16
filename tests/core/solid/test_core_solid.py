"""core.solid: the Manifold <-> arrays conversion, SPEC closedness and ray thickness."""
import numpy as np
import pytest

from bolus_addon.core.errors import BolusError
from bolus_addon.core.solid.manifold import closed_report, from_manifold, ray_thickness, to_manifold
from meshgen import box, degenerate_variants, grid, icosphere, torus


def test_box_round_trip_closed_and_volume():
    V, F = box((40.0, 30.0, 20.0), n=3)
    rep = closed_report(V, F)
    assert rep["closed"] and rep["components"] == 1 and rep["genus"] == 0
    assert rep["volume_mm3"] == pytest.approx(24000.0)
    M = to_manifold(V, F)
    assert M.volume() == pytest.approx(24000.0)
    V2, F2 = from_manifold(M)
    assert V2.dtype == np.float64 and F2.dtype == np.int64
    assert closed_report(V2, F2)["volume_mm3"] == pytest.approx(24000.0)


def test_genus_and_components():
    V, F = torus()
    assert closed_report(V, F)["genus"] == 1
    V1, F1 = icosphere(1, 10.0)
    V2 = np.r_[V1, V1 + [50.0, 0, 0]]
    F2 = np.r_[F1, F1 + len(V1)]
    rep = closed_report(V2, F2)
    assert rep["closed"] and rep["components"] == 2 and rep["genus"] == 0


def test_open_flipped_and_nonmanifold_are_reported():
    V, F = grid(3, 3)
    rep = closed_report(V, F)
    assert not rep["closed"] and rep["boundary_edges"] == 12 and rep["genus"] is None
    V, F = box(n=2)
    Ff = F.copy()
    Ff[0] = Ff[0, ::-1]
    rep = closed_report(V, Ff)
    assert not rep["closed"] and rep["inconsistent_edges"] == 3
    Fn = np.r_[F, F[:1]]
    assert closed_report(V, Fn)["nonmanifold_edges"] == 3


def test_to_manifold_refuses_open_mesh_naming_it():
    V, F = box(n=2)
    with pytest.raises(BolusError, match="not a closed solid.*2 open edge|not a closed solid.*open edge"):
        to_manifold(V, F[:-1], "part 2")
    with pytest.raises(BolusError, match="part 2"):
        to_manifold(V, F[:-1], "part 2")


@pytest.mark.parametrize("name", sorted(degenerate_variants(*box(n=2))))
def test_to_manifold_degenerate_input(name):
    """Each variant adds a dangling triangle (open edges) or makes a vertex non-finite:
    never a closed solid, and the message says which."""
    V, F, says = degenerate_variants(*box(n=2))[name]
    expect = f"non-finite coordinate at {says}" if name in ("nan", "inf") else "not a closed solid"
    with pytest.raises(BolusError, match=expect):
        to_manifold(V, F)
    if name not in ("nan", "inf"):
        assert not closed_report(V, F)["closed"]


def test_ray_thickness_on_a_box():
    V, F = box((40.0, 30.0, 20.0), n=3)
    O = np.array([[10.0, 10.0, 0.0], [10.0, 10.0, -5.0], [100.0, 100.0, 5.0], [20.0, 15.0, 10.0]])
    D = np.array([[0, 0, 1.0], [0, 0, 2.0], [0, 0, 1.0], [1.0, 0, 0]])
    d, P = ray_thickness(V, F, O, D, 100.0, return_points=True)
    assert d[0] == pytest.approx(20.0)           # from the bottom face to the top (the start face is skipped)
    assert d[1] == pytest.approx(5.0)            # enters the box at z = 0 (unit direction)
    assert np.isinf(d[2]) and np.isnan(P[2]).all()
    assert d[3] == pytest.approx(20.0)
    np.testing.assert_allclose(P[0], [10.0, 10.0, 20.0], atol=1e-9)
    assert np.isinf(ray_thickness(V, F, O[:1], D[:1], 10.0))[0]  # max_mm shorter than the wall


def test_ray_thickness_bad_input():
    V, F = box(n=2)
    with pytest.raises(BolusError, match="direction 0 is zero"):
        ray_thickness(V, F, [[1.0, 1.0, 1.0]], [[0.0, 0.0, 0.0]], 10.0)
    with pytest.raises(BolusError, match="2 origins but 1 directions"):
        ray_thickness(V, F, [[1.0, 1, 1], [2.0, 2, 2]], [[0.0, 0, 1]], 10.0)
    with pytest.raises(BolusError, match="not finite"):
        ray_thickness(V, F, [[np.nan, 1, 1]], [[0.0, 0, 1]], 10.0)


def test_weld_short_edges_collapses_float32_slivers_and_keeps_the_solid_closed():
    from meshgen import icosphere

    from bolus_addon.core.solid.manifold import closed_report, weld_short_edges

    V, F = icosphere(3, 30.0)
    V = V.copy()
    a, b = F[0, 0], F[0, 1]
    V[b] = V[a] + 2e-6 * (V[b] - V[a]) / np.linalg.norm(V[b] - V[a])  # a 2e-6 mm edge: one point in float32
    assert closed_report(V, F)["closed"]
    V2, F2, keep = weld_short_edges(V, F)
    assert len(F2) == len(F) - 2 and keep.sum() == len(F2) and not keep[0]
    assert len(V2) == len(V) - 1
    r = closed_report(V2, F2)
    assert r["closed"] and r["genus"] == 0
    assert abs(r["volume_mm3"] - closed_report(V, F)["volume_mm3"]) < 1e-6 * abs(r["volume_mm3"])
    # float32 coordinates no longer collapse any triangle
    P = V2.astype(np.float32)[F2]
    assert not (np.all(P[:, 0] == P[:, 1], axis=1) | np.all(P[:, 1] == P[:, 2], axis=1)
                | np.all(P[:, 0] == P[:, 2], axis=1)).any()
    # nothing short: unchanged
    V3, F3, keep3 = weld_short_edges(*icosphere(2, 30.0))
    assert keep3.all() and len(F3) == len(icosphere(2, 30.0)[1])
