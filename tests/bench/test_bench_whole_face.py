"""bench/whole_face_bench.py without the long runs: every piece measured on its own, the target
verdict, and its section of the markdown file replaced rather than appended twice."""
from __future__ import annotations

import numpy as np
import pytest
from meshgen import cone
from paths import import_bench

from bolus_addon.core.unfold.sheet_pieces import sheet_pieces


@pytest.fixture(scope="module")
def wf():
    return import_bench("whole_face_bench")


def test_pieces_are_measured_on_their_own_and_judged_against_the_target(wf):
    V, F = cone()
    res = sheet_pieces(V, F, 0.02)
    m = wf.measure_pieces(V, F, res)
    assert m["pieces"] == len(res.unfoldings) and m["partition"] and m["flips"] == 0
    assert m["met"] == (m["worst_el"] <= 0.02 and m["worst_ea"] <= 0.03 and m["overlaps"] == 0)
    # a piece squashed to half its width misses, by its own figures
    res.unfoldings[0].UV = res.unfoldings[0].UV * np.array([1.0, 0.5])
    bad = wf.measure_pieces(V, F, res)
    assert bad["worst_el"] > 0.1 and bad["worst_ea"] > 0.4 and not bad["met"]
    row = {"name": "cone", "faces": len(F), "ours": {"seconds": 31.0, **m}}
    text = wf.table([row]).text()
    assert "cone" in text and text.strip().splitlines()[-1].rstrip().endswith("no")  # over 30 s: not met


def test_the_section_is_replaced_not_appended_again(wf, tmp_path):
    import benchutil

    md = tmp_path / "b.md"
    md.write_text("# Benchmarks\n\n## Before\n\nkeep\n\n" + wf.SECTION + "\n\nold\n\n## After\n\nkeep too\n")
    benchutil.replace_section(md, wf.SECTION, wf.SECTION + "\n\nnew\n")
    text = md.read_text()
    assert text.count(wf.SECTION) == 1 and "new" in text and "old" not in text
    assert text.index("## Before") < text.index(wf.SECTION) < text.index("## After") and text.count("keep") == 2
