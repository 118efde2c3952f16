"""Core of `bolus.improve_flattenability`: the objective of eq. 4-21
(`core/improve_objective.py`) and the driver with its gradient method (`core/improve.py`)."""
import numpy as np
import pytest

from bolus_addon.core.errors import BolusError
from bolus_addon.core.improve.improve import (
    ImproveJob,
    gradient_steps,
    improve_flattenability,
    improve_messages,
    surface_stats,
)
from bolus_addon.core.improve.objective import SurfaceObjective, outward_directions, uniform_laplacian
from bolus_addon.core.analysis.saliency import analyse, smooth_for_analysis
from bolus_addon.core.mesh.topology import MeshTopology
from meshgen import degenerate_variants, grid, height_field, icosphere


def bumpy(n=14, noise=0.25, seed=1):
    """A 50 mm height field with a bump, a dip and scanner-like noise (~ n^2 vertices)."""
    rng = np.random.default_rng(seed)
    return height_field(lambda x, y: 6 * np.exp(-(x**2 + y**2) / 200) - 4 * np.exp(-((x - 12) ** 2 + y**2) / 60)
                        + noise * rng.standard_normal(x.shape), n, n, 50.0)


def plane(n=8):
    V, F = grid(n, n, 40.0)
    return V, F


# ----------------------------------------------------------------------------- objective (eq. 4-21)

def test_terms_match_their_definitions():
    V, F = bumpy()
    ob = SurfaceObjective(V, F)
    topo = MeshTopology(V, F)
    d = np.where(ob.movable, 0.3, 0.0)
    X = V + outward_directions(V, F) * d[:, None]
    t = ob.terms(d)
    th = MeshTopology(X, F).angle_sums
    inner = topo.interior_vertices
    assert t[0] == pytest.approx(np.abs(th[inner] - 2 * np.pi).sum())  # eq. 4-10
    L = uniform_laplacian(topo).toarray()
    nb = topo.vertex_adjacency.toarray()
    i = int(np.nonzero(inner)[0][5])
    assert L[i, i] == 1 and np.allclose(L[i][nb[i] > 0], -1 / nb[i].sum())  # eq. 4-12
    assert t[1] == pytest.approx(np.sum((L @ X)[inner] ** 2))  # eq. 4-13
    assert t[2] == pytest.approx(np.sum(d**2))  # eq. 4-16
    A0, A = MeshTopology(V, F).areas, MeshTopology(X, F).areas
    assert t[3] == pytest.approx(np.abs(A - A0).sum() / A0.sum())  # eq. 4-14
    assert ob.value(d) == pytest.approx(np.dot([10, 1, 0.1, 10], t))  # eq. 4-21, the seed's mu


def test_flat_plane_objective_is_zero_with_no_offsets():
    ob = SurfaceObjective(*plane())
    d = np.zeros(ob.n)
    assert ob.value(d) == pytest.approx(0.0, abs=1e-9)
    J, g = ob.value_and_grad(d)
    assert J == pytest.approx(0.0, abs=1e-9) and np.abs(g).max() < 1e-6


def test_gradient_matches_finite_differences():
    V, F = bumpy(noise=0.4)
    ob = SurfaceObjective(V, F)
    rng = np.random.default_rng(3)
    d = np.where(ob.movable, rng.uniform(0, 1, ob.n), 0.0)
    _, g = ob.value_and_grad(d, smooth=1e-3)
    for i in rng.choice(ob.movable_ids, 8, replace=False):
        e = np.zeros(ob.n)
        e[i] = 1e-6
        fd = (ob.value_and_grad(d + e, 1e-3)[0] - ob.value_and_grad(d - e, 1e-3)[0]) / 2e-6
        assert g[i] == pytest.approx(fd, rel=1e-4, abs=1e-5), i
    assert np.all(g[~ob.movable] == 0)


def test_batch_values_equal_full_evaluation():
    V, F = bumpy()
    ob = SurfaceObjective(V, F)
    rng = np.random.default_rng(4)
    d = np.where(ob.movable, rng.uniform(0, 0.5, ob.n), 0.0)
    for k in (1, 7, len(ob.movable_ids)):
        nodes = np.sort(rng.choice(ob.movable_ids, k, replace=False))
        D = rng.uniform(0, 1, (5, k))
        full = []
        for row in D:
            dd = d.copy()
            dd[nodes] = row
            full.append(ob.value(dd))
        assert np.allclose(ob.batch_values(d, nodes, D), full, rtol=1e-10, atol=1e-10), k
    with pytest.raises(BolusError, match="one column per node"):
        ob.batch_values(d, nodes, D[:, :-1])


def test_objective_refuses_bad_weights_and_directions():
    V, F = bumpy()
    with pytest.raises(BolusError, match="mu"):
        SurfaceObjective(V, F, mu=(1, -1, 0, 0))
    with pytest.raises(BolusError, match="directions"):
        SurfaceObjective(V, F, N=np.full((len(V), 3), np.nan))


# ----------------------------------------------------------------------------- the driver


def test_only_interior_vertices_move_along_their_normal_within_the_gap():
    V, F = bumpy()
    res = improve_flattenability(V, F, 0.8, smoothing_mm=3.0)
    topo = MeshTopology(V, F)
    moved = res.V - V
    assert np.all(moved[topo.boundary_vertices] == 0)
    assert np.all(res.gap >= 0) and res.gap.max() <= 0.8 + 1e-12
    assert res.gap.max() > 0.05, "nothing moved on a bumpy surface"
    # along the analysis copy's own vertex normal, by exactly the gap
    N = MeshTopology(smooth_for_analysis(topo, 3.0), F).vertex_normals
    assert np.allclose(moved, N * res.gap[:, None], atol=1e-12)
    assert np.allclose(res.directions, N)
    # outward: the side the faces point to (+z on this height field)
    assert np.all(moved[:, 2] >= -1e-12)
    assert res.whole_after.max_gap_mm == pytest.approx(res.gap.max())


@pytest.mark.parametrize("smoothing", [0.0, 3.0])
def test_flv_does_not_decrease_and_improves_a_bumpy_surface(smoothing):
    V, F = bumpy(noise=0.3)
    res = improve_flattenability(V, F, 1.0, smoothing_mm=smoothing)
    b, a = res.whole_before, res.whole_after
    assert a.flv >= b.flv and a.sum_varpi <= b.sum_varpi
    assert a.sum_varpi < 0.9 * b.sum_varpi, (b.sum_varpi, a.sum_varpi)
    # measured as the preview measures: analyse() of the output at the same scale
    assert a.sum_varpi == pytest.approx(analyse(res.V, F, smoothing).sum_varpi)
    rec = res.patches[0]
    assert rec.status == "improved" and rec.objective_after < rec.objective_before and rec.iterations > 0


def test_flat_patch_is_left_unchanged_and_said_so():
    V, F = plane()
    res = improve_flattenability(V, F, 1.0)
    assert not res.changed and np.array_equal(res.V, V)
    assert res.patches[0].status == "flat"
    msgs = improve_messages(res, "plane")
    assert any("already flat" in m and "nothing to do" in m for _, m in msgs)


def test_patches_are_optimised_separately_and_their_shared_border_stays():
    V, F = bumpy(n=16)
    labels = (MeshTopology(V, F).centroids[:, 0] > 0).astype(int)
    res = improve_flattenability(V, F, 1.0, patch_labels=labels)
    shared = np.intersect1d(F[labels == 0].ravel(), F[labels == 1].ravel())
    assert len(shared) > 5 and np.all(res.gap[shared] == 0)
    assert [p.patch for p in res.patches] == [0, 1]
    for p in res.patches:
        assert p.after.sum_varpi <= p.before.sum_varpi
    assert any(p.status == "improved" for p in res.patches)
    # faces outside the segmented region (-1) are not touched
    labels[labels == 1] = -1
    res = improve_flattenability(V, F, 1.0, patch_labels=labels)
    outside = np.setdiff1d(F[labels == -1].ravel(), F[labels == 0].ravel())
    assert np.all(res.gap[outside] == 0) and len(res.patches) == 1


def test_same_input_gives_the_same_result_twice():
    V, F = bumpy()
    a = improve_flattenability(V, F, 1.0)
    b = improve_flattenability(V, F, 1.0)
    assert np.array_equal(a.gap, b.gap)


def test_gradient_steps_respect_the_bounds_and_never_get_worse():
    V, F = bumpy(noise=0.4)
    ob = SurfaceObjective(V, F)
    upper = np.where(ob.movable, 0.5, 0.0)
    J0 = ob.value(np.zeros(ob.n))
    last = np.inf
    for st in gradient_steps(ob, upper, chunk=10, max_iterations=60):
        assert np.all(st.d >= 0) and np.all(st.d <= upper + 1e-12)
        assert st.value <= J0 and st.value <= last + 1e-12
        last = st.value
    assert last < J0


def test_cancel_keeps_the_best_so_far():
    V, F = bumpy(noise=0.4)
    job = ImproveJob(V, F, 1.0, smoothing_mm=0.0)
    for _ in range(2):
        assert job.step()
    res = job.result()
    assert res.cancelled and res.patches[0].status == "cancelled"
    assert np.all(res.gap >= 0) and res.gap.max() <= 1.0 and res.changed
    assert res.whole_after.sum_varpi <= res.whole_before.sum_varpi
    assert any("cancelled after" in m for _, m in improve_messages(res))
    assert job.result() is res and not job.step()


def test_large_gaps_are_warned():
    V, F = bumpy(noise=0.6)
    res = improve_flattenability(V, F, 4.0, smoothing_mm=0.0)
    assert res.gap.max() > 2.0  # 2.48 mm at vertex 158
    i = int(np.argmax(res.gap))
    assert any(f"largest air gap is {res.gap[i]:.2f} mm (vertex {i})" in w and "planning CT" in w
               for w in res.warnings)
    res = improve_flattenability(V, F, 1.0, smoothing_mm=0.0)
    assert not any("largest air gap" in w for w in res.warnings)


@pytest.mark.parametrize("gap,match", [(0.0, "positive"), (-1.0, "positive"), (float("nan"), "positive")])
def test_bad_gap_is_refused(gap, match):
    with pytest.raises(BolusError, match=match):
        ImproveJob(*bumpy(), gap)


def test_bad_settings_and_meshes_are_refused():
    V, F = bumpy()
    with pytest.raises(BolusError, match="unknown method"):
        ImproveJob(V, F, 1.0, method="NEWTON")
    with pytest.raises(BolusError, match="no interior vertices"):
        ImproveJob(V[F[0]], np.array([[0, 1, 2]]), 1.0)
    G = F.copy()
    G[0] = G[0, ::-1]
    with pytest.raises(BolusError, match="consistently oriented"):
        ImproveJob(V, G, 1.0)
    with pytest.raises(BolusError, match="closed surface"):
        ImproveJob(*icosphere(2, 30.0), 1.0)
    with pytest.raises(BolusError, match="one patch per triangle"):
        ImproveJob(V, F, 1.0, patch_labels=np.zeros(3))


@pytest.mark.parametrize("name", sorted(degenerate_variants(*bumpy(n=8))))
def test_degenerate_input(name):
    V, F, says = degenerate_variants(*bumpy(n=8))[name]
    if says is None:  # the needle: sound, finite
        res = improve_flattenability(V, F, 1.0)
        assert np.isfinite(res.V).all() and res.gap.max() <= 1.0
        return
    with pytest.raises(BolusError, match=says):
        improve_flattenability(V, F, 1.0)


def test_surface_stats_row():
    V, F = bumpy()
    st = surface_stats(V, V, F)
    topo = MeshTopology(V, F)
    assert (st.vertices, st.edges, st.faces) == (topo.n, len(topo.edges), topo.m)
    assert st.sum_varpi == pytest.approx(analyse(V, F, 0.0).sum_varpi) == pytest.approx(st.raw_sum_varpi)
    assert st.area_mm2 == pytest.approx(topo.areas.sum()) and st.max_gap_mm == 0.0


def test_lpso_method_through_the_job_is_seeded_and_bounded():
    V, F = bumpy(n=10, noise=0.4)
    kw = dict(method="LPSO", rng=3, particles=10, iterations=20, max_iterations=200, smoothing_mm=0.0)
    a = improve_flattenability(V, F, 0.7, **kw)
    b = improve_flattenability(V, F, 0.7, **kw)
    assert np.array_equal(a.gap, b.gap) and a.method == "LPSO"
    assert a.changed and np.all(a.gap >= 0) and a.gap.max() <= 0.7
    assert np.all(a.gap[MeshTopology(V, F).boundary_vertices] == 0)
    assert a.whole_after.sum_varpi <= a.whole_before.sum_varpi
    c = improve_flattenability(V, F, 0.7, **{**kw, "rng": 4})
    assert not np.array_equal(a.gap, c.gap)


def test_whole_region_crease_note_when_only_the_whole_gets_worse():
    V, F = bumpy(n=16)
    labels = (MeshTopology(V, F).centroids[:, 0] > 0).astype(int)
    res = improve_flattenability(V, F, 1.0, patch_labels=labels)
    note = [m for _, m in improve_messages(res) if "become shallow creases" in m]
    worse = res.whole_after.sum_varpi > res.whole_before.sum_varpi
    assert bool(note) == worse
    res.whole_after.sum_varpi = res.whole_before.sum_varpi + 1.0  # the case the note is for
    assert any("become shallow creases" in m for _, m in improve_messages(res))
    res.whole_after.sum_varpi = res.whole_before.sum_varpi - 1.0
    assert not any("become shallow creases" in m for _, m in improve_messages(res))


def test_smoothness_on_another_surface_gradient_and_batch():
    """smooth_base: the smoothness (4-13) measured on the skin moved by the same offsets while the
    angles are taken on the analysis copy (what ImproveJob does)."""
    V, F = bumpy(noise=0.4)
    Va = smooth_for_analysis(MeshTopology(V, F), 3.0)
    ob = SurfaceObjective(Va, F, smooth_base=V)
    rng = np.random.default_rng(5)
    d = np.where(ob.movable, rng.uniform(0, 1, ob.n), 0.0)
    L = uniform_laplacian(MeshTopology(V, F))
    inner = MeshTopology(V, F).interior_vertices
    assert ob.terms(d)[1] == pytest.approx(np.sum((L @ (V + ob.N * d[:, None]))[inner] ** 2))
    _, g = ob.value_and_grad(d, smooth=1e-3)
    for i in rng.choice(ob.movable_ids, 5, replace=False):
        e = np.zeros(ob.n)
        e[i] = 1e-6
        fd = (ob.value_and_grad(d + e, 1e-3)[0] - ob.value_and_grad(d - e, 1e-3)[0]) / 2e-6
        assert g[i] == pytest.approx(fd, rel=1e-4, abs=1e-5)
    nodes = np.sort(rng.choice(ob.movable_ids, 9, replace=False))
    D = rng.uniform(0, 1, (4, 9))
    full = []
    for row in D:
        dd = d.copy()
        dd[nodes] = row
        full.append(ob.value(dd))
    assert np.allclose(ob.batch_values(d, nodes, D), full, rtol=1e-10)
    with pytest.raises(BolusError, match="smooth_base"):
        SurfaceObjective(Va, F, smooth_base=V[:-1])
