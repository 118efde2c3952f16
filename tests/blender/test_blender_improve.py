"""`bolus.improve_flattenability` (SPEC): the `<name>_improved` object.

The operator's numbers are the core's (`core.improve.improve_flattenability` on the same
world-mm region): these tests check what the Blender layer adds -- the copy and its transform,
units, which vertices move and along what, the air-gap attribute and colours, the figures,
Edit Mode, patches, refusals, undo -- and that the improved object goes through Unfold,
Make Bolus and Export Pattern like any skin.
"""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from bpy_helpers import assert_same_object, attr_array, enter_edit_mode_with_faces, make_object, object_snapshot
from meshgen import degenerate_variants, grid, height_field

pytestmark = pytest.mark.blender

GAP = 1.0


def bumpy(n=10, size=60.0, noise=0.4, rng=0):
    """A 60 mm height field with a smooth bump and scan-like noise on the interior z (mm)."""
    V, F = height_field(lambda x, y: 8.0 * np.exp(-(x * x + y * y) / 400.0), nx=n, ny=n, size=size)
    inner = (np.abs(V[:, 0]) < size / 2 - 1e-9) & (np.abs(V[:, 1]) < size / 2 - 1e-9)
    V[inner, 2] += np.random.default_rng(rng).uniform(-noise, noise, inner.sum())
    return V, F


@pytest.fixture
def raw(bpy_addon, scene):
    """Angle sums of the raw mesh (smoothing 0): the noise is what the optimiser can remove."""
    scene.bolus.smoothing_mm = 0.0
    yield scene
    bpy_addon.context.scene.bolus.property_unset("smoothing_mm")  # (undo reloads the scene)


def local_co(ob) -> np.ndarray:
    me = ob.data
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def world_mm(bpy, ob) -> np.ndarray:
    M = np.array(ob.matrix_world)
    mm = bpy.context.scene.unit_settings.scale_length * 1000.0
    return (local_co(ob) @ M[:3, :3].T + M[:3, 3]) * mm


def interior_mask(F, n) -> np.ndarray:
    """(n,) bool: vertices on no boundary edge (every edge of theirs in two triangles)."""
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    out = np.ones(n, dtype=bool)
    out[u[c == 1].ravel()] = False
    return out


def core_result(bpy, ob, F, labels=None, method="GRADIENT", seed=0):
    """The core's Improvement on the same world-mm surface the operator reads."""
    from bolus_addon.core.improve.improve import improve_flattenability

    return improve_flattenability(world_mm(bpy, ob), F, GAP, method=method, rng=seed,
                                  smoothing_mm=bpy.context.scene.bolus.smoothing_mm, patch_labels=labels)


def lines(out: str, kind: str) -> list[str]:
    return [ln.removeprefix(kind + ": ") for ln in out.splitlines() if ln.startswith(kind + ": ")]


# =========================================================================== the object
@pytest.mark.smoke
@pytest.mark.parametrize("scale_length, transformed", [(0.001, False), (0.01, True)], ids=["mm", "cm_transformed"])
def test_improved_copy_is_the_cores_surface(bpy_addon, raw, capfd, scale_length, transformed):
    """A copy with the source's polygons, attributes and transform; only interior vertices moved,
    each along the core's direction by 0..max gap, and `bolus_air_gap` is the distance moved in mm
    (a scene of 1 unit = 1 cm and a rotated, non-uniformly scaled, moved object included)."""
    bpy = bpy_addon
    V, F = bumpy()
    ob = make_object(bpy, V / (scale_length * 1000.0), F, scale_length=scale_length)
    if transformed:
        ob.rotation_euler = (0.4, -0.3, 1.1)
        ob.scale = (1.3, 0.8, 1.1)
        ob.location = (2.0, -1.0, 0.5)
        bpy.context.view_layer.update()
    ob.data.uv_layers.new(name="UVMap")
    ob.data.attributes.new("user_weight", "FLOAT", "POINT").data.foreach_set("value", np.arange(len(V), dtype=float))
    before = object_snapshot(ob)
    capfd.readouterr()
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    out = capfd.readouterr().out
    assert_same_object(before, object_snapshot(ob))  # the source is never modified
    imp = bpy.data.objects["skin_improved"]
    assert imp.data is not ob.data and imp.users_collection[0] == ob.users_collection[0]
    np.testing.assert_array_equal(np.array(imp.matrix_world), np.array(ob.matrix_world))
    me = imp.data
    assert len(me.polygons) == len(F) and "UVMap" in me.uv_layers
    np.testing.assert_array_equal(attr_array(me, "user_weight"), np.arange(len(V)))
    a = me.attributes["bolus_air_gap"]
    assert (a.data_type, a.domain) == ("FLOAT", "POINT")
    assert me.color_attributes.active_color.name == "bolus_air_gap_color"

    res = core_result(bpy, ob, F)
    W0, W1 = world_mm(bpy, ob), world_mm(bpy, imp)
    gap = attr_array(me, "bolus_air_gap")
    tol = 2e-4 * max(1.0, scale_length * 1000.0)  # float32 positions
    np.testing.assert_allclose(W1, res.V, atol=tol)
    np.testing.assert_allclose(gap, res.gap, atol=1e-6)
    moved = W1 - W0
    dist = np.linalg.norm(moved, axis=1)
    np.testing.assert_allclose(dist, gap, atol=tol)  # the gap is the distance moved, in mm
    assert gap.min() >= 0.0 and gap.max() <= GAP + 1e-6 and gap.max() > 0.05
    interior = interior_mask(F, len(V))
    assert np.all(dist[~interior] <= tol) and np.all(gap[~interior] == 0.0)
    big = dist > 0.05
    along = np.einsum("ij,ij->i", moved[big], res.directions[big]) / dist[big]
    assert along.min() > 0.999  # outward along the core's direction, never inward

    props = ("bolus_source", "bolus_max_gap_mm", "bolus_FLV_before", "bolus_FLV_after", "bolus_sum_varpi_before",
             "bolus_sum_varpi_after", "bolus_max_air_gap_mm", "bolus_improve_table")
    assert all(k in imp for k in props)
    assert imp["bolus_source"] == "skin" and imp["bolus_max_gap_mm"] == GAP
    assert imp["bolus_FLV_after"] >= imp["bolus_FLV_before"]
    assert imp["bolus_sum_varpi_after"] < imp["bolus_sum_varpi_before"]  # the noise is what it removes
    assert imp["bolus_max_air_gap_mm"] == pytest.approx(gap.max(), abs=1e-6)
    t = json.loads(imp["bolus_improve_table"])
    assert t["method"] == "GRADIENT" and t["seed"] == 0 and t["smoothing_mm"] == 0.0 and not t["cancelled"]
    assert t["status"] == "improved" and t["whole"]["after"]["flv"] == pytest.approx(imp["bolus_FLV_after"])
    assert t["whole"]["before"]["vertices"] == len(V) and len(t["patches"]) == 1
    info = lines(out, "Info")
    whole = [ln for ln in info if ln.startswith("'skin': FLV ")]
    assert len(whole) == 1 and "smoothness" in whole[0] and "largest air gap" in whole[0], out
    assert f"FLV {t['whole']['before']['flv']:.4g} -> {t['whole']['after']['flv']:.4g}" in whole[0]
    assert info[-1].startswith("made 'skin_improved': the air gap (mm) in the point attribute 'bolus_air_gap'"), out


def test_air_gap_colour_scale(bpy_addon):
    """0 mm cool, 1 mm warm, 2 mm and more red."""
    from bolus.bolus_addon.operators.improve import air_gap_linear_rgba  # the registered module

    c = air_gap_linear_rgba(np.array([0.0, 1.0, 2.0, 5.0]))
    assert c.shape == (4, 4) and c.dtype == np.float32 and np.all(c[:, 3] == 1.0)
    assert c[0, 2] > c[0, 0]  # blue
    assert c[1, 0] > c[1, 1] > c[1, 2]  # orange
    assert c[2, 0] > 5 * c[2, 1] and np.array_equal(c[2], c[3])  # red, saturated


def test_mirrored_object_moves_out_where_its_normals_point(bpy_addon, raw):
    """'Outward' is the side Blender shows the face normals on, also under a mirroring transform."""
    bpy = bpy_addon
    V, F = bumpy()
    ob = make_object(bpy, V, F, scale_length=0.001)
    ob.scale = (-1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    imp = bpy.data.objects["skin_improved"]
    moved = world_mm(bpy, imp) - world_mm(bpy, ob)
    # world normals of the mirrored height field (faces wound +z locally) point up: Blender flips them back
    ob.data.update()
    n_world = np.array([(ob.matrix_world.to_3x3().inverted().transposed() @ v.normal).normalized()
                        for v in ob.data.vertices])
    big = np.linalg.norm(moved, axis=1) > 0.05
    assert big.sum() > 5
    assert np.all(np.einsum("ij,ij->i", moved[big], n_world[big]) > 0)


# =========================================================================== regions, patches
def test_edit_mode_moves_only_the_selection_interior(bpy_addon, raw):
    bpy = bpy_addon
    V, F = bumpy(n=12)
    ob = make_object(bpy, V, F, scale_length=0.001)
    before = object_snapshot(ob)
    C = V[F].mean(axis=1)
    sel = C[:, 0] < 10.0
    enter_edit_mode_with_faces(bpy, ob, sel)
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    assert ob.mode == "EDIT"  # the user's mode is restored
    bpy.ops.object.mode_set(mode="OBJECT")
    assert_same_object(before, object_snapshot(ob))
    imp = bpy.data.objects["skin_improved"]
    dist = np.linalg.norm(world_mm(bpy, imp) - world_mm(bpy, ob), axis=1)
    region_interior = np.zeros(len(V), dtype=bool)
    used = np.unique(F[sel])
    sub = np.searchsorted(used, F[sel])
    region_interior[used[interior_mask(sub, len(used))]] = True
    assert np.all(dist[~region_interior] < 1e-5) and dist[region_interior].max() > 0.05
    gap = attr_array(imp.data, "bolus_air_gap")
    assert np.all(gap[~region_interior] == 0.0)
    assert json.loads(imp["bolus_improve_table"])["whole"]["before"]["vertices"] == len(used)


def test_patches_are_improved_separately_and_their_borders_stay(bpy_addon, raw, capfd):
    bpy = bpy_addon
    V, F = bumpy(n=12)
    ob = make_object(bpy, V, F, scale_length=0.001)
    C = V[F].mean(axis=1)
    labels = (C[:, 0] > 0).astype(np.int32)
    ob.data.attributes.new("bolus_patch", "INT", "FACE").data.foreach_set("value", labels)
    capfd.readouterr()
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    out = capfd.readouterr().out
    imp = bpy.data.objects["skin_improved"]
    np.testing.assert_array_equal(attr_array(imp.data, "bolus_patch", np.int64), labels)  # kept on the copy
    gap = attr_array(imp.data, "bolus_air_gap")
    in0, in1 = np.zeros(len(V), bool), np.zeros(len(V), bool)
    in0[F[labels == 0].ravel()] = True
    in1[F[labels == 1].ravel()] = True
    border = in0 & in1
    assert border.sum() >= 10 and np.all(gap[border] == 0.0)
    assert gap[in0 & ~border].max() > 0.05 and gap[in1 & ~border].max() > 0.05
    res = core_result(bpy, ob, F, labels=labels)
    np.testing.assert_allclose(gap, res.gap, atol=1e-6)
    t = json.loads(imp["bolus_improve_table"])
    assert t["per_patch"] and [p["patch"] for p in t["patches"]] == [0, 1]
    info = lines(out, "Info")
    for p in t["patches"]:
        assert p["after"]["flv"] >= p["before"]["flv"]
        assert any(ln.startswith(f"patch {p['patch']} (") and "largest varpi" in ln for ln in info), out


def test_faces_outside_the_patches_stay(bpy_addon, raw, capfd):
    """Faces a segmentation of an Edit Mode region left at bolus_patch = -1 are not touched (said
    once); a region with no patch at all is improved as one patch."""
    bpy = bpy_addon
    V, F = bumpy(n=10)
    ob = make_object(bpy, V, F, scale_length=0.001)
    C = V[F].mean(axis=1)
    labels = np.where(C[:, 0] < -10.0, -1, 0).astype(np.int32)
    attr = ob.data.attributes.new("bolus_patch", "INT", "FACE")
    attr.data.foreach_set("value", labels)
    capfd.readouterr()
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    info = lines(capfd.readouterr().out, "Info")
    assert f"{(labels < 0).sum()} faces outside the segmented patches (bolus_patch = -1) were left as they are" in info
    gap = attr_array(bpy.data.objects["skin_improved"].data, "bolus_air_gap")
    outside = np.zeros(len(V), dtype=bool)
    outside[F[labels < 0].ravel()] = True
    assert np.all(gap[outside] == 0.0) and gap.max() > 0.05
    attr.data.foreach_set("value", np.full(len(F), -1, dtype=np.int32))
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    info = lines(capfd.readouterr().out, "Info")
    assert "no face of the region is in a segmented patch (bolus_patch = -1): improved as one patch" in info
    imp = bpy.data.objects["skin_improved"]
    assert attr_array(imp.data, "bolus_air_gap").max() > 0.05
    assert not json.loads(imp["bolus_improve_table"])["per_patch"]


def test_flat_plane_is_left_as_it_is(bpy_addon, raw, capfd):
    bpy = bpy_addon
    V, F = grid(6, 6, 50.0)
    ob = make_object(bpy, V, F, scale_length=0.001)
    capfd.readouterr()
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    out = capfd.readouterr().out
    imp = bpy.data.objects["skin_improved"]
    np.testing.assert_array_equal(local_co(imp), local_co(ob))
    assert np.all(attr_array(imp.data, "bolus_air_gap") == 0.0)
    assert any("nothing to do" in ln for ln in lines(out, "Info")), out
    assert json.loads(imp["bolus_improve_table"])["status"] == "flat"


# =========================================================================== refusals
@pytest.mark.parametrize("gap", [0.0, -1.0, float("nan")])
def test_bad_max_gap_is_refused_and_nothing_is_made(bpy_addon, raw, gap):
    bpy = bpy_addon
    V, F = bumpy(n=6)
    ob = make_object(bpy, V, F, scale_length=0.001)
    before, meshes = object_snapshot(ob), len(bpy.data.meshes)
    with pytest.raises(RuntimeError, match="gap"):
        bpy.ops.bolus.improve_flattenability(max_gap_mm=gap)
    assert "skin_improved" not in bpy.data.objects and len(bpy.data.meshes) == meshes
    assert_same_object(before, object_snapshot(ob))


@pytest.mark.parametrize("name", ["coincident", "collinear", "nan", "inf", "needle", "nonmanifold"])
def test_degenerate_input(bpy_addon, raw, name):
    """meshgen.degenerate_variants: refused with a message naming the problem (a surface to move
    along its normals must be manifold) and nothing made; the source unchanged."""
    bpy = bpy_addon
    V, F = bumpy(n=6)
    first = int(np.argmax(interior_mask(F, len(V))[F].all(axis=1)))  # an interior triangle first
    Vd, Fd, says = degenerate_variants(V, np.roll(F, -first, axis=0))[name]
    # Blender stores float32: the collinear sliver may get a sliver of area, then the bow-tie at its
    # corner is refused; the needle shares an interior edge, which makes that edge non-manifold
    says = {"collinear": "zero-area|non-manifold vertices", "needle": "non-manifold edges"}.get(name, says)
    ob = make_object(bpy, np.nan_to_num(Vd), Fd, scale_length=0.001)
    ob.data.vertices.foreach_set("co", Vd.ravel())  # past validate(), which would zero NaN / inf
    assert len(ob.data.polygons) == len(Fd), "test setup: validate() dropped a triangle"
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match=says):
        bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP)
    assert "skin_improved" not in bpy.data.objects
    assert_same_object(before, object_snapshot(ob))


def test_no_interior_vertices_is_refused(bpy_addon, raw):
    bpy = bpy_addon
    V, F = grid(1, 3, 30.0)  # a strip: every vertex on the border
    V[:, 2] = np.arange(len(V)) % 3
    make_object(bpy, V, F, scale_length=0.001)
    with pytest.raises(RuntimeError, match="interior"):
        bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP)
    assert "skin_improved" not in bpy.data.objects


def test_improved_and_pattern_objects_are_refused(bpy_addon, raw):
    bpy = bpy_addon
    ob = make_object(bpy, *bumpy(n=6), scale_length=0.001)
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    bpy.context.view_layer.objects.active = bpy.data.objects["skin_improved"]
    with pytest.raises(RuntimeError, match="'skin_improved' was made by Improve Flattenability: select its source 'skin'"):
        bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP)
    bpy.context.view_layer.objects.active = ob
    assert bpy.ops.bolus.unfold(max_el=0.0) == {"FINISHED"}
    bpy.context.view_layer.objects.active = bpy.data.objects["skin_pattern"]
    with pytest.raises(RuntimeError, match="'skin_pattern' is a pattern made by Unfold: select its source 'skin'"):
        bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP)
    assert "skin_improved_improved" not in bpy.data.objects and "skin_pattern_improved" not in bpy.data.objects


def test_an_unrelated_object_of_that_name_is_kept(bpy_addon, raw):
    bpy = bpy_addon
    other = make_object(bpy, *grid(2, 2, 10.0), name="skin_improved", scale_length=0.001)
    make_object(bpy, *bumpy(n=6), scale_length=0.001)
    snap = object_snapshot(other)
    with pytest.raises(RuntimeError, match="'skin_improved' exists and was not made by Improve Flattenability"):
        bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP)
    assert_same_object(snap, object_snapshot(bpy.data.objects["skin_improved"]))


# =========================================================================== runs
def test_twice_refills_the_same_object(bpy_addon, raw):
    bpy = bpy_addon
    make_object(bpy, *bumpy(n=8), scale_length=0.001)
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    first = attr_array(bpy.data.objects["skin_improved"].data, "bolus_air_gap")
    meshes = len(bpy.data.meshes)
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=0.3) == {"FINISHED"}
    names = sorted(o.name for o in bpy.data.objects)
    assert names == ["skin", "skin_improved"] and len(bpy.data.meshes) == meshes
    imp = bpy.data.objects["skin_improved"]
    assert imp.data.name == "skin_improved" and imp["bolus_max_gap_mm"] == pytest.approx(0.3)
    second = attr_array(imp.data, "bolus_air_gap")
    assert second.max() <= 0.3 + 1e-6 < first.max()


def test_undo_removes_the_improved_object(bpy_addon, raw):
    bpy = bpy_addon
    make_object(bpy, *bumpy(n=6), scale_length=0.001)
    bpy.ops.ed.undo_push(message="mesh made")
    assert bpy.ops.bolus.improve_flattenability("EXEC_DEFAULT", True, max_gap_mm=GAP) == {"FINISHED"}
    assert "skin_improved" in bpy.data.objects
    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert "skin_improved" not in bpy.data.objects and "skin" in bpy.data.objects
    assert bpy.ops.ed.redo() == {"FINISHED"}
    assert "skin_improved" in bpy.data.objects


def test_lpso_runs_within_the_bounds_and_is_seeded(bpy_addon, raw):
    bpy = bpy_addon
    V, F = bumpy(n=6)
    make_object(bpy, V, F, scale_length=0.001)
    gaps = []
    for _ in range(2):
        assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP, method="LPSO", seed=3) == {"FINISHED"}
        imp = bpy.data.objects["skin_improved"]
        gaps.append(attr_array(imp.data, "bolus_air_gap"))
    g = gaps[0]
    assert g.min() >= 0.0 and g.max() <= GAP + 1e-6 and np.all(g[~interior_mask(F, len(V))] == 0.0)
    np.testing.assert_array_equal(gaps[0], gaps[1])  # a fixed seed gives the same surface
    t = json.loads(imp["bolus_improve_table"])
    assert t["method"] == "LPSO" and t["seed"] == 3
    assert imp["bolus_FLV_after"] >= imp["bolus_FLV_before"]


def test_esc_keeps_the_best_so_far(bpy_addon, raw):
    """The modal path by hand (headless has no event loop): a few timer ticks, then Esc: the
    object is made from the job's best result, with a warning."""
    bpy = bpy_addon
    from bolus.bolus_addon.operators import improve as improve_ops  # the registered module
    from bolus.bolus_addon.blender.operator_base import BolusOperator

    Op = improve_ops.BOLUS_OT_improve_flattenability

    class Fake(BolusOperator):
        bl_idname = "BOLUS_OT_fake_improve"
        modal, finish = Op.__dict__["modal"], Op.__dict__["finish"]  # abort: BolusOperator's
        _timer = None

        def __init__(self):
            self.reports = []

        def report(self, kind, msg):
            self.reports.append((set(kind), msg))

    V, F = bumpy(n=8)
    make_object(bpy, V, F, scale_length=0.001)
    C = V[F].mean(axis=1)
    bpy.context.object.data.attributes.new("bolus_patch", "INT", "FACE").data.foreach_set(
        "value", np.digitize(C[:, 0], [-10.0, 10.0]).astype(np.int32))  # 3 patches: several steps
    op = Fake()
    op._run = improve_ops._ImproveRun(op, bpy.context, GAP, "GRADIENT", 0)
    assert op.modal(bpy.context, SimpleNamespace(type="MOUSEMOVE")) == {"RUNNING_MODAL"}
    assert op.modal(bpy.context, SimpleNamespace(type="TIMER")) == {"RUNNING_MODAL"}
    assert op.modal(bpy.context, SimpleNamespace(type="ESC")) == {"FINISHED"}
    imp = bpy.data.objects["skin_improved"]
    t = json.loads(imp["bolus_improve_table"])
    assert t["cancelled"] and t["status"] == "cancelled"
    warn = [m for k, m in op.reports if k == {"WARNING"}]
    assert any(m.startswith("cancelled after ") and m.endswith("the best surface so far was kept") for m in warn)
    gap = attr_array(imp.data, "bolus_air_gap")
    assert gap.min() >= 0.0 and gap.max() <= GAP + 1e-6


# =========================================================================== the next steps
def test_unfold_shell_and_export_take_the_improved_object(bpy_addon, raw, tmp_path):
    """The improved surface is where the sheet or printed bolus is made."""
    bpy = bpy_addon
    V, F = bumpy(n=8)
    ob = make_object(bpy, V, F, scale_length=0.001)
    assert bpy.ops.bolus.segment(patches=2) == {"FINISHED"}
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    imp = bpy.data.objects["skin_improved"]
    bpy.context.view_layer.objects.active = imp
    assert bpy.ops.bolus.unfold(max_el=0.0) == {"FINISHED"}
    pat = bpy.data.objects["skin_improved_pattern"]
    assert pat["bolus_source"] == "skin_improved"
    assert len(json.loads(pat["bolus_pattern_table"])["islands"]) == 2  # the copied bolus_patch
    path = tmp_path / "improved.svg"
    assert bpy.ops.bolus.export_pattern(filepath=str(path)) == {"FINISHED"}
    assert path.exists() and "<svg" in path.read_text()
    assert bpy.ops.bolus.make_shell(thickness_mm=6.0, resolution_mm=1.5) == {"FINISHED"}
    bol = bpy.data.objects["skin_improved_bolus"]
    assert bol["bolus_source"] == "skin_improved" and bol["bolus_volume_cm3"] > 0
    assert "skin_bolus" not in bpy.data.objects and "skin_pattern" not in bpy.data.objects
    assert ob.name == "skin"


def test_print_parts_of_the_improved_object_are_its_own(bpy_addon, raw, tmp_path):
    """Its `bolus_source` names the skin it came from, as a print part's names its source: Export
    Parts and the panel's print tables with the improved object active are its own, not the skin's."""
    bpy = bpy_addon
    from bolus.bolus_addon.blender.objects import print_source

    ob = make_object(bpy, *bumpy(n=8), scale_length=0.001)
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=GAP) == {"FINISHED"}
    imp = bpy.data.objects["skin_improved"]
    bpy.context.view_layer.objects.active = imp
    assert bpy.ops.bolus.print_segment(parts=2) == {"FINISHED"}
    assert bpy.ops.bolus.orient_parts() == {"FINISHED"}
    assert bpy.ops.bolus.export_parts(directory=str(tmp_path)) == {"FINISHED"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["skin_improved_part_0.stl", "skin_improved_part_1.stl"]
    assert print_source(imp) is imp and print_source(ob) is ob
    assert print_source(bpy.data.objects["skin_improved_part_1"]) is imp
