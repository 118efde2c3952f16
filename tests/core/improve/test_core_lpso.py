"""Local node selection (Algorithm 4-1) and L-PSO (Algorithm 4-2) on the objective of eq. 4-21:
the selection rules on meshes whose angle-sum signs are known, the
bounds, fixed vertices, never worse, seeded, the T-doubling, a real drop of J, and
degenerate / bad input."""
import numpy as np
import pytest
from meshgen import degenerate_variants, grid, height_field, ring_surface

from bolus_addon.core.errors import BolusError
from bolus_addon.core.improve.objective import SurfaceObjective
from bolus_addon.core.improve.lpso import LPSOState, lpso, lpso_steps, select_nodes

TWO_PI = 2 * np.pi
NA = 12


def cone(h=8.0):
    """A flat disk (rings r = 40, 30, 20 in z = 0) with a regular pyramid on its middle
    (ring r = 10 at z = h / 2, apex at z = h).  Exact angle sums: the apex has a deficit
    (theta < 2 pi), the foot ring r = 20 an excess (theta > 2 pi), the rings r = 30 (plane)
    and r = 10 (on the pyramid's straight edges) are flat (theta = 2 pi).
    Returns V, F and the index arrays of the apex, foot ring, ring 10, ring 30."""
    V, F, ring = ring_surface(np.array([[40.0, 0], [30, 0], [20, 0], [10, h / 2]]), na=NA, pole=True)
    V[-1] = [0, 0, h]
    ids = np.arange(len(V))
    return V, F, int(ids[ring == -1][0]), ids[ring == 2], ids[ring == 3], ids[ring == 1]


def bumpy(nx=14, seed=3, amp=4.0):
    """A free-form 100 mm square with 8 bumps and dents up to ``amp`` mm high, about 8 mm wide
    (nx = 14: 225 vertices, 169 interior, sum varpi 0.87; the seed's free-form example has 0.61)."""
    g = np.random.default_rng(seed)
    c = g.uniform(-40, 40, (8, 2))
    a = g.uniform(-amp, amp, 8)

    def z(x, y):
        return sum(ai * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / 120.0) for ai, (cx, cy) in zip(a, c))

    return height_field(z, nx=nx, ny=nx)


def _upper(obj, gap=1.0):
    return np.where(obj.movable, gap, 0.0)


def test_cone_signs_are_as_built():
    V, F, apex, foot, r10, r30 = cone()
    th = SurfaceObjective(V, F).theta(np.zeros(len(V)))
    assert th[apex] < TWO_PI - 0.1
    assert (th[foot] > TWO_PI + 1e-3).all()
    np.testing.assert_allclose(th[r10], TWO_PI, atol=1e-12)
    np.testing.assert_allclose(th[r30], TWO_PI, atol=1e-12)


def test_cone_tip_deficit_selects_its_neighbours_not_itself():
    V, F, apex, foot, r10, r30 = cone()
    obj = SurfaceObjective(V, F)
    d = np.zeros(obj.n)
    # 37 interior vertices, 13 not flat: top 50 % -> reference = apex + foot ring
    sel = select_nodes(obj, d, top_fraction=0.5)
    np.testing.assert_array_equal(sel, np.sort(np.r_[foot, r10]))   # excess foot ring + apex's one-ring
    assert apex not in sel and not np.isin(r30, sel).any()
    # the default 30 %: ceil(0.3 * 37) = 12 reference nodes, the apex first; the apex's ring is selected
    sel = select_nodes(obj, d)
    assert apex not in sel and np.isin(r10, sel).all()
    assert np.isin(sel, np.r_[foot, r10]).all() and np.isin(foot, sel).sum() >= 11
    assert np.all(np.diff(sel) > 0) and sel.dtype.kind == "i"


def test_saddle_excess_vertices_are_selected():
    V, F = height_field(lambda x, y: (x**2 - y**2) / 60.0, nx=10, ny=10)
    obj = SurfaceObjective(V, F)
    d = np.zeros(obj.n)
    th = obj.theta(d)
    centre = int(np.argmin(np.linalg.norm(V[:, :2], axis=1)))
    assert th[centre] > TWO_PI + 1e-3
    sel = select_nodes(obj, d, top_fraction=1.0)
    excess = np.nonzero(obj.interior & (th > TWO_PI + 1e-9))[0]
    assert centre in sel and np.isin(excess, sel).all()


def test_step4_a_deficit_node_moved_out_is_selected():
    V, F, apex, foot, r10, r30 = cone()
    obj = SurfaceObjective(V, F)
    d = np.zeros(obj.n)
    d[apex] = 0.3
    assert obj.theta(d)[apex] < TWO_PI
    sel = select_nodes(obj, d, top_fraction=0.5)
    assert apex in sel
    assert np.isin(r10, sel).all()


def test_selection_only_movable_vertices():
    V, F, apex, foot, r10, r30 = cone()
    movable = np.ones(len(V), dtype=bool)
    movable[r10[:4]] = False
    obj = SurfaceObjective(V, F, movable=movable)
    sel = select_nodes(obj, np.zeros(obj.n), top_fraction=0.5)
    assert not np.isin(r10[:4], sel).any() and np.isin(r10[4:], sel).all()
    assert obj.interior[sel].all()


def test_flat_patch_selects_nothing_and_stays():
    V, F = grid(8, 8, jitter=0.3)
    obj = SurfaceObjective(V, F)
    d0 = np.zeros(obj.n)
    assert len(select_nodes(obj, d0)) == 0
    s = lpso(obj, d0, _upper(obj))
    assert s.done and s.stop == "nothing to move" and s.iterations == 0 and s.rounds == 0
    np.testing.assert_array_equal(s.d, d0)
    assert s.value == pytest.approx(obj.value(d0))


def test_bounds_fixed_vertices_and_never_worse_on_every_state():
    V, F = bumpy()
    movable = np.ones(len(V), dtype=bool)
    movable[::7] = False
    obj = SurfaceObjective(V, F, movable=movable)
    upper = _upper(obj, 0.8)
    d0 = np.zeros(obj.n)
    J0 = obj.value(d0)
    states = list(lpso_steps(obj, d0, upper, rng=1, particles=12, iterations=20, max_iterations=120, chunk=10,
                             eps=0.0))
    assert [s.done for s in states].count(True) == 1 and states[-1].done
    assert [s.iterations for s in states[:-1]] == list(range(10, states[-1].iterations + 1, 10))
    assert states[-1].iterations == 120 and states[-1].stop == "max_iterations"
    for s in states:
        assert isinstance(s, LPSOState)
        assert np.all(s.d >= 0) and np.all(s.d <= upper)
        assert np.all(s.d[~obj.movable] == 0)          # boundary and non-movable vertices never move
        assert s.value <= J0 + 1e-9 * abs(J0)
        assert s.value == pytest.approx(obj.value(s.d), rel=1e-9)
    # snapshots: an early state is not changed by the later ones
    assert states[0].iterations == 10 and states[-1].iterations > 10
    # the best so far never gets worse
    vals = [s.value for s in states]
    assert all(b <= a + 1e-9 * abs(a) for a, b in zip(vals, vals[1:]))
    last = states[-1]
    assert last.history[0] == pytest.approx(J0) and last.history[-1] == pytest.approx(last.value)
    assert len(last.history) == last.rounds + 1


def test_start_outside_the_box_is_projected_and_non_movable_stay_put():
    V, F = bumpy(nx=10)
    obj = SurfaceObjective(V, F)
    upper = _upper(obj, 0.5)
    d0 = np.where(obj.movable, 0.9, 0.0)            # above the max gap: projected to 0.5
    d0[obj.movable_ids[0]] = -0.2                   # below 0: projected to 0
    s = lpso(obj, d0, upper, rng=0, particles=8, iterations=10, max_iterations=40)
    assert np.all(s.d >= 0) and np.all(s.d <= upper) and np.all(s.d[~obj.movable] == 0)
    assert s.history[0] == pytest.approx(obj.value(np.clip(d0, 0, upper)))


def test_same_seed_same_result_other_seed_differs():
    V, F = bumpy(nx=10)
    obj = SurfaceObjective(V, F)
    kw = dict(particles=10, iterations=15, max_iterations=60)
    a = lpso(obj, np.zeros(obj.n), _upper(obj), rng=7, **kw)
    b = lpso(SurfaceObjective(V, F), np.zeros(obj.n), _upper(obj), rng=7, **kw)
    c = lpso(obj, np.zeros(obj.n), _upper(obj), rng=8, **kw)
    np.testing.assert_array_equal(a.d, b.d)
    assert a.value == b.value and a.iterations == b.iterations and a.evaluations == b.evaluations
    assert not np.array_equal(a.d, c.d)
    g = np.random.default_rng(7)
    e = lpso(obj, np.zeros(obj.n), _upper(obj), rng=g, **kw)   # a Generator is accepted
    np.testing.assert_array_equal(a.d, e.d)


def test_T_doubling_when_the_first_T_finds_nothing_better():
    # J = mu3 sum d^2 only: d = 0 is the optimum, so no swarm can find anything better
    V, F = bumpy(nx=10)
    obj = SurfaceObjective(V, F, mu=(0.0, 0.0, 1.0, 0.0))
    d0 = np.zeros(obj.n)
    s = lpso(obj, d0, _upper(obj), rng=0, particles=6, iterations=4, max_iterations=500)
    assert s.selected > 0
    assert s.doublings >= 2 and s.rounds == 0
    # T doubled k times (T = 4, 8, 16, ...): a swarm that collapsed ends at t = T, else the cap ends it
    assert (s.stop, s.iterations) in (("stalled", 4 * 2 ** s.doublings), ("max_iterations", 500))
    np.testing.assert_array_equal(s.d, d0)
    assert s.value == 0.0 and s.history == [0.0]
    # with a cap the run ends there
    s = lpso(obj, d0, _upper(obj), rng=0, particles=6, iterations=4, max_iterations=10)
    assert s.iterations == 10 and s.stop == "max_iterations" and s.doublings == 2  # at t = 4 and 8


def test_J_drops_on_a_bumpy_surface():
    V, F = bumpy()
    obj = SurfaceObjective(V, F)
    d0 = np.zeros(obj.n)
    J0, t0 = obj.value(d0), obj.terms(d0)
    s = lpso(obj, d0, _upper(obj), rng=0, particles=20, iterations=30, max_iterations=400)
    t1 = obj.terms(s.d)
    msg = (f"J {J0:.3f} -> {s.value:.3f}, sum varpi {t0[0]:.4f} -> {t1[0]:.4f}, {s.iterations} iterations, "
           f"{s.rounds} rounds, stop {s.stop}, largest gap {s.d.max():.3f} mm")
    assert s.value == pytest.approx(obj.value(s.d), rel=1e-12), msg
    assert s.value < 0.96 * J0, msg
    assert t1[0] < 0.93 * t0[0], msg            # the flattenability term itself drops
    assert s.rounds >= 2 and s.d.max() > 0.01, msg
    assert s.iterations <= 400 and s.evaluations >= 20 * s.iterations
    # the selection is refreshed between rounds: a vertex outside the first round's nodes moved too
    assert not np.isin(np.nonzero(s.d > 0)[0], select_nodes(obj, d0)).all(), msg


def test_eps_rule_stops_early_and_zero_eps_runs_longer():
    V, F = bumpy(nx=10)
    obj = SurfaceObjective(V, F)
    kw = dict(rng=2, particles=10, iterations=10, max_iterations=300)
    loose = lpso(obj, np.zeros(obj.n), _upper(obj), eps=0.5, **kw)
    assert loose.stop == "converged" and loose.rounds == 1 and loose.iterations == 10 * 2 ** loose.doublings
    tight = lpso(obj, np.zeros(obj.n), _upper(obj), eps=0.0, **kw)
    assert tight.rounds > loose.rounds and tight.value <= loose.value


@pytest.mark.parametrize("bad, says", [
    ("d0_shape", "d0 must be an array"),
    ("upper_nan", "non-finite"),
    ("upper_negative", "upper must be >= 0"),
    ("particles", "particles"),
    ("iterations", "iterations"),
    ("chunk", "chunk"),
    ("max_iterations", "max_iterations"),
    ("eps", "eps"),
    ("top_fraction", "top_fraction"),
])
def test_bad_arguments_are_refused(bad, says):
    V, F = bumpy(nx=6)
    obj = SurfaceObjective(V, F)
    d0, upper, kw = np.zeros(obj.n), _upper(obj), {}
    if bad == "d0_shape":
        d0 = np.zeros(3)
    elif bad == "upper_nan":
        upper = np.where(obj.movable, np.nan, 0.0)
    elif bad == "upper_negative":
        upper = np.full(obj.n, -1.0)
    else:
        kw = {bad: {"particles": 1, "iterations": 0, "chunk": 2.5, "max_iterations": np.inf, "eps": np.inf,
                    "top_fraction": 0.0}[bad]}
    with pytest.raises(BolusError, match=says):
        lpso(obj, d0, upper, **kw)


def test_select_nodes_refuses_bad_arguments():
    V, F = bumpy(nx=6)
    obj = SurfaceObjective(V, F)
    with pytest.raises(BolusError, match="top_fraction"):
        select_nodes(obj, np.zeros(obj.n), top_fraction=1.5)
    with pytest.raises(BolusError, match="d must be"):
        select_nodes(obj, np.zeros(obj.n + 1))
    d = np.zeros(obj.n)
    d[obj.movable_ids[0]] = np.inf
    with pytest.raises(BolusError, match=f"vertex {obj.movable_ids[0]}"):
        select_nodes(obj, d)


BASE = bumpy(nx=8)
CASES = degenerate_variants(*BASE)


@pytest.mark.parametrize("name", sorted(CASES))
def test_degenerate_meshes(name):
    V, F, says = CASES[name]
    if says not in (None, "non-manifold"):
        with pytest.raises(BolusError, match=says):
            SurfaceObjective(V, F)
        return
    # needle triangle and a non-manifold fin: sound; the fin's vertices are not interior, so never move
    obj = SurfaceObjective(V, F)
    upper = _upper(obj)
    sel = select_nodes(obj, np.zeros(obj.n))
    assert obj.interior[sel].all()
    s = lpso(obj, np.zeros(obj.n), upper, rng=0, particles=8, iterations=10, max_iterations=60)
    assert np.isfinite(s.d).all() and np.isfinite(s.value)
    assert np.all(s.d >= 0) and np.all(s.d <= upper) and np.all(s.d[~obj.interior] == 0)
    assert s.d[len(BASE[0]):].max(initial=0.0) == 0.0
    assert s.value <= obj.value(np.zeros(obj.n)) + 1e-9
