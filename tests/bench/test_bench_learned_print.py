"""A smoke run of the learned print segmentation benchmark (bench/learned_print_bench.py) on one mesh.

``main(["--quick", "--only", "face", ...])``: no training, the ICT face only (13,120 triangles, the
smallest of the four).  The JSON must hold LEARNED, GEOMETRIC and ABCUT with finite figures that add
up, ABcut asked for LEARNED's part count, and the tables must keep their columns.  No timing is asserted.
"""
from __future__ import annotations

import json
import math

import pytest
from paths import import_bench, data_mesh


@pytest.fixture(scope="module")
def lpb():
    return import_bench("learned_print_bench")


@pytest.fixture(scope="module")
def run(lpb, tmp_path_factory):
    data_mesh("ict_face_narrow.obj")  # skips when the mesh is missing
    out = tmp_path_factory.mktemp("learned_print_bench")
    js, md = out / "figures.json", out / "bench.md"
    assert lpb.main(["--quick", "--only", "face", "--json", str(js), "--markdown", str(md)]) == 0
    return json.loads(js.read_text()), md.read_text()


def test_three_methods_with_finite_totals(run):
    data, _ = run
    assert data["training"]["run"] is None  # --quick: the shipped record only
    (mesh,) = data["meshes"]
    assert "error" not in mesh and mesh["triangles"] == 13120
    whole = mesh["whole"]
    assert math.isfinite(whole["objective"]) and whole["objective"] > 0
    by = {m["method"]: m for m in mesh["methods"]}
    assert list(by) == ["LEARNED", "GEOMETRIC", "ABCUT"]  # --quick: no ABcut at GEOMETRIC's count
    for name, m in by.items():
        assert "error" not in m, (name, m)
        assert m["parts"] == len(m["part_rows"]) >= 2
        assert sum(p["triangles"] for p in m["part_rows"]) == mesh["triangles"]
        for k in ("WQ", "WU", "objective", "support_volume_mm3"):
            assert math.isfinite(m["totals"][k]) and m["totals"][k] >= 0
            assert m["totals"][k] == pytest.approx(sum(p[k] for p in m["part_rows"]))
        assert m["totals"]["objective"] == pytest.approx(m["totals"]["WQ"] + m["totals"]["WU"])
        assert m["vs_whole"] == pytest.approx(m["totals"]["objective"] / whole["objective"])
        assert m["segment_s"] > 0 and m["orient_s"] > 0
    for name in ("LEARNED", "GEOMETRIC"):
        m = by[name]
        assert m["clusters"] >= 1 and m["subgraphs"] > 0 and 0.9 < m["usage_rate"] <= 1.0
        assert m["requested"] is None
        # a sub-graph is never split between parts: the parts' sub-graph counts add up to all of them
        assert sum(p["subgraphs"] for p in m["part_rows"]) == m["subgraphs"]
    assert by["ABCUT"]["requested"] == by["LEARNED"]["parts"]
    assert all(p["subgraphs"] is None for p in by["ABCUT"]["part_rows"])


def test_markdown_section_and_tables(lpb, run):
    data, md = run
    assert md.lstrip().startswith("## Learned print segmentation (`bench/learned_print_bench.py`)")
    assert "None of the benchmark's meshes is among them." in md
    for table in (lpb.summary_table(data["meshes"]), lpb.training_table(data["training"])):
        lines = table.markdown().splitlines()
        assert len({line.count("|") for line in lines}) == 1
    rows = lpb.summary_table(data["meshes"]).rows
    assert [r[1] for r in rows] == ["whole model", "LEARNED", "GEOMETRIC", "ABCUT"]
    assert rows[3][4] == f"{data['meshes'][0]['methods'][2]['parts']} ({data['meshes'][0]['methods'][0]['parts']})"


def test_training_lines_flag_a_bench_mesh_in_the_training_set(lpb, run):
    data, _ = run
    shipped = dict(data["training"]["shipped"])
    assert lpb.training_lines({"shipped": shipped, "run": None}, ["fish.obj"])[1].startswith("None of")
    shipped["meshes"] = shipped["meshes"] + ["fish.obj"]
    assert lpb.training_lines({"shipped": shipped, "run": None}, ["fish.obj"])[1] == \
        "NOTE: fish.obj IS in the training set."


def test_cluster_coherence_measures_scattered_clusters(lpb):
    """1 when every cluster is one edge-connected piece; the area share of the largest pieces otherwise."""
    import meshgen

    from bolus_addon.core.mesh.topology import MeshTopology

    V, F = meshgen.grid(4, 1, 40.0)  # 8 triangles in a strip, 10 mm squares
    t = MeshTopology(V, F)
    x = t.centroids[:, 0]
    one_piece = (x > 20).astype(int)
    assert lpb.cluster_coherence(t, one_piece) == 1.0
    scattered = ((x > 10) & (x < 30)).astype(int)  # cluster 0 in two pieces of equal area at the ends
    assert abs(lpb.cluster_coherence(t, scattered) - 0.75) < 1e-12
