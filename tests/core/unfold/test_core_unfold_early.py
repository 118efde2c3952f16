"""The early decision of `unfold_patch(target_el=...)`: a patch that cannot
meet the EL target in one piece is flagged hopeless after the cheap stages (cut, conformal
start, a short relaxation), before the refinement and the overlap correction; a patch that
can is unfolded exactly as without the target."""
import numpy as np
import pytest
from meshgen import cylinder_piece, degenerate_variants, height_field, spherical_cap

from bolus_addon.core.unfold import unfold
from bolus_addon.core.errors import BolusError
from bolus_addon.core.unfold.unfold import QUICK_GAIN, QUICK_ITERS, unfold_patch

TARGET = 0.02  # 2 %, the max_el


def _pocket():
    """A nostril-like pocket: a Gaussian hollow 15 mm deep and 6 mm wide in a 60 mm sheet
    (angle deficit at its bottom, as much excess around its rim); full pipeline EL 3.8 %."""
    return height_field(lambda x, y: -15.0 * np.exp(-(x * x + y * y) / 36.0), 30, 30, 60.0)


def _strong_cap():
    """A hemisphere (90 degree cap, R 100 mm): full pipeline EL 8.7 %."""
    return spherical_cap(100.0, 90.0, 4)


@pytest.mark.parametrize("make", [_pocket, _strong_cap], ids=["pocket", "hemisphere"])
def test_hopeless_patch_is_flagged_early(make):
    V, F = make()
    quick = unfold_patch(V, F, target_el=TARGET)
    assert quick.hopeless
    assert "target 2 %" in quick.hopeless_reason and "trial relaxation" in quick.hopeless_reason
    assert "angle deficit" in quick.hopeless_reason and "angle excess" in quick.hopeless_reason
    # decided after the trial: no refinement, flip or outline iterations after it
    assert quick.iterations <= QUICK_ITERS
    assert QUICK_GAIN * quick.trial_EL > TARGET
    assert np.isfinite(quick.UV).all() and quick.UV.shape == (len(quick.vert_origin), 2)
    assert quick.EL == pytest.approx(quick.trial_EL)
    # the decision was right: the whole pipeline does not meet the target either, and costs more
    full = unfold_patch(V, F)
    assert full.EL > TARGET
    assert full.iterations > 2 * quick.iterations
    assert full.trial_EL == pytest.approx(quick.trial_EL)


@pytest.mark.parametrize("make", [lambda: spherical_cap(100.0, 30.0, 4), lambda: cylinder_piece()],
                         ids=["mild cap", "cylinder"])
def test_flattenable_patch_is_not_flagged_and_unchanged(make):
    V, F = make()
    u = unfold_patch(V, F, target_el=TARGET)
    assert not u.hopeless and u.hopeless_reason == ""
    assert u.EL < TARGET and u.flipped == 0 and u.overlaps == 0
    ref = unfold_patch(V, F)
    np.testing.assert_array_equal(u.UV, ref.UV)  # the target changes nothing here
    assert u.iterations == ref.iterations


def test_trial_decides_after_the_relaxation_when_it_ends_sooner():
    """A patch whose relaxation converges before QUICK_ITERS is judged on the relaxed pattern."""
    V, F = spherical_cap(100.0, 60.0, 4)  # relaxes in ~20 iterations; full EL 3.6 %
    u = unfold_patch(V, F, target_el=TARGET)
    assert u.hopeless and u.iterations < QUICK_ITERS
    assert f"({u.iterations} iterations)" in u.hopeless_reason
    assert not unfold_patch(V, F, target_el=0.1).hopeless  # a 10 % target it meets


def test_without_relaxation_the_start_is_the_trial():
    V, F = _strong_cap()
    u = unfold_patch(V, F, relax=False, target_el=TARGET)
    assert u.hopeless and u.iterations == 0 and u.trial_EL == pytest.approx(u.EL)


def test_gain_is_read_at_call_time(monkeypatch):
    """QUICK_GAIN is the calibrated bound; a gain of 0 never flags (the rule is the only trigger)."""
    V, F = _pocket()
    monkeypatch.setattr(unfold, "QUICK_GAIN", 0.0)
    assert not unfold_patch(V, F, target_el=TARGET, refine_rounds=0).hopeless


@pytest.mark.parametrize("bad", [0.0, -0.02, float("nan"), float("inf"), "2 %", [0.02]])
def test_bad_target_is_refused(bad):
    V, F = cylinder_piece()
    with pytest.raises(BolusError, match="target_el must be None or an EL fraction above 0"):
        unfold_patch(V, F, target_el=bad)


V0, F0 = height_field(lambda x, y: (x**2 + y**2) / 300.0, nx=8, ny=8)


@pytest.mark.parametrize("name", list(degenerate_variants(V0, F0)))
def test_degenerate_input_with_target(name):
    """Degenerate meshes: the same refusal as without a target, or a sound result."""
    V, F, expect = degenerate_variants(V0, F0)[name]
    if expect is not None:
        with pytest.raises(BolusError, match=expect):
            unfold_patch(V, F, target_el=TARGET)
        return
    u = unfold_patch(V, F, target_el=TARGET)
    assert np.isfinite(u.UV).all() and np.isfinite(u.EL) and np.isfinite(u.trial_EL)


def _ruffle():
    """A ruffled disk z = a r^2 sin(6 phi) (1152 triangles): its rim has far more length than
    a flat disk's, so any flat pattern folds over itself; 14 outline crossings after the
    relaxation, EL 2.8 %: not hopeless by EL / EA."""
    return height_field(lambda x, y: 0.025 * (x * x + y * y) * np.sin(6 * np.arctan2(y, x)), 24, 24, 60.0)


def test_tangled_outline_is_handed_back_with_a_target(monkeypatch):
    """With a target: an outline crossing itself at more than TANGLED_CROSSINGS points (or more
    than TANGLED_OVERLAP of the triangles overlapping) after the relaxation is handed back
    hopeless without the overlap correction (which spent ~4x
    the iterations and still left ~1000 triangles overlapping); without a target the
    correction runs as before."""
    V, F = _ruffle()
    u = unfold_patch(V, F, target_el=0.05)  # trial EL 3.7 %: not an early miss at 5 %
    assert u.hopeless and "outline crosses itself at 14 points" in u.hopeless_reason
    assert "angle excess" in u.hopeless_reason
    assert u.EL < 0.05 and u.overlaps > 0
    full = unfold_patch(V, F)  # no target: today's pipeline, correction included
    assert not full.hopeless and full.overlaps > len(F) // 2  # the correction did not lay it flat
    assert full.iterations > 3 * u.iterations
    assert u.EL < 1.05 * full.EL  # and the figures are no worse for skipping it
    monkeypatch.setattr(unfold, "TANGLED_CROSSINGS", 10**9)
    overlapped = unfold_patch(V, F, target_el=0.05)  # 88 % of its triangles overlap after the relaxation
    assert overlapped.hopeless and "of its triangles overlap others" in overlapped.hopeless_reason
    monkeypatch.setattr(unfold, "TANGLED_OVERLAP", 2.0)  # both rules off: the target changes nothing
    same = unfold_patch(V, F, target_el=0.05)
    np.testing.assert_array_equal(same.UV, full.UV)
    # (patches with a few crossings still get the correction: test_core_unfold's scanned nose
    # patches have 1-2 after the relaxation and come out without overlaps)
