"""Blender-side tests of `bpy.ops.bolus.smooth_cuts` (SPEC: "the patch borders replaced by
smooth cut curves (ch. 4.1.2): new vertices lie on the original surface; bolus_patch and
seams updated").

The operator is driven as a user would: a mesh with a `bolus_patch` face attribute (set
by hand on synthetic grids, or by `bpy.ops.bolus.segment` on a real face), then Smooth
Cut Lines, then the mesh is inspected.  Every expectation (the surface, areas, the
connectivity of the patches, the straightness of a border, the curve it follows) is
computed here from the mesh data with numpy, scipy and mathutils, never with the
add-on's core.

Blender stores vertex coordinates as float32, so "on the original surface" means within
a few float32 ulps of it: 1e-6 of the mesh size.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from paths import ASSETS
from bpy_helpers import (
    assert_labels_connected,
    attr_array,
    edge_verts,
    enter_edit_mode_with_faces,
    import_obj,
    loop_edges_polys,
    loop_triangles,
    make_object,
    mesh_snapshot,
    seams,
)

pytestmark = pytest.mark.blender

SIZE = 100.0  # mm: the synthetic grids are 100 mm squares, one unit = 1 mm
N = 30  # quads per side
H = SIZE / N  # grid spacing
ICT = ("ict_face_narrow.obj", 0.01)  # centimetres
KNEE = ("makehuman_knee_patch.obj", 0.1)  # decimetres, small (207 quads)


# --------------------------------------------------------------------------- helpers
def quad_grid(n=N, size=SIZE):
    """Flat (n x n)-quad square in z = 0, vertex (i, j) at index i*(n+1)+j."""
    xs = np.linspace(0.0, size, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    V = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    F = np.stack([idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()], axis=1)
    return V, F


def labelled_grid(bpy, rule, n=N, size=SIZE):
    """A quad grid (scale_length 0.001: 1 unit = 1 mm) whose quads get bolus_patch = rule(centre x, centre y)."""
    V, F = quad_grid(n, size)
    ob = make_object(bpy, V, F, scale_length=0.001)
    c = V[F].mean(axis=1)
    set_labels(ob.data, rule(c[:, 0], c[:, 1]))
    return ob


def set_labels(me, labels) -> None:
    attr = me.attributes.get("bolus_patch") or me.attributes.new("bolus_patch", "INT", "FACE")
    attr.data.foreach_set("value", np.asarray(labels, dtype=np.int32))
    me.update()


def labels_of(me) -> np.ndarray:
    return attr_array(me, "bolus_patch", np.int64)


def coords(me) -> np.ndarray:
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def polygons(me) -> list[tuple[int, ...]]:
    return [tuple(p.vertices) for p in me.polygons]




def surface_area(me) -> float:
    """Sum of the areas of Blender's triangles (for planar polygons: of the polygons)."""
    P = coords(me)[loop_triangles(me)[0]]
    return 0.5 * float(np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1).sum())


def polygon_area_sum(me) -> float:
    """Sum of polygon areas from their vector area (exact for planar polygons of any size)."""
    V = coords(me)
    total = 0.0
    for poly in polygons(me):
        P = V[list(poly)]
        total += 0.5 * np.linalg.norm(np.cross(P, np.roll(P, -1, axis=0)).sum(axis=0))
    return total


def surface_tree(me):
    """BVH of the mesh's surface as it is now (Blender's triangles, object space)."""
    from mathutils.bvhtree import BVHTree  # noqa: PLC0415 (only under Blender)

    return BVHTree.FromPolygons([tuple(v) for v in coords(me)], [tuple(map(int, t)) for t in loop_triangles(me)[0]])


def distance_to(tree, P) -> np.ndarray:
    out = np.empty(len(P))
    for i, p in enumerate(P):
        hit = tree.find_nearest(tuple(map(float, p)))
        out[i] = np.inf if hit[0] is None else hit[3]
    return out


def mesh_size(me) -> float:
    V = coords(me)
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


def between_patches(me, labels) -> np.ndarray:
    """(e,) bool: edges whose polygons carry different labels."""
    le, lp = loop_edges_polys(me)
    lab = np.asarray(labels)[lp]
    ne = len(me.edges)
    lo = np.full(ne, np.iinfo(np.int64).max)
    hi = np.full(ne, np.iinfo(np.int64).min)
    np.minimum.at(lo, le, lab)
    np.maximum.at(hi, le, lab)
    return hi > lo


def border_vertices(me, labels, a=None, b=None) -> np.ndarray:
    """Vertices on edges between patches (a and b if given)."""
    le, lp = loop_edges_polys(me)
    lab = np.asarray(labels)[lp]
    out = set()
    E = edge_verts(me)
    for e in np.nonzero(between_patches(me, labels))[0]:
        labs = set(lab[le == e].tolist())
        if a is None or labs == {a, b}:
            out.update(E[e].tolist())
    return np.array(sorted(out), dtype=np.int64)




def fit_line(P2) -> tuple[np.ndarray, np.ndarray]:
    """Total least-squares line through 2D points: (point on it, unit normal)."""
    c = P2.mean(axis=0)
    _, _, Vt = np.linalg.svd(P2 - c)
    return c, Vt[1]


def fit_conic(P2):
    """Algebraic conic fit A x^2 + B xy + C y^2 + D x + E y + F = 0 (coordinates centred and scaled)."""
    c = P2.mean(axis=0)
    s = np.abs(P2 - c).max()
    x, y = ((P2 - c) / s).T
    M = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=1)
    coef = np.linalg.svd(M)[2][-1]

    def distance(Q):
        qx, qy = ((Q - c) / s).T
        A, B, C, D, E, _ = coef
        val = np.stack([qx * qx, qx * qy, qy * qy, qx, qy, np.ones_like(qx)], axis=1) @ coef
        grad = np.hypot(2 * A * qx + B * qy + D, B * qx + 2 * C * qy + E)
        return s * np.abs(val) / grad  # first-order geometric distance, mm

    return coef, distance


def cut_table(ob) -> list[dict]:
    return json.loads(ob["bolus_cut_table"])


def state(ob):
    """mesh_snapshot plus the patch labels and our custom properties."""
    me = ob.data
    lab = labels_of(me) if "bolus_patch" in me.attributes else None
    return mesh_snapshot(me), lab, {k: ob[k] for k in ob.keys() if k.startswith("bolus_")}


def assert_same_state(before, after) -> None:
    (co0, loops0, seams0, names0), lab0, props0 = before
    (co1, loops1, seams1, names1), lab1, props1 = after
    np.testing.assert_array_equal(co0, co1)
    np.testing.assert_array_equal(loops0, loops1)
    np.testing.assert_array_equal(seams0, seams1)
    assert names0 == names1
    if lab0 is None:
        assert lab1 is None
    else:
        np.testing.assert_array_equal(lab0, lab1)
    assert props0 == props1


def line_rule(x, y):
    return (x > 50.0 + 0.3 * (y - 50.0)).astype(int)


def parabola_rule(x, y):
    return (x > 50.0 + 0.01 * (y - 50.0) ** 2).astype(int)


def disk_rule(x, y):
    return ((x - 50.0) ** 2 + (y - 50.0) ** 2 < 25.0**2).astype(int)


def check_straight_border(me, n0, labels):
    """The 0|1 border of a grid cut by a straight line; returns (point, normal) of the line."""
    V = coords(me)
    bv = border_vertices(me, labels)
    new = bv[bv >= n0]
    assert len(new) >= 10, "the border should run through new vertices"
    c, nrm = fit_line(V[new, :2])
    d_all = np.abs((V[bv, :2] - c) @ nrm)
    # the new vertices lie on the cut line; old ones only where a cut point snapped onto
    # a vertex (within 5 % of an edge of up to H*sqrt(2))
    assert np.abs((V[new, :2] - c) @ nrm).max() < 1e-4
    assert d_all.max() < 0.05 * H * np.sqrt(2.0), f"border vertex {d_all.max():.3f} mm off the line"
    assert (d_all < 1e-4).mean() >= 0.85  # measured 1.0: every border vertex on the line
    # ... and the line is the one the jagged labels followed: x = 50 + 0.3 (y - 50)
    expected = np.array([1.0, -0.3]) / np.hypot(1.0, 0.3)
    assert abs(abs(nrm @ expected) - 1.0) < 1e-3  # within ~2.5 degrees
    assert abs((np.array([50.0, 50.0]) - c) @ nrm) < 0.5 * H
    return c, nrm


# --------------------------------------------------------------- straight border
@pytest.mark.smoke
def test_straight_border_on_quad_grid(bpy_addon, scene):
    bpy = bpy_addon
    ob = labelled_grid(bpy, line_rule)
    me = ob.data
    V0, polys0 = coords(me), polygons(me)
    n0 = len(V0)
    # a UV map (uv = xy / 100) and a vertex group (0.5 everywhere) to be carried over
    uv = me.uv_layers.new(name="UVMap")
    le0 = np.empty(len(me.loops), dtype=np.int64)
    me.loops.foreach_get("vertex_index", le0)
    uv.data.foreach_set("uv", (V0[le0, :2] / SIZE).ravel())
    ob.vertex_groups.new(name="weight").add(range(n0), 0.5, "REPLACE")
    tree0 = surface_tree(me)
    area0 = polygon_area_sum(me)
    assert area0 == pytest.approx(SIZE * SIZE, rel=1e-9)
    assert len(border_vertices(me, labels_of(me))) > N  # jagged

    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    V = coords(me)
    lab = labels_of(me)
    assert len(V) > n0
    np.testing.assert_array_equal(V[:n0], V0)  # old vertices keep their place and index
    # (a) new vertices on the original surface (float32 storage: 1e-6 of the size)
    dist = distance_to(tree0, V[n0:])
    assert dist.max() < 1e-6 * mesh_size(me)
    # (b) no area gained or lost
    assert polygon_area_sum(me) == pytest.approx(area0, rel=1e-6)
    # (c) two patches, each in one piece
    assert set(np.unique(lab).tolist()) == {0, 1}
    assert_labels_connected(me, lab)
    # (d) the border is a straight line
    c, nrm = check_straight_border(me, n0, lab)
    # every polygon is on the side of the line its label says
    cent = np.array([V[list(p)].mean(axis=0)[:2] for p in polygons(me)])
    side = (cent - c) @ nrm > 0
    assert np.all(side == (lab == 1)) or np.all(side == (lab == 0))
    # (e) seams exactly on the patch border
    np.testing.assert_array_equal(seams(me), between_patches(me, lab))
    # (f) quads away from the cut are left as they were; the others became triangles
    polys = polygons(me)
    assert {len(p) for p in polys} == {3, 4}
    old_quads = set(polys0)
    quads = [p for p in polys if len(p) == 4]
    assert set(quads) <= old_quads
    far = [p for p in polys0 if abs((V0[list(p)].mean(axis=0)[:2] - c) @ nrm) > H]
    assert len(far) == pytest.approx(838, rel=0.15) and set(far) <= set(quads)  # measured 838
    assert len(far) <= len(quads) < len(polys0)
    # (g) corner and vertex data interpolated onto the new geometry
    le = np.empty(len(me.loops), dtype=np.int64)
    me.loops.foreach_get("vertex_index", le)
    uvs = np.empty(len(me.loops) * 2)
    me.uv_layers["UVMap"].data.foreach_get("uv", uvs)
    np.testing.assert_allclose(uvs.reshape(-1, 2), V[le, :2] / SIZE, atol=1e-5)
    gi = ob.vertex_groups["weight"].index
    w = np.array([next((g.weight for g in v.groups if g.group == gi), -1.0) for v in me.vertices])
    np.testing.assert_allclose(w, 0.5, atol=1e-6)
    # the patch colours follow the new labels (one flat colour per patch)
    col = np.empty(len(me.loops) * 4)
    me.color_attributes["bolus_patch_color"].data.foreach_get("color", col)
    col = col.reshape(-1, 4)
    _, lp = loop_edges_polys(me)
    c0, c1 = col[lab[lp] == 0], col[lab[lp] == 1]
    assert np.ptp(c0, axis=0).max() == 0 and np.ptp(c1, axis=0).max() == 0 and not np.allclose(c0[0], c1[0])
    # the report
    (row,) = cut_table(ob)
    assert (row["a"], row["b"], row["closed"], row["method"]) == (0, 1, False, "line")
    assert row["turning_after"] < 1e-6 * row["turning_before"]  # measured 1.5e-8 (float32 coordinates)
    assert row["max_shift_mm"] == pytest.approx(2.10, rel=0.15)  # measured


def cut_labelled_grid(bpy, rule):
    """Cut a labelled grid; check the new vertices lie on the old surface and the patches stay
    connected.  Returns (object, vertices, border vertices, the new ones among them)."""
    ob = labelled_grid(bpy, rule)
    me = ob.data
    n0 = len(me.vertices)
    tree0 = surface_tree(me)
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    V, lab = coords(me), labels_of(me)
    assert distance_to(tree0, V[n0:]).max() < 1e-6 * mesh_size(me)
    assert_labels_connected(me, lab)
    bv = border_vertices(me, lab)
    return ob, V, bv, bv[bv >= n0]


# ----------------------------------------------------------------- curved border
def test_curved_border_follows_a_parabola(bpy_addon, scene):
    ob, V, bv, new = cut_labelled_grid(bpy_addon, parabola_rule)
    assert len(new) >= 10
    x, y = V[new, 0], V[new, 1]
    coef = np.polyfit(y, x, 2)
    assert np.abs(np.polyval(coef, y) - x).max() < 1e-3  # mm: on one parabola x = a y^2 + b y + c
    assert coef[0] == pytest.approx(0.0098, rel=0.15)  # measured; the labels' x = 50 + 0.01 (y - 50)^2
    xa, ya = V[bv, 0], V[bv, 1]
    assert np.abs(np.polyval(coef, ya) - xa).max() < 0.05 * H * np.sqrt(2.0)
    (row,) = cut_table(ob)
    assert row["method"] == "parabola" and row["closed"] is False
    assert row["turning_after"] / row["turning_before"] == pytest.approx(0.0473, rel=0.15)  # measured


def test_closed_border_follows_an_ellipse(bpy_addon, scene):
    ob, V, bv, new = cut_labelled_grid(bpy_addon, disk_rule)
    assert len(new) >= 20
    (A, B, C, *_), dist = fit_conic(V[new, :2])
    assert B * B - 4 * A * C < 0  # an ellipse
    # the cut follows a fine polygon of the ellipse: within its chord error
    assert dist(V[new, :2]).max() < 2e-3
    r = np.hypot(V[new, 0] - 50.0, V[new, 1] - 50.0)
    assert np.abs(r - 25.0).max() == pytest.approx(0.197, rel=0.15)  # measured: about the circle the labels followed
    assert dist(V[bv, :2]).max() < 0.05 * H * np.sqrt(2.0) + 2e-3
    (row,) = cut_table(ob)
    assert row["closed"] is True and row["method"] == "ellipse"
    assert row["turning_after"] / row["turning_before"] == pytest.approx(0.171, rel=0.15)  # measured
    # the disk is still the inner patch: a polygon at the centre is patch 1, the corners 0
    me, lab = ob.data, labels_of(ob.data)
    cent = np.array([V[list(p)].mean(axis=0)[:2] for p in polygons(me)])
    assert np.all(lab[np.hypot(*(cent - 50.0).T) < 20.0] == 1)
    assert np.all(lab[np.hypot(*(cent - 50.0).T) > 30.0] == 0)


# --------------------------------------------------------------------- real mesh
def test_real_mesh_after_segment(bpy_addon, scene, capfd):
    bpy = bpy_addon
    ob = import_obj(bpy, ASSETS / ICT[0], ICT[1])
    me = ob.data
    assert bpy.ops.bolus.segment(patches=4) == {"FINISHED"}
    lab0 = labels_of(me)
    n_patches = int(lab0.max()) + 1
    n0, V0 = len(me.vertices), coords(me)
    ntri0 = len(loop_triangles(me)[0])
    tree0, area0 = surface_tree(me), surface_area(me)
    capfd.readouterr()
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    out = capfd.readouterr().out
    V, lab = coords(me), labels_of(me)
    assert len(V) > n0
    np.testing.assert_array_equal(V[:n0], V0)
    assert distance_to(tree0, V[n0:]).max() < 1e-6 * mesh_size(me)
    assert surface_area(me) == pytest.approx(area0, rel=1e-6)
    assert set(np.unique(lab).tolist()) == set(range(n_patches))
    assert_labels_connected(me, lab)
    np.testing.assert_array_equal(seams(me), between_patches(me, lab))
    rows = cut_table(ob)
    assert len(rows) >= n_patches - 1
    for r in rows:
        assert {"a", "b", "closed", "method", "turning_before", "turning_after", "max_shift_mm", "note"} <= set(r)
        assert r["turning_after"] < r["turning_before"], r
        assert 0 <= r["a"] < r["b"] < n_patches
        assert len(border_vertices(me, lab, r["a"], r["b"])) > 0  # still neighbours
    tb = sum(r["turning_before"] * r["length_before_mm"] for r in rows)
    ta = sum(r["turning_after"] * r["length_after_mm"] for r in rows)
    assert ta / tb == pytest.approx(0.034, rel=0.15)  # measured: the length-weighted turning 96.6 % lower
    assert f"Smoothed {len(rows)} of {len(rows)} borders" in out
    table = json.loads(ob["bolus_patch_table"])
    assert table["smooth_cuts"] is True
    before, after = table["before_smooth_cuts"], table["patches"]
    assert [r["patch"] for r in before] == [r["patch"] for r in after] == list(range(n_patches))
    assert sum(r["faces"] for r in before) == ntri0
    assert sum(r["faces"] for r in after) == len(loop_triangles(me)[0])


def test_unfold_works_on_the_cut_mesh(bpy_addon, scene):
    """The new topology is usable downstream (the small knee: unfolding the ICT face takes minutes)."""
    bpy = bpy_addon
    ob = import_obj(bpy, ASSETS / KNEE[0], KNEE[1])
    me = ob.data
    assert bpy.ops.bolus.segment(patches=3, smoothing_mm=0.0) == {"FINISHED"}
    n0 = len(me.vertices)
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    assert len(me.vertices) > n0
    lab = labels_of(me)
    assert bpy.ops.bolus.unfold() == {"FINISHED"}
    pat = bpy.data.objects[ob.name + "_pattern"]
    src = attr_array(pat.data, "bolus_source_face", np.int64)
    assert set(src.tolist()) == set(range(len(me.polygons)))  # every polygon of the cut mesh laid out
    np.testing.assert_array_equal(attr_array(pat.data, "bolus_patch", np.int64), lab[src])
    co = coords(pat.data)
    assert np.abs(co[:, 2]).max() == 0.0


# -------------------------------------------------------------------------- undo
def test_undo_restores_the_mesh(bpy_addon, scene):
    bpy = bpy_addon
    ob = labelled_grid(bpy, line_rule, n=12)
    name, n0 = ob.name, len(ob.data.vertices)
    ob.data.edges[5].use_seam = True  # the user's seam: must come back
    ob.data.update()
    before = state(ob)
    bpy.ops.ed.undo_push(message="labels set")
    assert bpy.ops.bolus.smooth_cuts("EXEC_DEFAULT", True) == {"FINISHED"}
    ob = bpy.data.objects[name]
    n_cut = len(ob.data.vertices)
    assert n_cut > n0 and "bolus_cut_table" in ob
    assert bpy.ops.ed.undo() == {"FINISHED"}
    ob = bpy.data.objects[name]  # undo reloads the data-blocks: fetch them again
    assert_same_state(before, state(ob))
    assert "bolus_cut_table" not in ob
    assert bpy.ops.ed.redo() == {"FINISHED"}
    ob = bpy.data.objects[name]
    assert len(ob.data.vertices) == n_cut and "bolus_cut_table" in ob


# --------------------------------------------------------------------- bad input
@pytest.mark.smoke
def test_no_patch_attribute(bpy_addon, scene):
    bpy = bpy_addon
    V, F = quad_grid(6)
    ob = make_object(bpy, V, F, scale_length=0.001)
    before = state(ob)
    with pytest.raises(RuntimeError, match="'skin' has no 'bolus_patch' attribute: run Segment into Patches first"):
        bpy.ops.bolus.smooth_cuts()
    assert_same_state(before, state(ob))


def test_single_patch(bpy_addon, scene, capfd):
    """SPEC: with nothing to change, INFO, no change, no error."""
    bpy = bpy_addon
    ob = labelled_grid(bpy, lambda x, y: np.zeros_like(x, dtype=int), n=6)
    before = state(ob)
    capfd.readouterr()
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Info: Nothing to smooth on 'skin': there is only one patch" in out and "Error" not in out
    assert_same_state(before, state(ob))


def test_no_face_in_a_patch(bpy_addon, scene):
    bpy = bpy_addon
    ob = labelled_grid(bpy, lambda x, y: np.full_like(x, -1, dtype=int), n=6)
    before = state(ob)
    with pytest.raises(RuntimeError, match="no face of 'skin' belongs to a patch: run Segment into Patches first"):
        bpy.ops.bolus.smooth_cuts()
    assert_same_state(before, state(ob))


def test_shape_keys(bpy_addon, scene):
    bpy = bpy_addon
    ob = labelled_grid(bpy, line_rule, n=8)
    ob.shape_key_add(name="Basis")
    ob.shape_key_add(name="Smile")
    before = state(ob)
    with pytest.raises(RuntimeError, match="'skin' has shape keys.*apply or remove them first"):
        bpy.ops.bolus.smooth_cuts()
    assert_same_state(before, state(ob))
    assert len(ob.data.shape_keys.key_blocks) == 2


@pytest.mark.parametrize("case", ["strip", "corner"])
def test_border_of_a_single_edge(bpy_addon, scene, case, capfd):
    """Patches meeting along one edge only: nothing to fit, the operator says so (INFO, SPEC)."""
    bpy = bpy_addon
    if case == "strip":  # two quads side by side
        V = np.array([[0, 0, 0], [10, 0, 0], [20, 0, 0], [0, 10, 0], [10, 10, 0], [20, 10, 0]], dtype=float)
        ob = make_object(bpy, V, [(0, 1, 4, 3), (1, 2, 5, 4)], scale_length=0.001)
        set_labels(ob.data, [0, 1])
    else:  # the corner triangle of a 2x2 grid whose corner quad is split along 3-1
        V, F = quad_grid(2, 20.0)
        F = [tuple(f) for f in F[1:]] + [(0, 3, 1), (3, 4, 1)]
        ob = make_object(bpy, V, F, scale_length=0.001)
        set_labels(ob.data, [0, 0, 0, 1, 0])
    before = state(ob)
    capfd.readouterr()
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Info: Nothing to change on 'skin'" in out and "the mesh was not changed" in out
    assert "Error" not in out and "Warning" not in out
    assert out.count("Border 0|1 ") == 1 and "too short to fit a curve" in out  # the border, said once
    assert_same_state(before, state(ob))


def test_active_object_not_a_mesh(bpy_addon, scene):
    bpy = bpy_addon
    ob = labelled_grid(bpy, line_rule, n=6)
    before = state(ob)
    bpy.ops.object.empty_add()
    other = bpy.context.active_object
    with pytest.raises(RuntimeError, match=f"'{other.name}' is not a mesh: select the skin surface mesh"):
        bpy.ops.bolus.smooth_cuts()
    assert_same_state(before, state(ob))
    assert "bolus_cut_table" not in other


# --------------------------------------------------------------------- Edit Mode
def test_edit_mode_works_on_the_whole_mesh(bpy_addon, scene):
    """A selection inside one patch does not restrict the cut; Edit Mode shows the new mesh."""
    import bmesh  # noqa: PLC0415 (only under Blender)

    bpy = bpy_addon
    ob = labelled_grid(bpy, line_rule)
    me = ob.data
    n0 = len(me.vertices)
    tree0 = surface_tree(me)
    V0 = coords(me)
    sel = np.array([V0[list(p)].mean(axis=0)[0] < 15.0 for p in polygons(me)])
    assert np.all(labels_of(me)[sel] == 0)  # the selection alone holds a single patch
    enter_edit_mode_with_faces(bpy, ob, sel)
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    assert ob.mode == "EDIT"
    bm = bmesh.from_edit_mesh(me)
    n_edit, nf_edit = len(bm.verts), len(bm.faces)
    layer = bm.faces.layers.int.get("bolus_patch")
    assert layer is not None and {f[layer] for f in bm.faces} == {0, 1}
    assert n_edit > n0
    bpy.ops.object.mode_set(mode="OBJECT")
    assert (len(me.vertices), len(me.polygons)) == (n_edit, nf_edit)  # leaving Edit Mode keeps the cut
    V, lab = coords(me), labels_of(me)
    assert distance_to(tree0, V[n0:]).max() < 1e-6 * mesh_size(me)
    assert_labels_connected(me, lab)
    check_straight_border(me, n0, lab)
    np.testing.assert_array_equal(seams(me), between_patches(me, lab))


def test_error_in_edit_mode_stays_in_edit_mode(bpy_addon, scene):
    bpy = bpy_addon
    ob = labelled_grid(bpy, lambda x, y: np.full_like(x, -1, dtype=int), n=6)
    before = state(ob)
    enter_edit_mode_with_faces(bpy, ob, np.ones(len(ob.data.polygons), dtype=bool))
    with pytest.raises(RuntimeError, match="no face of 'skin' belongs to a patch"):
        bpy.ops.bolus.smooth_cuts()
    assert ob.mode == "EDIT"
    bpy.ops.object.mode_set(mode="OBJECT")
    after = state(ob)
    np.testing.assert_array_equal(before[0][0], after[0][0])
    np.testing.assert_array_equal(before[0][1], after[0][1])
    np.testing.assert_array_equal(before[1], after[1])
    assert after[2] == before[2]


# ------------------------------------------------------------------------- panel
def test_panel_shows_the_cut_table(bpy_addon, scene):
    from test_blender_panel import draw_panel  # noqa: PLC0415 (the recording layout of the panel tests)

    bpy = bpy_addon
    ob = labelled_grid(bpy, parabola_rule, n=20)
    log = draw_panel(bpy)
    assert ("operator", "bolus.smooth_cuts") in log
    assert ("label", "Border") not in log
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    labels = [t for kind, t in draw_panel(bpy) if kind == "label"]
    (row,) = cut_table(ob)
    assert "Border" in labels and "0|1" in labels and row["method"] in labels
    assert f"{row['turning_before']:.2f}→{row['turning_after']:.2f}" in labels


# ------------------------------------------------- selection, region, reports
def bumpy_region_grid(bpy, n=40):
    """A 100 mm grid with a bump; returns (object, mask of the quads within 30 mm of the centre)."""
    V, F = quad_grid(n)
    V[:, 2] = 20.0 * np.exp(-((V[:, 0] - 50.0) ** 2 + (V[:, 1] - 50.0) ** 2) / 600.0)
    ob = make_object(bpy, V, F, scale_length=0.001)
    c = V[F].mean(axis=1)
    return ob, np.hypot(c[:, 0] - 50.0, c[:, 1] - 50.0) < 30.0


def set_edit_selection(me, select, hide=None) -> None:
    """In Edit Mode: exactly the faces ``select`` selected (with their edges and vertices), ``hide`` hidden."""
    import bmesh  # noqa: PLC0415 (only under Blender)

    bm = bmesh.from_edit_mesh(me)
    for seq in (bm.faces, bm.edges, bm.verts):
        for ele in seq:
            ele.hide_set(False)
            ele.select_set(False)
    bm.faces.ensure_lookup_table()
    if hide is not None:
        for i in np.nonzero(hide)[0]:
            bm.faces[int(i)].hide_set(True)
    for i in np.nonzero(select)[0]:
        bm.faces[int(i)].select_set(True)
    bmesh.update_edit_mesh(me)


def edit_flags(me):
    """(face select, face patch label, vert select, edge select, face/vert/edge sets) from the edit-mesh."""
    import bmesh  # noqa: PLC0415 (only under Blender)

    bm = bmesh.from_edit_mesh(me)
    layer = bm.faces.layers.int.get("bolus_patch")
    fsel = np.array([f.select for f in bm.faces])
    lab = np.array([f[layer] for f in bm.faces])
    in_sel_face_v = np.zeros(len(bm.verts), dtype=bool)
    in_sel_face_e = np.zeros(len(bm.edges), dtype=bool)
    bm.verts.index_update()
    bm.edges.index_update()
    for f in bm.faces:
        if f.select:
            in_sel_face_v[[v.index for v in f.verts]] = True
            in_sel_face_e[[e.index for e in f.edges]] = True
    vsel = np.array([v.select for v in bm.verts])
    esel = np.array([e.select for e in bm.edges])
    return fsel, lab, vsel, esel, in_sel_face_v, in_sel_face_e


def test_selection_follows_the_region_in_edit_mode(bpy_addon, scene):
    """The Edit Mode region, segmented and cut, is still exactly the selection."""
    bpy = bpy_addon
    ob, region = bumpy_region_grid(bpy)
    me = ob.data
    enter_edit_mode_with_faces(bpy, ob, region)
    set_edit_selection(me, region)  # the helper leaves every edge (so every vertex) selected
    assert bpy.ops.bolus.segment(patches=3) == {"FINISHED"}
    fsel, lab, vsel, esel, in_v, in_e = edit_flags(me)
    assert np.array_equal(fsel, lab >= 0) and fsel.sum() == region.sum()  # the region before
    assert np.array_equal(vsel, in_v)
    nf = len(fsel)
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    assert ob.mode == "EDIT"
    fsel, lab, vsel, esel, in_v, in_e = edit_flags(me)
    assert len(fsel) > nf  # the cut added faces
    assert (lab >= 0).sum() > region.sum()
    np.testing.assert_array_equal(fsel, lab >= 0)  # selected faces = the patch faces, nothing else
    np.testing.assert_array_equal(vsel, in_v)  # their vertices, no others
    assert esel[in_e].all()  # their edges; any other selected edge joins two selected vertices
    ev = np.array([[v.index for v in e.verts] for e in __import__("bmesh").from_edit_mesh(me).edges])
    assert vsel[ev[esel]].all()
    # and the next step works on that region: a second cut finds nothing to change
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}


def test_no_crack_where_a_cut_meets_the_edge_of_the_region(bpy_addon, scene):
    """A border running to the edge of an Edit Mode region ends on a vertex there: no edge that a
    face outside the region shares is split on one side only (a T-junction: the surface would
    get a crack, seen as new boundary edges inside the grid)."""
    bpy = bpy_addon
    ob, region = bumpy_region_grid(bpy)
    me = ob.data

    def boundary_edges():
        le, _ = loop_edges_polys(me)
        return int((np.bincount(le, minlength=len(me.edges)) == 1).sum())

    before = boundary_edges()
    assert before == 4 * 40  # the grid's own outline
    enter_edit_mode_with_faces(bpy, ob, region)
    assert bpy.ops.bolus.segment(patches=3) == {"FINISHED"}
    n0 = len(me.vertices)
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    assert len(me.vertices) > n0  # it did cut
    assert boundary_edges() == before
    le, _ = loop_edges_polys(me)
    assert np.bincount(le, minlength=len(me.edges)).max() == 2  # and no edge got three faces


@pytest.mark.parametrize("mode", ["OBJECT", "EDIT"])
def test_selection_and_hiding_follow_each_polygon(bpy_addon, scene, mode):
    """Every face after the cut lies in one old quad: it is selected (hidden) iff that quad was."""
    bpy = bpy_addon
    ob = labelled_grid(bpy, line_rule)
    me = ob.data
    rng = np.random.default_rng(3)
    pick = rng.random(N * N)
    sel, hide = pick < 0.3, pick > 0.8  # disjoint: a hidden face cannot be selected
    bpy.context.tool_settings.mesh_select_mode = (False, False, True)
    bpy.ops.object.mode_set(mode="EDIT")
    set_edit_selection(me, sel, hide)
    if mode == "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
        assert np.array_equal([p.hide for p in me.polygons], hide) and np.array_equal([p.select for p in me.polygons], sel)
    n0 = len(me.polygons)
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    assert ob.mode == mode
    if mode == "EDIT":
        bpy.ops.object.mode_set(mode="OBJECT")
    assert len(me.polygons) > n0
    V = coords(me)
    c = np.array([V[list(p)].mean(axis=0) for p in polygons(me)])
    quad = np.floor(c[:, 0] / H).astype(int) * N + np.floor(c[:, 1] / H).astype(int)  # quad_grid's order
    got_sel = np.array([p.select for p in me.polygons])
    got_hide = np.array([p.hide for p in me.polygons])
    np.testing.assert_array_equal(got_hide, hide[quad])
    np.testing.assert_array_equal(got_sel, sel[quad])
    in_sel = np.zeros(len(me.vertices), dtype=bool)
    for p in me.polygons:
        if p.select:
            in_sel[list(p.vertices)] = True
    np.testing.assert_array_equal(np.array([v.select for v in me.vertices]), in_sel)
    in_shown = np.zeros(len(me.vertices), dtype=bool)
    for p in me.polygons:
        if not p.hide:
            in_shown[list(p.vertices)] = True
    vhide = np.array([v.hide for v in me.vertices])
    assert not (vhide & in_shown).any()  # a vertex of a visible face is visible
    new = np.arange(len(me.vertices)) >= (N + 1) ** 2
    assert (vhide[new] == ~in_shown[new]).all()  # a new vertex is hidden iff all its faces are


def far_defect(kind: str):
    """Triangles 200 mm away from the 100 mm grid: a bow-tie (two sharing one vertex), a fin
    (three on one edge) or one with a NaN coordinate, as (vertices, faces) to append."""
    if kind == "nan":
        return np.array([[300, 0, 0], [310, 0, 0], [305, np.nan, 0]]), [(0, 1, 2)]
    if kind == "bowtie":
        V = np.array([[300, 0, 0], [310, 0, 0], [305, 8, 0], [300, 16, 0], [310, 16, 0]], dtype=float)
        return V, [(0, 1, 2), (2, 4, 3)]
    V = np.array([[300, 0, 0], [310, 0, 0], [305, 8, 0], [305, -8, 0], [305, 0, 8]], dtype=float)
    return V, [(0, 1, 2), (1, 0, 3), (0, 1, 4)]


@pytest.mark.parametrize("kind, refusal", [("bowtie", "non-manifold"), ("fin", "non-manifold"),
                                           ("nan", "invalid coordinate")])
def test_checks_apply_to_the_patch_faces_only(bpy_addon, scene, kind, refusal):
    """A non-manifold (or NaN) spot 200 mm from the patches does not block the cut ..."""
    bpy = bpy_addon
    V, F = quad_grid(12)
    W, G = far_defect(kind)
    c = V[F].mean(axis=1)
    labels = list(line_rule(c[:, 0], c[:, 1])) + [-1] * len(G)
    ob = make_object(bpy, np.vstack([V, W]), [tuple(f) for f in F] + [tuple(np.add(g, len(V))) for g in G],
                     scale_length=0.001)
    ob.data.vertices.foreach_set("co", np.vstack([V, W]).ravel())  # (make_object's validate() zeroes NaN)
    set_labels(ob.data, labels)
    n0 = len(ob.data.vertices)
    far = coords(ob.data)[len(V):].copy()
    assert np.isnan(far).any() == (kind == "nan")
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    me = ob.data
    assert len(me.vertices) > n0
    np.testing.assert_array_equal(coords(me)[len(V):n0], far)  # the far part untouched
    lab = labels_of(me)
    assert (lab == -1).sum() == len(G)
    # ... but the same spot inside a patch still refuses
    ob2 = make_object(bpy, np.vstack([V, W]), [tuple(f) for f in F] + [tuple(np.add(g, len(V))) for g in G],
                      name="inside", scale_length=0.001)
    ob2.data.vertices.foreach_set("co", np.vstack([V, W]).ravel())
    set_labels(ob2.data, list(line_rule(c[:, 0], c[:, 1])) + [0] * len(G))
    with pytest.raises(RuntimeError, match=refusal):
        bpy.ops.bolus.smooth_cuts()


def test_second_run_reports_nothing_to_change(bpy_addon, scene, capfd):
    """SPEC: with nothing to change smooth_cuts reports INFO, changes nothing, raises no error."""
    bpy = bpy_addon
    ob = labelled_grid(bpy, line_rule)
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    before = state(ob)
    capfd.readouterr()
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Info: Nothing to change on 'skin'" in out
    assert "Error" not in out and "Warning" not in out
    assert out.count("Border 0|1 ") == 1
    assert_same_state(before, state(ob))


def test_each_border_reported_once(bpy_addon, scene, capfd):
    """Every border is reported once, also one left as it is (a WARNING only, not also an INFO line)."""
    bpy = bpy_addon

    def rule(x, y):
        lab = line_rule(x, y)
        lab[(x < 4.0) & (y < 4.0)] = 2  # the corner quad: a border of two edges, left as it is
        return lab

    ob = labelled_grid(bpy, rule)
    capfd.readouterr()
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    out = capfd.readouterr().out
    rows = cut_table(ob)
    assert {r["method"] == "unchanged" for r in rows} == {True, False}  # a mix of both
    lines = [ln for ln in out.splitlines() if ": Border " in ln]
    assert len(lines) == len(rows)
    for r in rows:
        assert sum(f"Border {r['a']}|{r['b']} (" in ln for ln in lines) == 1


def test_int8_patch_attribute(bpy_addon, scene):
    """bolus_patch stored as 8-bit integers (another tool) is cut like the INT one segment writes."""
    bpy = bpy_addon
    V, F = quad_grid()
    ob = make_object(bpy, V, F, scale_length=0.001)
    c = V[F].mean(axis=1)
    ob.data.attributes.new("bolus_patch", "INT8", "FACE").data.foreach_set("value", line_rule(c[:, 0], c[:, 1]).astype(np.int8))
    n0 = len(ob.data.vertices)
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    me = ob.data
    assert len(me.vertices) > n0
    assert [a.name for a in me.attributes].count("bolus_patch") == 1
    lab = labels_of(me)
    assert set(np.unique(lab).tolist()) == {0, 1}
    assert_labels_connected(me, lab)
    check_straight_border(me, n0, lab)
