"""Time limits: a job that cannot fit is refused, any other runs and stops at the limit.

`core.budget` estimates a step's time from the triangle counts; an operator whose LOWER BOUND
(estimate / OVER_ESTIMATE) is over the limit refuses before the long work, with the figures and
what to do; otherwise it starts and its `Deadline` stops it at the limit, nothing changed.  The
limit is 60 s (`budget.BUDGET_S`), the sidebar's, or ``BOLUS_TIME_BUDGET_S``: here it is lowered
on small meshes (the 520k-face range scan itself is in bench/rangescan_bench.py).
"""
from __future__ import annotations

import re
import sys

import numpy as np
import pytest
from bpy_helpers import assert_same_object, make_object, object_snapshot
from meshgen import spherical_cap

from bolus_addon.core import budget
from bolus_addon.core.errors import BolusError

ENV = budget.BUDGET_ENV


# --------------------------------------------------------------------------- core (no bpy)
def test_estimate_grows_with_the_pieces_and_inverts(monkeypatch):
    monkeypatch.delenv(ENV, raising=False)
    for step, (T, M, p) in budget.COSTS.items():
        assert budget.estimate_s(step, M) == pytest.approx(T)
        assert budget.estimate_s(step, [M, M]) == pytest.approx(2 * T)  # pieces one after another
        n = budget.max_triangles(step, 30.0)
        assert budget.estimate_s(step, n) <= 30.0 + 1e-9 < budget.estimate_s(step, n + max(n // 100, 1))
        big = [10 * M, M]  # over 30 s for every step
        r = budget.decimate_ratio(step, big, 30.0)
        assert 0 < r < 1
        assert budget.estimate_s(step, [int(r * m) for m in big]) <= 30.0  # the advised ratio fits
        assert budget.decimate_ratio(step, [10], 30.0) == 1.0


def test_budget_from_the_environment(monkeypatch):
    monkeypatch.delenv(ENV, raising=False)
    assert budget.budget_s() == budget.BUDGET_S == 60.0
    monkeypatch.setenv(ENV, "2.5")
    assert budget.budget_s() == 2.5
    for off in ("off", "0", "none"):
        monkeypatch.setenv(ENV, off)
        assert budget.budget_s() is None
        assert budget.check_budget("unfold", [10 ** 9], "huge", "do less") > 1e6  # no refusal when off
    for bad in ("soon", "-3", "nan"):
        monkeypatch.setenv(ENV, bad)
        with pytest.raises(BolusError, match=ENV):
            budget.budget_s()


def test_refusal_names_the_figures_and_what_to_do(monkeypatch):
    monkeypatch.delenv(ENV, raising=False)
    sizes = [125_188, 121_166, 67_063]
    with pytest.raises(BolusError) as exc:
        budget.check_budget("unfold", sizes, "the region has 313,417 triangles in 3 islands",
                            "select the treatment area first (Select Treatment Area)")
    msg = str(exc.value)
    for part in ("313,417 triangles in 3 islands", "largest piece 125,188 triangles", "Unfold Patches would take",
                 "s left of the 60 s budget after reading", "not started", "Select Treatment Area", "Decimate modifier, ratio 0."):
        assert part in msg, (part, msg)
    # within the budget: the estimate, no refusal
    assert budget.check_budget("unfold", [500], "small", "nothing") < 1.0
    with pytest.raises(BolusError, match="no time estimate"):
        budget.check_budget("teleport", [5], "x", "y")


# --------------------------------------------------------------------------- operators (bpy)
def cap_object(bpy, scene):
    """A spherical cap (radius 60 mm, 1,3xx triangles) in a mm scene: an open skin-like region."""
    V, F = spherical_cap(60.0, 50.0, 4)
    scene.unit_settings.scale_length = 0.001
    return make_object(bpy, V, F.tolist(), name="cap")


def write_patches(bpy, ob, name="bolus_patch"):
    """Two patches (x < 0, x >= 0) as a face attribute, as Segment writes them."""
    me = ob.data
    c = np.array([p.center[0] for p in me.polygons])
    attr = me.attributes.new(name, "INT", "FACE")
    attr.data.foreach_set("value", (c >= 0).astype(np.int32))
    me.update()


def refuses_over_budget(bpy, monkeypatch, ob, op, match, **kw):
    """op refuses (the source unchanged, no new object) under a budget of 1 ms; finishes under the default."""
    before, objects = object_snapshot(ob), set(bpy.data.objects.keys())
    monkeypatch.setenv(ENV, "0.001")
    with pytest.raises(RuntimeError, match=match):
        getattr(bpy.ops.bolus, op)(**kw)
    assert_same_object(before, object_snapshot(ob))
    assert set(bpy.data.objects.keys()) == objects
    monkeypatch.delenv(ENV)
    assert getattr(bpy.ops.bolus, op)(**kw) == {"FINISHED"}


@pytest.mark.blender
def test_unfold_refuses_over_budget(bpy_addon, scene, monkeypatch):
    bpy = bpy_addon
    ob = cap_object(bpy, scene)
    write_patches(bpy, ob)
    refuses_over_budget(bpy, monkeypatch, ob, "unfold",
                        r"the region has [\d,]+ triangles in 2 islands .*Unfold Patches would take about .* over the "
                        r"0 s budget, so it was not started.*Select Treatment Area.*Decimate modifier, ratio",
                        max_el=0.0)
    assert bpy.data.objects.get("cap_pattern") is not None


@pytest.mark.blender
def test_improve_refuses_over_budget(bpy_addon, scene, monkeypatch):
    bpy = bpy_addon
    ob = cap_object(bpy, scene)
    refuses_over_budget(bpy, monkeypatch, ob, "improve_flattenability",
                        r"Improve Flattenability would take about .* not started.*Select Treatment Area",
                        max_gap_mm=0.5)


@pytest.mark.blender
def test_smooth_cuts_refuses_over_budget(bpy_addon, scene, monkeypatch):
    bpy = bpy_addon
    ob = cap_object(bpy, scene)
    write_patches(bpy, ob)
    refuses_over_budget(bpy, monkeypatch, ob, "smooth_cuts", r"the patches of 'cap' have [\d,]+ triangles.*Smooth "
                        r"Cut Lines would take about .* not started")


@pytest.mark.blender
def test_print_segment_refuses_over_budget(bpy_addon, scene, monkeypatch):
    bpy = bpy_addon
    ob = cap_object(bpy, scene)
    refuses_over_budget(bpy, monkeypatch, ob, "print_segment", r"Split into Print Parts would take about .* not "
                        r"started.*Make Bolus", parts=2)


def test_make_shell_refuses_over_budget_with_a_resolution_that_fits(monkeypatch):
    from bolus_addon.core.solid.shell import MIN_VOXELS_ACROSS, make_shell

    V, F = spherical_cap(60.0, 50.0, 4)
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    est = budget.estimate_s("make_shell", budget.shell_cells(area, 0.5))
    assert est > budget.estimate_s("make_shell", budget.shell_cells(area, 1.0))  # finer costs more
    limit = budget.lower_bound_s(est) / 1.5  # even the lower bound is over it
    monkeypatch.setenv(ENV, f"{limit:.6f}")
    with pytest.raises(BolusError, match=r"a 5 mm wall on the region .* cm²\) at 0.5 mm: Make Bolus would take about "
                                         r".* not started: choose a resolution of ([0-9.]+) mm or coarser") as exc:
        make_shell(V, F, 5.0, 0.0, 0.5)
    coarse = float(re.search(r"resolution of ([0-9.]+) mm", str(exc.value)).group(1))
    assert 0.5 < coarse <= 5.0 / MIN_VOXELS_ACROSS
    assert budget.lower_bound_s(budget.check_grid_budget(area, 5.0, coarse, MIN_VOXELS_ACROSS, "x", len(F))) <= limit
    # no resolution keeps 4 voxels across the wall within a tiny budget: a smaller region
    monkeypatch.setenv(ENV, "0.001")
    with pytest.raises(BolusError, match=r"select a smaller region .* fewer than 4 voxels across the 5 mm wall"):
        make_shell(V, F, 5.0, 0.0, 0.5)


@pytest.mark.blender
def test_make_shell_operator_refuses_over_budget(bpy_addon, scene, monkeypatch):
    bpy = bpy_addon
    ob = cap_object(bpy, scene)
    refuses_over_budget(bpy, monkeypatch, ob, "make_shell", r"Make Bolus (would take about .* not started|stopped at "
                        r"the time limit of 0.001 s after .* nothing was changed)",
                        thickness_mm=5.0, resolution_mm=1.25)
    assert bpy.data.objects.get("cap_bolus") is not None


# --------------------------------------------------------------------------- the user's time limit
def test_time_limit_argument_and_its_precedence(monkeypatch):
    monkeypatch.delenv(ENV, raising=False)
    assert budget.budget_s(None) == budget.BUDGET_S
    assert budget.budget_s(120.0) == 120.0
    assert budget.budget_s(0.0) is None and budget.budget_s(float("inf")) is None  # no limit
    with pytest.raises(BolusError, match="time limit"):
        budget.budget_s(float("nan"))
    with pytest.raises(BolusError, match=r"Time limit \(s\) in the Bolus sidebar"):
        budget.check_budget("unfold", [10 ** 6], "huge", "do less", limit=30.0)
    assert budget.check_budget("unfold", [10 ** 6], "huge", "do less", limit=0.0) > 60.0  # 0: runs, however long
    monkeypatch.setenv(ENV, "off")  # the environment wins (tests, batch runs)
    assert budget.check_budget("unfold", [10 ** 6], "huge", "do less", limit=30.0) > 60.0


@pytest.mark.blender
def test_the_sidebar_time_limit_decides(bpy_addon, scene, monkeypatch):
    """Scene.bolus.time_limit_s (the sidebar's Time limit (s)): a tiny one refuses Unfold, or stops Make
    Bolus (whose lower bound fits 1 ms here), with the way out named; 0 lets them run."""
    monkeypatch.delenv(ENV, raising=False)
    bpy = bpy_addon
    ob = cap_object(bpy, scene)
    write_patches(bpy, ob)
    before = object_snapshot(ob)
    scene.bolus.time_limit_s = 0.001
    for op, kw in (("unfold", {"max_el": 0.0}), ("make_shell", {"thickness_mm": 5.0, "resolution_mm": 1.25})):
        with pytest.raises(RuntimeError, match=r"(not started|stopped at the time limit).*Time limit \(s\) in the Bolus "
                                               r"sidebar, 0 = no limit"):
            getattr(bpy.ops.bolus, op)(**kw)
    assert_same_object(before, object_snapshot(ob))
    assert bpy.data.objects.get("cap_pattern") is None and bpy.data.objects.get("cap_bolus") is None
    scene.bolus.time_limit_s = 0.0
    assert bpy.ops.bolus.unfold(max_el=0.0) == {"FINISHED"}
    assert bpy.ops.bolus.make_shell(thickness_mm=5.0, resolution_mm=1.25) == {"FINISHED"}


# --------------------------------------------------------------------------- stopping at the limit
def test_deadline_passes_progress_on_and_stops_past_the_limit():
    now = [100.0]
    seen = []
    d = budget.Deadline(lambda f, t: seen.append((f, t)), 5.0, "Unfold Patches", clock=lambda: now[0])
    d(0.1, "patch 1/3")
    now[0] = 104.9
    d(0.3)  # within the limit: passed on, no stop
    assert seen == [(0.1, "patch 1/3"), (0.3, "")]
    now[0] = 105.2
    with pytest.raises(budget.TimeLimitReached, match=r"Unfold Patches stopped at the time limit of 5 s after 5.2 s, "
                                                      r"40 % done, at 'patch 1/3'; nothing was changed: .*Time limit"):
        d(0.4)
    assert isinstance(budget.TimeLimitReached("x"), BolusError)
    budget.Deadline(None, None, "x", clock=lambda: 1e9)(0.5)  # no limit: never stops


def test_a_job_whose_estimate_is_over_the_limit_but_may_fit_is_not_refused(monkeypatch):
    """The size-only estimate over the limit is no reason to refuse: only the lower bound is."""
    monkeypatch.delenv(ENV, raising=False)
    n = budget.max_triangles("unfold", 120.0)  # about 2 min estimated: over 60 s, lower bound 3 s
    assert budget.check_budget("unfold", [n], "x", "y") > 60.0
    assert budget.check_grid_budget(1.0e5, 10.0, 0.5, 4, "x") > 0  # a 1,000 cm2 chest at 0.5 mm starts


@pytest.mark.blender
@pytest.mark.parametrize("op, kw", [("unfold", {"max_el": 0.0}), ("make_shell", {"thickness_mm": 5.0, "resolution_mm": 1.25}),
                                    ("improve_flattenability", {"max_gap_mm": 0.5}), ("smooth_cuts", {})])
def test_a_started_job_stops_cleanly_at_the_limit(bpy_addon, scene, monkeypatch, op, kw):
    """Nothing is refused (OVER_ESTIMATE huge), the limit is 1 ms: each job starts, stops at its
    first progress call past the limit with an ERROR saying how far it got, nothing changed."""
    bpy = bpy_addon
    ob = cap_object(bpy, scene)
    write_patches(bpy, ob)
    for name, module in list(sys.modules.items()):  # the add-on's copy of core.budget too
        if name.endswith("core.budget"):
            monkeypatch.setattr(module, "OVER_ESTIMATE", 1e12)
    monkeypatch.setenv(ENV, "0.001")
    before, objects = object_snapshot(ob), set(bpy.data.objects.keys())
    with pytest.raises(RuntimeError, match=r"stopped at the time limit of 0.001 s after .* % done.*nothing was changed"):
        getattr(bpy.ops.bolus, op)(**kw)
    assert_same_object(before, object_snapshot(ob))
    assert set(bpy.data.objects.keys()) == objects
