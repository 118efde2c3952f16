"""The surface-improvement benchmark (bench/flatten_bench.py): its own measures and a --quick smoke run.

The figures of docs/benchmarks.md rest on them: the bounds check must catch a result that
leaves its bounds, the gain must be FLV after / FLV before, the concave-spot and disk helpers
must find what they say.  No timing is asserted.
"""
from __future__ import annotations

import json
from types import SimpleNamespace

import meshgen
import numpy as np
import pytest
from paths import import_bench


@pytest.fixture(scope="module")
def fb():
    """bench/flatten_bench.py imported (bpy is never imported by it)."""
    return import_bench("flatten_bench")


def test_freeform_patch_has_the_seeds_counts():
    """meshgen.freeform_patch is the Table 4-3-like surface: 89 nodes, 247 edges, 159 faces, one disk, +z normals."""
    from bolus_addon.core.analysis.saliency import analyse
    from bolus_addon.core.mesh.topology import MeshTopology

    V, F = meshgen.freeform_patch()
    topo = MeshTopology(V, F)
    assert (len(V), len(topo.edges), len(F)) == (89, 247, 159)
    assert topo.interior_vertices.sum() == 89 - 17
    assert (topo.face_normals[:, 2] > 0).all()
    s = analyse(V, F, 0.0)
    assert 0.5 < s.flv < 0.9  # the seed's 0.65


def test_check_bounds_catches_every_violation(fb):
    """A sound result passes; a gap above the maximum, a negative gap, a moved border vertex or a move off the
    direction each fail."""
    V, F = meshgen.freeform_patch()
    from bolus_addon.core.mesh.topology import MeshTopology

    topo = MeshTopology(V, F)
    N = topo.vertex_normals
    gap = np.where(topo.interior_vertices, 0.5, 0.0)

    def res(g, W=None):
        return SimpleNamespace(V=V + N * g[:, None] if W is None else W, gap=g, directions=N)

    ok = fb.check_bounds(V, F, res(gap), 1.0)
    assert ok["bounds_ok"] and ok["gap_max"] == pytest.approx(0.5) and ok["gap_mean"] == pytest.approx(0.5)
    inner = int(np.nonzero(topo.interior_vertices)[0][0])
    border = int(np.nonzero(~topo.interior_vertices)[0][0])
    too_far = gap.copy()
    too_far[inner] = 1.5
    negative = gap.copy()
    negative[inner] = -0.1
    moved_border = gap.copy()
    moved_border[border] = 0.2
    sideways = V + N * gap[:, None]
    sideways[inner, 0] += 0.01
    for bad in (res(too_far), res(negative), res(moved_border), res(gap, sideways)):
        assert not fb.check_bounds(V, F, bad, 1.0)["bounds_ok"]


def test_gain_is_the_flv_ratio(fb):
    """gain = FLV after / FLV before (eq. 4-3), also where FLV underflows to 0 in print."""
    from bolus_addon.core.analysis.saliency import flattenability_value

    b, a = {"sum_varpi_raw": 3.9}, {"sum_varpi_raw": 1.2}
    assert fb.gain(b, a, "raw") == pytest.approx(flattenability_value(1.2) / flattenability_value(3.9))
    assert fb.gain({"sum_varpi_3": 60.0}, {"sum_varpi_3": 58.0}, "3") == pytest.approx(4.0)


def test_concave_spot_and_disk_helpers(fb):
    """On a height field with a bump (the 'nose tip') and a dip 20 mm beside it, concave_spot finds the dip's
    lowest vertex; disk_with_vertices hits its target count closely."""
    V, F = meshgen.height_field(lambda x, y: 15 * np.exp(-(x * x + y * y) / 200.0)
                                - 4 * np.exp(-((x - 20) ** 2 + y * y) / 30.0), 40, 40, 100.0)
    tip = int(np.argmax(V[:, 2]))
    c = fb.concave_spot(V, F, tip, (20.0, 0.0))
    assert np.allclose(V[c, :2], [20.0, 0.0], atol=2.6)  # grid step 2.5 mm
    Vd, Fd, r, area = fb.disk_with_vertices(V, F, V[c], 300)
    assert abs(len(Vd) - 300) <= 15 and 0 < r < 90 and len(Fd) > 0


def test_border_distance(fb):
    """Edge-path distance to the border: 0 on it, half the side in the middle of a square grid."""
    V, F = meshgen.grid(10, 10, 100.0)
    d = fb.border_distance(V, F)
    on = (V[:, 0] % 100 == 0) | (V[:, 1] % 100 == 0)
    assert (d[on] == 0).all() and (d[~on] > 0).all()
    assert d[np.argmin(np.linalg.norm(V[:, :2] - 50.0, axis=1))] == pytest.approx(50.0)


def test_quick_run_figures_are_sane(fb, tmp_path):
    """bench --quick on the free-form patch: both methods, bounds hold, FLV does not decrease (raw, the
    optimiser's own scale there), the EL ratio is EL after / EL before, the tables and verdict are written."""
    out, md = tmp_path / "f.json", tmp_path / "b.md"
    md.write_text("# Benchmarks\n\n## Another bench\n\nIts table.\n")
    assert fb.main(["--quick", "--only", "free-form", "--json", str(out), "--markdown", str(md)]) == 0
    data = json.loads(out.read_text())
    (case,) = data["cases"]
    assert case["case"] == "free-form 89" and case["vertices"] == 89 and case["faces"] == 159
    runs = case["runs"]
    assert sorted(r["method"] for r in runs) == ["GRADIENT", "LPSO"]
    for r in runs:
        assert "error" not in r, r.get("error")
        assert r["bounds_ok"] and 0.0 <= r["gap_min"] and r["gap_max"] <= 1.0 + 1e-9
        assert r["boundary_gap_max"] == 0.0
        assert r["gain_raw"] >= 1.0 - 1e-9  # smoothing 0: the optimiser's own measure
        assert r["after"]["sum_varpi_raw"] <= case["before"]["sum_varpi_raw"] + 1e-9
        el0, el1 = case["unfold_before"]["EL"], r["unfold_after"]["EL"]
        assert 0 < el0 < 1 and 0 < el1 < 1 and r["el_ratio"] == pytest.approx(el1 / el0)
        assert r["iterations"] > 0 and r["seconds"] > 0 and r["folded"] == 0
        for key in ("raw", "3"):  # the drop split near / far from the border adds up to the whole drop
            drop = case["before"][f"sum_varpi_{key}"] - r["after"][f"sum_varpi_{key}"]
            assert r[f"drop_{key}_near"] + r[f"drop_{key}_far"] == pytest.approx(drop, abs=1e-9)
    text = md.read_text()
    assert "bench/flatten_bench.py" in text and "seed nose (Table 4-4)" in text
    assert text.count("free-form 89") >= 3 and "Verdict at 1 mm" in text
    assert text.startswith("# Benchmarks\n\n## Another bench\n\nIts table.\n") and text.count(fb.HEADING) == 1
    assert "* GRADIENT: 1 runs at 1 mm" in text and "* LPSO: 1 runs at 1 mm" in text


def test_markdown_section_replaces_its_old_copy(fb, tmp_path):
    """A second run with --markdown replaces the section instead of appending a second copy."""
    md = tmp_path / "b.md"
    md.write_text(f"# Benchmarks\n\n{fb.HEADING}\n\nold figures\n\n## Another bench\n\nIts table.\n")
    assert fb.main(["--quick", "--only", "free-form", "--markdown", str(md)]) == 0
    text = md.read_text()
    assert text.count(fb.HEADING) == 1 and "old figures" not in text and "Verdict at 1 mm" in text
    assert text.rstrip().endswith("## Another bench\n\nIts table.")
