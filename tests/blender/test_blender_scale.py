"""In the Blender layer, `bolus.segment` reuses the last
`bolus.saliency_preview` of exactly the same region and smoothing (in memory, float64,
keyed by `saliency.analysis_key`) and recomputes otherwise; the patches are the same
either way."""
from __future__ import annotations

import numpy as np
import pytest
from bpy_helpers import attr_array, make_object
from meshgen import sheet_with_dome

pytestmark = pytest.mark.blender


@pytest.fixture
def counted(monkeypatch):
    """Count the flattenability analyses segment runs itself (spectral.analyse)."""
    import sys

    calls = []  # the extension may be loaded under another package name: patch every copy
    mods = [m for name, m in list(sys.modules.items()) if name.endswith("core.analysis.spectral")]
    for mod in mods:
        orig = mod.analyse

        def wrapped(*a, _orig=orig, **k):
            calls.append(1)
            return _orig(*a, **k)

        monkeypatch.setattr(mod, "analyse", wrapped)
    return calls


def _labels(bpy, ob):
    return attr_array(ob.data, "bolus_patch", np.int64)


def test_segment_reuses_the_preview_of_the_same_region(scene, counted):
    bpy = __import__("bpy")
    V, F, _ = sheet_with_dome(n_sheet=10, n_dome=8, na=32)
    V = V * [1.3, 1.0, 1.0]  # not round: one best cut
    ob = make_object(bpy, V / 1000.0, F)  # mm -> m (unit scale 1)
    ops = bpy.ops.bolus
    assert ops.segment(patches=3, smoothing_mm=3.0) == {"FINISHED"}
    fresh = _labels(bpy, ob)
    assert len(counted) == 1  # nothing to reuse yet
    assert ops.saliency_preview(smoothing_mm=3.0) == {"FINISHED"}
    assert ops.segment(patches=3, smoothing_mm=3.0) == {"FINISHED"}
    assert len(counted) == 1  # reused
    np.testing.assert_array_equal(_labels(bpy, ob), fresh)
    assert ops.segment(patches=3, smoothing_mm=2.0) == {"FINISHED"}  # another smoothing
    assert len(counted) == 2
    ob.data.vertices[5].co.z += 0.0005  # an edit: the preview no longer holds
    assert ops.segment(patches=3, smoothing_mm=3.0) == {"FINISHED"}
    assert len(counted) == 3
