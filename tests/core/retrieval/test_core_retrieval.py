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


def quiet(*_):
    return None


def test_views_and_skeleton_share_one_cache_and_keep_each_other(tmp_path):
    write_obj(tmp_path / "torus.obj", *torus(50.0, 16.0, 32, 12))
    V, F = icosphere(2, 30.0)
    write_binary(tmp_path / "egg.stl", V * np.array([2.0, 1.0, 1.0]), F)
    keep, new, _ = describe_all(tmp_path, "VIEWS")
    assert len(new) == 2 and all(e.descriptor.matrix.shape[0] > 30 for e in new)
    describe_all(tmp_path, "SKELETON")
    views_cached = retrieval.load_cache(tmp_path, "VIEWS")  # still there after the skeleton's save
    assert set(views_cached) == {"egg.stl", "torus.obj"}
    for e in new:
        np.testing.assert_array_equal(views_cached[e.file].descriptor.matrix, e.descriptor.matrix)
    assert set(retrieval.load_cache(tmp_path, "SKELETON")) == {"egg.stl", "torus.obj"}
    keep, todo, gone = retrieval.plan_update(tmp_path, "VIEWS")
    assert (len(keep), todo, gone) == (2, [], [])


def test_an_interrupted_build_resumes_and_a_failed_write_keeps_the_old_cache(tmp_path, monkeypatch):
    for k in range(5):
        write_obj(tmp_path / f"t{k}.obj", *torus(50.0, 10.0 + 2 * k, 24, 10))
    monkeypatch.setattr(retrieval, "CHECKPOINT_S", 0.0)
    calls = []

    def stop_after_first_batch(fraction, text):
        calls.append(text)
        if len(calls) == 2:
            raise KeyboardInterrupt  # Esc in the middle of the build

    keep, todo, _ = retrieval.plan_update(tmp_path, "VIEWS")
    with pytest.raises(KeyboardInterrupt):
        retrieval.update_library(tmp_path, [(p, p) for p in todo], keep, stop_after_first_batch, 0, 1, "VIEWS")
    done = retrieval.load_cache(tmp_path, "VIEWS")
    assert 0 < len(done) < 5  # the first batch was saved ...
    keep, todo, _ = retrieval.plan_update(tmp_path, "VIEWS")
    assert len(keep) == len(done) and len(todo) == 5 - len(done)  # ... and only the rest is done again
    retrieval.update_library(tmp_path, [(p, p) for p in todo], keep, quiet, 0, 1, "VIEWS")
    before = (tmp_path / retrieval.CACHE_FILE).read_bytes()

    def full_disk(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full_disk)
    with pytest.raises(BolusError, match="cannot write the library cache .* No space left"):
        retrieval.save_cache(tmp_path, list(retrieval.load_cache(tmp_path, "VIEWS").values()), "VIEWS")
    assert (tmp_path / retrieval.CACHE_FILE).read_bytes() == before and not list(tmp_path.glob("*.tmp"))


def test_models_without_faces_or_broken_are_left_out(tmp_path):
    write_obj(tmp_path / "torus.obj", *torus(50.0, 16.0, 32, 12))
    (tmp_path / "points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    (tmp_path / "broken.stl").write_bytes(b"\x00\x01" * 40)
    keep, todo, _ = retrieval.plan_update(tmp_path, "VIEWS")
    entries, new, warnings = retrieval.update_library(tmp_path, [(p, p) for p in todo], keep, quiet, 0, 1, "VIEWS")
    assert set(entries) == {"torus.obj"}
    assert sorted(w.split(" ")[0] for w in warnings) == ["broken.stl", "flat.obj", "points.obj"]
    assert all("left out of the library" in w for w in warnings)
    (tmp_path / "torus.obj").unlink()
    keep, todo, _ = retrieval.plan_update(tmp_path, "VIEWS")
    with pytest.raises(BolusError, match="no model of the library .* could be described"):
        retrieval.update_library(tmp_path, [(p, p) for p in todo], keep, quiet, 0, 1, "VIEWS")


def test_confidence_is_the_runner_ups_relative_gap():
    assert retrieval.confidence([("a", 0.5), ("b", 1.0)]) == pytest.approx(0.5)
    assert retrieval.confidence([("a", 0.5), ("b", 0.5)]) == 0.0
    assert retrieval.confidence([("a", 0.5)]) == 1.0
