"""The bolus library's cache and ranking (core.retrieval; seed ch. 5, SPEC build_library / retrieve)."""
import numpy as np
import pytest
from meshgen import icosphere, torus
from meshfiles import write_binary, write_obj

from bolus_addon.core.retrieval import library as retrieval
from bolus_addon.core.retrieval import skeleton_method
from bolus_addon.core.errors import BolusError


def describe_all(folder, method="SKELETON"):
    keep, todo, gone = retrieval.plan_update(folder, method)
    entries, new, warnings = retrieval.update_library(folder, [(p, p) for p in todo], keep, lambda f, t: None, 0, 1,
                                                      method)
    assert not warnings and set(entries) == {e.file for e in keep + new}
    return keep, new, gone


def test_cache_is_reused_and_redone_for_what_changed(tmp_path, monkeypatch):
    write_obj(tmp_path / "torus.obj", *torus(50.0, 16.0, 32, 12))
    V, F = icosphere(2, 30.0)
    write_binary(tmp_path / "egg.stl", V * np.array([2.0, 1.0, 1.0]), F)
    (tmp_path / "notes.txt").write_text("not a model")
    assert [p.name for p in retrieval.library_files(tmp_path)] == ["egg.stl", "torus.obj"]
    keep, new, gone = describe_all(tmp_path)
    assert (len(keep), len(new), gone) == (0, 2, [])
    cached = retrieval.load_cache(tmp_path, "SKELETON")
    assert set(cached) == {"egg.stl", "torus.obj"}
    for e in new:  # the cached descriptors are the computed ones
        np.testing.assert_array_equal(cached[e.file].descriptor.samples, e.descriptor.samples)
        assert cached[e.file].descriptor.kind == "model" and cached[e.file].descriptor.samples.shape == (64, 3)
    keep, new, gone = describe_all(tmp_path)
    assert (len(keep), len(new), gone) == (2, 0, [])
    write_obj(tmp_path / "torus.obj", *torus(50.0, 20.0, 32, 12))  # changed
    (tmp_path / "egg.stl").unlink()  # removed
    keep, todo, gone = retrieval.plan_update(tmp_path, "SKELETON")
    assert [p.name for p in todo] == ["torus.obj"] and keep == [] and gone == ["egg.stl"]
    # other settings or a damaged cache: everything is redone
    monkeypatch.setitem(skeleton_method.SETTINGS, "samples", 32)
    assert retrieval.load_cache(tmp_path, "SKELETON") == {}
    monkeypatch.setitem(skeleton_method.SETTINGS, "samples", 64)
    assert set(retrieval.load_cache(tmp_path, "SKELETON")) == {"egg.stl", "torus.obj"}
    (tmp_path / retrieval.CACHE_FILE).write_bytes(b"damaged")
    assert retrieval.load_cache(tmp_path, "SKELETON") == {}


def test_descriptor_is_invariant_to_pose_and_scale_and_ranks_itself_first():
    V, F = torus(50.0, 12.0, 40, 14)
    V = V * np.array([1.6, 1.0, 1.0])  # a round torus's repeated eigenvalues make its feature space arbitrary
    a = skeleton_method.model_descriptor(V, F)
    Q, _ = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))
    b = skeleton_method.model_descriptor(2.5 * V @ Q.T + 7.0, F)
    egg = icosphere(3, 30.0)
    c = skeleton_method.model_descriptor(egg[0] * np.array([3.0, 1.0, 0.5]), egg[1])
    ranking = skeleton_method.rank(b, {"torus": a, "egg": c})
    assert ranking[0][0] == "torus" and ranking[0][1] < 0.05 < ranking[1][1]


def test_refusals(tmp_path):
    with pytest.raises(BolusError, match="does not exist"):
        retrieval.library_files(tmp_path / "none")
    with pytest.raises(BolusError, match="holds no models"):
        retrieval.library_files(tmp_path)
    with pytest.raises(BolusError, match="only .obj and .stl"):
        retrieval.read_model(tmp_path / "x.blend")
    d = skeleton_method.model_descriptor(*torus(50.0, 12.0, 24, 8))
    with pytest.raises(BolusError, match="library is empty"):
        skeleton_method.rank(d, {})
    with pytest.raises(BolusError, match="unknown retrieval method 'ICP'"):
        retrieval.plan_update(tmp_path, "ICP")
