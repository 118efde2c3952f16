"""The retrieval benchmark's own parts (bench/retrieval_bench.py) and a smoke run of it.

The figures of docs/benchmarks.md rest on them: the Hu invariants must have their known values on a
disc and a rectangle and not change with scale, rotation and translation (a mirror flips h7 only);
the rasterised library silhouettes must cover the projection; the library must hold three members
per class with the right relevant sets; the corruptions must do what they say; a Blender render
and the rasterised silhouette of the same view must agree (same camera frame, same handedness).
The whole ``--quick`` run takes a few minutes on 2 cores, so it runs only with BOLUS_BENCH_SMOKE=1.
"""
from __future__ import annotations

import json
import math
import os

import meshgen
import numpy as np
import pytest
from paths import import_bench

from bolus_addon.core.mesh.objfile import load_obj


@pytest.fixture(scope="module")
def rb():
    return import_bench("retrieval_bench")


def disc(radius=60.0, size=200, centre=(100.0, 100.0)):
    y, x = np.mgrid[:size, :size] + 0.5
    return (x - centre[0]) ** 2 + (y - centre[1]) ** 2 <= radius ** 2


def rotated_rectangle(a, b, angle_deg, size=300, centre=(150.0, 150.0)):
    """Pixels whose centre lies in an a x b rectangle turned by angle about its centre."""
    y, x = np.mgrid[:size, :size] + 0.5
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    u = c * (x - centre[0]) + s * (y - centre[1])
    v = -s * (x - centre[0]) + c * (y - centre[1])
    return (np.abs(u) <= a / 2) & (np.abs(v) <= b / 2)


def asymmetric_shape():
    """An 'F'-like mask without any mirror symmetry (h7 != 0)."""
    m = np.zeros((160, 160), bool)
    m[20:140, 30:55] = True
    m[20:45, 55:120] = True
    m[70:90, 55:100] = True
    m[120:140, 90:130] = True
    return m


# ------------------------------------------------------------------ Hu invariants


def test_hu_of_a_disc_and_a_rectangle_have_their_known_values(rb):
    h = rb.hu_moments(disc())
    assert h[0] == pytest.approx(1 / (2 * math.pi), rel=2e-3)  # a disc: (mu20 + mu02) / mu00^2 = 1 / (2 pi)
    assert np.all(np.abs(h[1:]) < 1e-12)  # and every other invariant 0 (the pixel disc is symmetric)
    a, b = 120, 40  # an a x b pixel rectangle: mu20 = b a (a^2 - 1) / 12 exactly
    m = np.zeros((100, 200), bool)
    m[30:30 + b, 40:40 + a] = True
    h = rb.hu_moments(m)
    assert h[0] == pytest.approx((a * a - 1 + b * b - 1) / (12 * a * b), rel=1e-12)
    assert h[1] == pytest.approx(((a * a - b * b) / (12 * a * b)) ** 2, rel=1e-12)
    assert np.all(np.abs(h[2:]) < 1e-12)  # symmetric about both axes: no third-order moments


def test_hu_invariance_to_translation_rotation_and_scale(rb):
    base = rotated_rectangle(120, 40, 0)
    h = rb.hu_moments(base)
    shifted = np.roll(np.roll(base, 37, axis=0), -23, axis=1)
    assert np.allclose(rb.hu_moments(shifted), h, rtol=1e-12, atol=1e-15)
    assert np.allclose(rb.hu_moments(np.rot90(base)), h, rtol=1e-12, atol=1e-15)
    twice = np.kron(base, np.ones((2, 2), bool))  # scaled x 2 (pixels of a finer grid)
    assert rb.hu_moments(twice)[:2] == pytest.approx(h[:2], rel=1e-3)
    turned = rotated_rectangle(120, 40, 30)
    assert rb.hu_moments(turned)[:2] == pytest.approx(h[:2], rel=0.01)
    assert rb.hu_distance(rb.hu_moments(turned), h) < 0.01
    assert rb.hu_distance(rb.hu_moments(twice), h) < 0.01
    # different shapes are far apart, and the distance is symmetric and 0 on itself
    d = rb.hu_distance(rb.hu_moments(disc()), h)
    assert d > 0.3 and d == pytest.approx(rb.hu_distance(h, rb.hu_moments(disc())))
    assert rb.hu_distance(h, h) == 0.0


def test_a_mirror_flips_h7_only(rb):
    m = asymmetric_shape()
    h, hm = rb.hu_moments(m), rb.hu_moments(m[:, ::-1])
    assert abs(h[6]) > 1e-9
    assert np.allclose(hm[:6], h[:6], rtol=1e-9) and hm[6] == pytest.approx(-h[6], rel=1e-9)
    f = rb.hu_features(m)  # -sign(h) log10 |h|
    assert f == pytest.approx(-np.sign(h) * np.log10(np.abs(h)))


def test_hu_leaves_out_near_zero_invariants(rb):
    """matchShapes I1: an invariant under 1e-5 in either shape (sign and log are noise there) adds nothing."""
    a = np.array([0.2, 0.01, 1e-3, 1e-4, 3e-9, 1e-6, 2e-9])
    b = a.copy()
    b[4:] = -b[4:]  # the near-zero ones flip sign
    assert rb.hu_distance(a, b) == 0.0
    b[0] = 0.25
    assert rb.hu_distance(a, b) == pytest.approx(abs(1 / math.log10(0.2) - 1 / math.log10(0.25)))
    with pytest.raises(ValueError, match="empty"):
        rb.hu_moments(np.zeros((10, 10), bool))


# ------------------------------------------------------------------ silhouettes


def test_silhouette_of_a_box_and_a_ball(rb):
    V, F = meshgen.box((80.0, 30.0, 20.0), 3)
    top = rb.silhouette(V, F, (0.0, 0.0, 1.0), size=200)  # 80 x 30 seen from above
    rows, cols = np.nonzero(top)
    w, h = np.ptp(cols) + 1, np.ptp(rows) + 1
    assert w == pytest.approx(200 - 4, abs=2) and w / h == pytest.approx(80 / 30, rel=0.03)
    assert top.sum() / (w * h) > 0.98  # a full rectangle
    side = rb.silhouette(V, F, (1.0, 0.0, 0.0), size=200)  # 30 wide, 20 high (z up)
    rows, cols = np.nonzero(side)
    assert (np.ptp(cols) + 1) / (np.ptp(rows) + 1) == pytest.approx(30 / 20, rel=0.03)
    Vs, Fs = meshgen.icosphere(4, 50.0)
    d = np.array([0.3, -0.5, 0.8])
    assert rb.hu_moments(rb.silhouette(Vs, Fs, d / np.linalg.norm(d)))[0] == pytest.approx(1 / (2 * math.pi),
                                                                                          rel=0.01)


def test_silhouette_covers_every_pixel_centre_of_the_projection(rb):
    """One large triangle: exactly the pixels whose centre is inside are set."""
    V = np.array([[0.0, 0.0, 0.0], [100.0, 10.0, 0.0], [30.0, 80.0, 0.0]])
    F = np.array([[0, 1, 2]])
    m = rb.silhouette(V, F, (0.0, 0.0, 1.0), size=120)
    h, w = m.shape
    # the rasteriser's map: x right, z-view up = +y, 2 px margin, scale (size - 5) / longest extent
    s = (120 - 5) / 100.0
    P = (V[:, :2] - V[:, :2].min(axis=0)) * s + 2.0
    y, x = np.mgrid[:h, :w]
    cx, cy = x + 0.5, (h - 1 - y) + 0.5

    def side(a, b):
        return (P[b, 0] - P[a, 0]) * (cy - P[a, 1]) - (P[b, 1] - P[a, 1]) * (cx - P[a, 0])

    e = [side(0, 1), side(1, 2), side(2, 0)]
    inside = (e[0] > 1e-6) & (e[1] > 1e-6) & (e[2] > 1e-6)
    assert inside.sum() > 3000 and np.all(m[inside])
    on = (e[0] >= -1e-6) & (e[1] >= -1e-6) & (e[2] >= -1e-6)  # centres on an edge may go either way
    assert not np.any(m & ~on)


# ------------------------------------------------------------------ the library


def classes():
    return {"bar": meshgen.box((80.0, 20.0, 20.0), 3), "ball": meshgen.icosphere(2, 30.0)}


def test_library_has_three_members_per_class(rb, tmp_path):
    cls = classes()
    lib = rb.build_library(tmp_path / "lib", cls, rng=0)
    assert [m["name"] for m in lib] == [f"{c}_{v}.obj" for c in cls for v in ("original", "turned", "noisy")]
    assert sorted(p.name for p in (tmp_path / "lib").iterdir()) == sorted(m["name"] for m in lib)
    rel = rb.relevant_sets(lib)
    assert rel == {c: {f"{c}_{v}.obj" for v in rb.VARIANTS} for c in cls}
    for m in lib:
        V0, F0 = cls[m["class"]]
        V, F, _ = load_obj(m["path"])
        assert np.array_equal(F, F0) and (m["vertices"], m["triangles"]) == (len(V0), len(F0))
        if m["variant"] == "original":
            assert np.allclose(V, V0, atol=1e-6)
        elif m["variant"] == "turned":  # a similarity: distances scaled by one factor, not just moved
            d0 = np.linalg.norm(V0[F0[:, 0]] - V0[F0[:, 1]], axis=1)
            d = np.linalg.norm(V[F0[:, 0]] - V[F0[:, 1]], axis=1)
            s = d / d0
            assert np.ptp(s) < 1e-5 and rb.TURN_SCALE[0] <= s.mean() <= rb.TURN_SCALE[1]
            A = np.linalg.lstsq(np.c_[V0, np.ones(len(V0))], V, rcond=None)[0][:3] / s.mean()
            assert np.allclose(A @ A.T, np.eye(3), atol=1e-5) and np.linalg.det(A) > 0
            assert not np.allclose(A, np.eye(3), atol=0.05)
        else:  # vertex noise of NOISE_EDGE x the mean edge length per axis
            sigma = rb.NOISE_EDGE * rb.mean_edge_length(V0, F0)
            assert np.std(V - V0) == pytest.approx(sigma, rel=0.2)


def test_library_is_reproducible_and_a_class_does_not_depend_on_the_others(rb, tmp_path):
    cls = classes()
    a = rb.build_library(tmp_path / "a", cls, rng=0)
    b = rb.build_library(tmp_path / "b", {"ball": cls["ball"]}, rng=0)
    c = rb.build_library(tmp_path / "c", cls, rng=1)
    text = {m["name"]: open(m["path"]).read() for m in a}
    assert all(open(m["path"]).read() == text[m["name"]] for m in b)
    assert open(c[4]["path"]).read() != text["ball_turned.obj"]


# ------------------------------------------------------------------ query corruptions and the baseline


def painted(mask, bg=(0.78, 0.84, 0.93), fg=(0.8, 0.62, 0.52)):
    return np.where(mask[..., None], np.rint(255 * np.array(fg)), np.rint(255 * np.array(bg))).astype(np.uint8)


def test_noise_occlusion_and_the_object_mask(rb):
    m = disc(70, 300, (150.0, 140.0))
    grey = np.full((100, 100, 3), 128, np.uint8)  # far from 0 and 255: no clipping
    assert np.std(rb.add_noise(grey, 0.05, 0) - 128.0) == pytest.approx(0.05 * 255, rel=0.05)
    rgb = painted(m)
    noisy = rb.add_noise(rgb, 0.05, 0)
    assert np.array_equal(noisy, rb.add_noise(rgb, 0.05, 0)) and not np.array_equal(noisy, rgb)
    got = rb.object_mask(noisy, (0.78, 0.84, 0.93))  # the baseline's mask survives the noise
    assert (got & m).sum() / (got | m).sum() > 0.97
    occluded, share = rb.occlude(rgb, m, 0.15, 3)
    changed = np.any(occluded != rgb, axis=2)
    rows, cols = np.nonzero(changed)
    assert 0.15 <= share < 0.25 and share == pytest.approx((changed & m).sum() / m.sum(), abs=0.01)
    box = np.zeros_like(changed)
    box[rows.min():rows.max() + 1, cols.min():cols.max() + 1] = True
    assert np.array_equal(changed, box)  # one rectangle ...
    assert np.all(occluded[changed] == np.rint(255 * np.array(rb.OCCLUDER_SRGB)))  # ... of the grey



def test_photo_kinds_do_what_they_say(rb):
    """Each kind of query photo from one render (retrieval_photos.py): the clean one is the render over its
    background, the cropped one has about 20 % of the object out of the frame, the phone one is a 9:16 portrait,
    the blurred one is smoother, the 'light' one has another object colour over a gradient."""
    import retrieval_photos as rp

    H, W = 300, 400
    yy, xx = np.mgrid[:H, :W] + 0.5
    m = (xx - 200) ** 2 + (yy - 150) ** 2 <= 70 ** 2
    rgba = np.zeros((H, W, 4))
    rgba[m] = (0.8, 0.62, 0.52, 1.0)
    light = rgba.copy()
    light[m, :3] = (0.45, 0.52, 0.62)
    bg = (0.78, 0.84, 0.93)
    render = {"class": "ball", "view": "view 1", "background": bg, "light": "studio.sl", "path": "-", "rgba": rgba,
              "rgba_light": light}
    qs = rb.make_queries([render])
    assert [q["condition"] for q in qs] == list(rb.CONDITIONS) == list(rp.KINDS)
    by = {q["condition"]: q for q in qs}
    assert np.array_equal(by["clean"]["rgb"], painted(m, bg))
    assert [q["id"] for q in qs][2] == "ball / view 1 / noise" and by["occlusion"]["occluded_share"] >= 0.15
    left = by["cropped"]["cropped_share"]
    assert 0.2 <= left < 0.25  # about CROPPED of the object out of the frame ...
    obj = rb.object_mask(by["cropped"]["rgb"], bg)
    assert obj.sum() == pytest.approx((1 - left) * m.sum(), rel=0.02)  # ... and what is left is in it
    assert by["phone"]["rgb"].shape == (480, 270, 3)
    assert np.abs(np.diff(by["blur"]["rgb"].astype(float), axis=1)).max() < np.abs(
        np.diff(by["clean"]["rgb"].astype(float), axis=1)).max()
    top, bottom = by["light"]["rgb"][2, 2].astype(float), by["light"]["rgb"][-3, 2].astype(float)
    assert np.abs(top - bottom).max() > 60  # a gradient behind
    assert np.allclose(by["light"]["rgb"][150, 200] / 255, (0.45, 0.52, 0.62), atol=0.01)


def test_baseline_ranks_the_class_of_a_silhouette_first(rb, tmp_path):
    """run_hu on photos painted from silhouettes of the originals (no Blender): every query finds its class."""
    cls = classes()
    lib = rb.build_library(tmp_path / "lib", cls, rng=0)
    rel = rb.relevant_sets(lib)
    d = np.array([0.2, -0.3, 0.9])
    queries = []
    for c, (V, F) in cls.items():
        m = np.pad(rb.silhouette(V, F, d / np.linalg.norm(d), size=240), 30)
        for cond, rgb in (("clean", painted(m)), ("noise", rb.add_noise(painted(m), 0.05, 1))):
            queries.append({"id": f"{c} / v / {cond}", "class": c, "view": "v", "condition": cond, "rgb": rgb,
                            "background": (0.78, 0.84, 0.93)})
    res = rb.run_hu(lib, queries, rel)
    assert [r["first_rank"] for r in res["queries"]] == [1, 1, 1, 1]
    s = rb.summaries(res["queries"])
    assert s["all"]["top1"] == 1.0 and s["all"]["failed"] == 0 and set(s["condition"]) == {"clean", "noise"}
    tm = rb.timing(res)
    sizes = [len(V) for V, _ in cls.values()]
    assert tm["models"]["vertices"] == {"min": min(sizes), "max": max(sizes)}
    assert tm["photos"]["wall_s"]["count"] == 4 and tm["comparisons"]["wall_s"]["mean"] > 0
    ch = rb.chance(queries, [m["name"] for m in lib], rel, draws=50)
    assert 0.0 < ch["ADR"] < 0.8 and ch["MR"] == pytest.approx(3.5, abs=0.5)  # N = 6: a random rank is 3.5


# ------------------------------------------------------------------ Blender


@pytest.mark.blender
def test_render_agrees_with_the_rasterised_silhouette(rb, tmp_path):
    """The query camera and the library silhouettes use one frame: a Workbench render of an asymmetric block
    and its silhouette from the same direction have the same Hu invariants, h7's sign (handedness) included."""
    pytest.importorskip("bpy")
    V, F = meshgen.box((40.0, 30.0, 20.0), 2)
    V = V.copy()
    V[(V[:, 0] > 0) & (V[:, 1] > 0), 2] += 25.0
    V[V[:, 0] > 0, 1] += 10.0
    (r,), seconds = rb.render_queries([("block", V, F, "+y", "+z")], [("v", 30.0, 20.0)], tmp_path)
    assert r["rgb"].shape == (rb.HEIGHT, rb.WIDTH, 3) and seconds > 0
    m = rb.object_mask(r["rgb"], r["background"])
    rows, cols = np.nonzero(m)
    assert rows.min() > 5 and cols.min() > 5 and rows.max() < rb.HEIGHT - 6 and cols.max() < rb.WIDTH - 6
    hq = rb.hu_moments(m)
    hs = rb.hu_moments(rb.silhouette(V, F, np.array(r["direction"])))
    assert hq[:4] == pytest.approx(hs[:4], rel=0.05)
    assert abs(hs[6]) > 1e-9 and np.sign(hq[6]) == np.sign(hs[6])
    assert rb.hu_distance(hq, hs) < 0.02


@pytest.mark.blender
@pytest.mark.skipif(os.environ.get("BOLUS_BENCH_SMOKE") != "1",
                    reason="the --quick retrieval bench takes minutes; set BOLUS_BENCH_SMOKE=1 to run it")
def test_quick_run(rb, tmp_path):
    pytest.importorskip("bpy")
    js, md = tmp_path / "figures.json", tmp_path / "bench.md"
    assert rb.main(["--quick", "--json", str(js), "--markdown", str(md)]) == 0
    data, text = json.loads(js.read_text()), md.read_text()
    kinds = len(rb.CONDITIONS)
    assert data["N"] == 12 and data["queries"]["count"] == 4 * kinds and data["q"] == 3
    for name in (rb.VIEWS_NAME, rb.SEED_NAME, rb.HU_NAME):
        res = data["methods"][name]
        assert "error" not in res, res
        s = res["summary"]["all"]
        assert s["queries"] == 4 * kinds and 0 <= s["ADR"] <= 1 and 2.0 <= s["MR"] <= 11.0 and 0 <= s["LR"] <= 1
        assert len(res["models"]) == 12 and all(m["wall_s"] > 0 for m in res["models"])
    assert [q["models"] for q in data["scale"]["query"]] == list(rb.SCALE_SIZES)
    assert text.lstrip().startswith("## Retrieval from a photo (`bench/retrieval_bench.py`)")
    assert "Ranked first most often: VIEWS: " in text and "; HU: " in text
    for table in text.split("\n\n"):
        if table.startswith("|"):
            assert len({line.count("|") for line in table.splitlines()}) == 1
