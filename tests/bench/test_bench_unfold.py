"""The benchmark's own arithmetic (bench/benchutil.py, bench/unfold_bench.py), without Blender.

The figures of docs/benchmarks.md rest on it: SLIM's EL-optimal scale must be the exact
minimiser, the ablation's stages must each add one step, the tables must keep their columns.
"""
from __future__ import annotations


import numpy as np
import pytest
from paths import import_bench



@pytest.fixture(scope="module")
def bench():
    """(benchutil, unfold_bench) imported from bench/ (bpy is imported only inside their functions)."""
    return import_bench("benchutil", "unfold_bench")


def el_of(V, F, UV):
    from bolus_addon.core.unfold.measures import length_area_errors

    return length_area_errors(V, F, UV)[0]


def bumpy_grid(rng, n=7):
    """A bumpy height field (V (n*n,3) mm, F) and a distorted flat map of it (UV, 40x too small)."""
    x, y = np.meshgrid(np.linspace(0, 60, n), np.linspace(0, 60, n))
    V = np.stack([x.ravel(), y.ravel(), 5 * np.sin(x.ravel() / 9) * np.cos(y.ravel() / 7)], 1)
    q = np.arange(n * n).reshape(n, n)
    a, b, c, d = q[:-1, :-1].ravel(), q[:-1, 1:].ravel(), q[1:, :-1].ravel(), q[1:, 1:].ravel()
    F = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    UV = (V[:, :2] + rng.normal(0, 1.5, (n * n, 2))) / 40.0
    return V, F, UV


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_el_optimal_scale_is_the_exact_minimiser(bench, seed):
    """EL(s * UV) is convex and piecewise linear in s; the weighted median is its minimum:
    no factor on a fine grid around it, and no breakpoint (a ratio L0/L), does better."""
    _, ub = bench
    V, F, UV = bumpy_grid(np.random.default_rng(seed))
    s = ub.el_optimal_scale(V, F, UV)
    best = el_of(V, F, s * UV)
    assert 30.0 < s < 50.0  # the map is 40x too small, with noise
    for t in np.linspace(0.9 * s, 1.1 * s, 2001):
        assert best <= el_of(V, F, t * UV) + 1e-12
    L0 = np.concatenate([np.linalg.norm(V[F[:, k]] - V[F[:, (k + 1) % 3]], axis=1) for k in range(3)])
    L = np.concatenate([np.linalg.norm(UV[F[:, k]] - UV[F[:, (k + 1) % 3]], axis=1) for k in range(3)])
    breakpoints = np.unique(L0 / L)
    assert any(np.isclose(s, breakpoints, rtol=1e-12))  # the minimum of a piecewise-linear sum is a breakpoint
    assert best <= min(el_of(V, F, t * UV) for t in breakpoints[:: max(1, len(breakpoints) // 200)]) + 1e-12


def test_el_optimal_scale_recovers_a_uniform_scale(bench):
    """A flat patch mapped at 1/25 of its size comes back at exactly 25, EL 0."""
    _, ub = bench
    rng = np.random.default_rng(3)
    V, F, _ = bumpy_grid(rng)
    V[:, 2] = 0.0
    UV = V[:, :2] / 25.0
    s = ub.el_optimal_scale(V, F, UV)
    assert s == pytest.approx(25.0, rel=1e-12)
    assert el_of(V, F, s * UV) == pytest.approx(0.0, abs=1e-12)


def test_el_optimal_scale_of_a_collapsed_map(bench):
    """Every UV edge of zero length: no factor changes EL; 1 is returned (documented)."""
    _, ub = bench
    V, F, _ = bumpy_grid(np.random.default_rng(4))
    assert ub.el_optimal_scale(V, F, np.zeros((len(V), 2))) == 1.0


def test_ablation_stages_add_one_step_each(bench):
    """(a') and (a) differ only in the start; from (a) on each stage switches on exactly one
    more step of the model, ending at the default call; every switch exists on unfold_patch."""
    _, ub = bench
    assert ub.ablation_missing() == []
    kw = {stage: ub.OURS_RUNS[key][1] for stage, key, _, _ in ub.ABLATION}
    assert [(s, b) for s, _, _, b in ub.ABLATION] == [("a", None), ("a'", "a"), ("b", "a"), ("c", "b"), ("d", "c"),
                                                      ("e", "d"), ("e'", "e")]
    full = {"relax": True, "crossed_springs": True, "disturbing_springs": True, "refine_rounds": 3,
            "start": "auto", "method": "lbfgs"}

    def effective(k):
        out = {**full, **kw[k]}
        if not out["relax"]:  # no relaxation: no springs at work, no refinement (unfold_patch ignores it)
            out.update(refine_rounds=0, crossed_springs=False, disturbing_springs=False)
        return out

    def diff(a, b):
        return {k for k in full if effective(a)[k] != effective(b)[k]}

    assert diff("a'", "a") == {"start"}
    assert diff("a", "b") == {"relax"}
    assert diff("b", "c") == {"crossed_springs"}
    assert diff("c", "d") == {"disturbing_springs"}
    assert diff("d", "e") == {"refine_rounds"}
    assert diff("e", "e'") == {"crossed_springs"}
    assert effective("e") == full


def fake_row(name, stages, hopeless=False):
    """A benchmark row with the ablation's runs (EL, EA fractions)."""
    key = {"a'": "start_greedy", "a": "start", "b": "tension", "c": "crossed", "d": "lbfgs0", "e": "default",
           "e'": "no_crossed"}
    methods = {key[s]: {"EL": el, "EA": ea, "flipped": 0, "overlaps": 0, "seconds": t, "warnings": []}
               for s, (el, ea, t) in stages.items()}
    return {"patch": name, "hopeless": hopeless, "methods": methods}


def test_ablation_tables_show_the_change_of_each_stage(bench):
    bu, ub = bench
    stages = {"a'": (0.10, 0.20, 0.1), "a": (0.08, 0.15, 0.1), "b": (0.05, 0.08, 1.0), "c": (0.05, 0.06, 1.1),
              "d": (0.051, 0.061, 1.2), "e": (0.04, 0.05, 1.5), "e'": (0.04, 0.052, 1.4)}
    rows = [fake_row("p", stages), fake_row("q", stages), fake_row("pocket", {"a": (0.3, 0.5, 0.1)}, hopeless=True)]
    md = ub.ablation_table(rows).markdown().splitlines()
    assert md[0].startswith("| patch | stage | EL % | EA % |")
    assert len({line.count("|") for line in md}) == 1  # every row has every column
    b_row = next(line for line in md if "| b |" in line)
    assert "| 5.00 | 8.00 |" in b_row and "| -3.00 | -7.00 |" in b_row  # against (a), not (a')
    a1_row = next(line for line in md if "| a' |" in line)
    assert "| +2.00 | +5.00 |" in a1_row  # (a') against (a)
    effects = ub.stage_effects(rows).rows
    by_step = {r[0].split(" ")[0]: r for r in effects}
    assert by_step["b"][1] == "2"  # the hopeless patch is left out
    assert by_step["c"][2] == "+0.00" and by_step["c"][4] == "0 / 2 / 0"  # crossed springs: EL the same
    assert by_step["c"][5] == "-2.00" and by_step["c"][7] == "2 / 0 / 0"  # ... EA 2 points lower
    assert by_step["e"][4] == "2 / 0 / 0"
    assert by_step["e'"][2] == "+0.00" and by_step["e'"][5] == "+0.20"  # without crossed springs at the end
    assert list(by_step) == ["a'", "b", "c", "d", "e", "e'"]


def test_table_text_and_markdown(bench, tmp_path):
    bu, _ = bench
    t = bu.Table([("name", "<"), ("x", ">"), ("y", ">")])
    t.add("a|b", "1.00", "2")
    t.add_error("broken", "ValueError: no")
    md = t.markdown().splitlines()
    assert md[1] == "|---|---:|---:|"
    assert md[2] == "| a\\|b | 1.00 | 2 |" and md[3] == "| broken | ERROR: ValueError: no |  |"
    text = t.text().splitlines()
    assert text[0] == "name    x y" and text[2] == "a|b  1.00 2"
    with pytest.raises(ValueError):
        t.add("too", "few")
    out = tmp_path / "b.md"
    out.write_text(bu.markdown_header())
    bu.append_markdown(out, "## Section\n\n" + t.markdown())
    body = out.read_text()
    assert body.startswith("# Benchmarks") and "| numpy / scipy / scikit-learn | " + np.__version__ in body
    assert body.rstrip().endswith("| broken | ERROR: ValueError: no |  |")
