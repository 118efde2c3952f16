"""The bad-mesh corpus, made by the tests (numpy + bpy, no files).

Every case is a small skin-like surface (a bumpy 60 mm dome in a 1 unit = 1 mm scene, built
from quads) with one kind of damage that planning systems and scanners hand over.
`CASES` maps a name to a builder ``build(bpy) -> Case``; the builder leaves the object active,
selected and, for the Edit Mode case, in Edit Mode.  `arrays(...)` gives the polygon lists
without bpy (for core tests).  (The 1M-face mesh of the issue is the scale and range-scan benchmarks'.)

What each case is (vertex / face indices are Blender's, as the messages name them):

- ``clean``: the undamaged dome (the control case: every operator finishes)
- ``nonmanifold_edge``: a third quad on the interior edge (NM_EDGE) of the dome
- ``holes``: two interior holes (4 and 1 quads removed)
- ``zero_area``: a sliver triangle whose three vertices lie on a line, glued to corner vertex 0
- ``needle``: a triangle with a 1e-3 mm wide tip (positive area) at the dome's edge
- ``duplicate_vertices``: the two halves of the dome do not share their middle row of
  vertices (every vertex there is doubled: a crack) and one extra vertex sits on vertex 5
- ``ngons_concave``: two quads merged into a hexagon, an octagon of four quads, and a
  concave (dart-shaped) quad
- ``loose``: 3 loose vertices and 2 loose edges beside the dome
- ``pieces``: three separate domes
- ``one_triangle``: one triangle
- ``flipped_normals``: the polygons of the last 3 of 10 rows wound the other way (60 of 200 triangles)
- ``modifiers``: a Subdivision + Displace stack on the dome (the operators read the mesh data,
  not the evaluated mesh: the result is that of the dome without its modifiers)
- ``scale_nonuniform``, ``scale_negative``, ``rotated``: object transforms
- ``edit_nothing_selected``: Edit Mode with no face selected (the whole mesh is the region)
- ``nan``: vertex NAN_VERTEX has a NaN coordinate
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

N = 10  #: quads per side of the dome
SIZE = 60.0  #: mm across (small: Make Bolus's voxel grid grows with the area)
NAN_VERTEX = 27


def vid(i: int, j: int, n: int = N) -> int:
    """Index of grid vertex (i, j) of an n x n-quad dome."""
    return i * (n + 1) + j


def dome(n: int = N, size: float = SIZE, offset=(0.0, 0.0, 0.0), height: float | None = None):
    """An n x n-quad bumpy dome, size mm across (height size / 4.8): V ((n+1)^2, 3), quads as lists (n*n of them)."""
    xs, ys = np.meshgrid(np.linspace(-size / 2, size / 2, n + 1), np.linspace(-size / 2, size / 2, n + 1),
                         indexing="ij")
    height = size / 4.8 if height is None else height
    r2 = (xs**2 + ys**2) / (size / 2.5) ** 2
    z = height * np.exp(-r2) + size / 60.0 * np.sin(xs * 13.0 / size) * np.cos(ys * 9.0 / size)
    V = np.c_[xs.ravel(), ys.ravel(), z.ravel()] + np.asarray(offset, dtype=np.float64)
    F = [[vid(i, j, n), vid(i + 1, j, n), vid(i + 1, j + 1, n), vid(i, j + 1, n)] for i in range(n) for j in range(n)]
    return V, F


#: the dome's interior edge the non-manifold case hangs a third quad on
NM_EDGE = (vid(5, 5), vid(5, 6))


def quad_of(i: int, j: int, n: int = N) -> int:
    return i * n + j


# ----------------------------------------------------------------------------- the arrays
def clean():
    return dome(), []


def nonmanifold_edge():
    V, F = dome()
    a, b = NM_EDGE
    top = (V[a] + V[b]) / 2 + np.array([2.0, 0.0, 6.0])
    V = np.r_[V, [top + np.array([0, -3.0, 0]), top + np.array([0, 3.0, 0])]]
    n = len(V)
    return (V, F + [[a, b, n - 1, n - 2]]), []


def holes():
    V, F = dome()
    drop = {quad_of(i, j) for i in (3, 4) for j in (3, 4)} | {quad_of(7, 6)}
    return (V, [f for k, f in enumerate(F) if k not in drop]), []


def zero_area():
    V, F = dome()
    n = len(V)
    V = np.r_[V, V[0] + np.array([[-3.0, 0.0, 0.0], [-6.0, 0.0, 0.0]])]
    return (V, F + [[0, n + 1, n]]), []


def needle():
    V, F = dome()
    n = len(V)
    # beside the edge (0,0)-(0,1) of the dome's rim: a 6 mm long, 0.001 mm wide sliver
    a, b = vid(0, 0), vid(0, 1)
    tip = (V[a] + V[b]) / 2 + np.array([-1e-3, 0.0, 0.0])
    V = np.r_[V, [tip]]
    return (V, F + [[a, b, n]]), []  # a -> b: the quad beside it runs b -> a (consistent winding)


def duplicate_vertices():
    V, F = dome()
    n = len(V)
    mid = [vid(5, j) for j in range(N + 1)]  # the middle row, shared by quads i = 4 and i = 5
    dup = {v: n + k for k, v in enumerate(mid)}
    V = np.r_[V, V[mid], V[[5]]]  # ... doubled; and a lone copy of vertex 5 (coincident, in no face)
    F = [[dup.get(v, v) if k >= quad_of(5, 0) else v for v in f] for k, f in enumerate(F)]
    return (V, F), []


def ngons_concave():
    V, F = dome()
    F = [list(f) for f in F]
    drop = set()
    # a hexagon from quads (2,2) and (2,3)
    hexagon = [vid(2, 2), vid(3, 2), vid(3, 3), vid(3, 4), vid(2, 4), vid(2, 3)]
    drop |= {quad_of(2, 2), quad_of(2, 3)}
    # an octagon from the four quads (6..7, 6..7) (its middle vertex (7,7) becomes loose: dropped below)
    octagon = [vid(6, 6), vid(7, 6), vid(8, 6), vid(8, 7), vid(8, 8), vid(7, 8), vid(6, 8), vid(6, 7)]
    drop |= {quad_of(i, j) for i in (6, 7) for j in (6, 7)}
    F = [f for k, f in enumerate(F) if k not in drop] + [hexagon, octagon]
    V = V.copy()
    # a concave quad: vertex (4,7) pulled in towards (5,8) past the quad's diagonal (4,8)-(5,7)
    c = vid(4, 7)
    V[c] = V[c] + 0.8 * (V[vid(5, 8)] - V[c])
    used = np.unique(np.concatenate([np.asarray(f) for f in F]))
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    return (V[used], [[int(remap[v]) for v in f] for f in F]), []


def loose():
    V, F = dome()
    n = len(V)
    V = np.r_[V, [[100.0, 0.0, 0.0], [110.0, 0.0, 0.0], [120.0, 5.0, 0.0], [-100.0, 0, 0], [-100.0, 10.0, 0]]]
    return (V, F), [(n + 1, n + 2), (n + 3, n + 4)]  # vertex n alone, two loose edges


def pieces():
    V1, F1 = dome(6, 30.0)
    V2, F2 = dome(6, 30.0, offset=(45.0, 0.0, 0.0))
    V3, F3 = dome(5, 25.0, offset=(0.0, 45.0, 5.0))
    n1, n2 = len(V1), len(V1) + len(V2)
    F = F1 + [[v + n1 for v in f] for f in F2] + [[v + n2 for v in f] for f in F3]
    return (np.r_[V1, V2, V3], F), []


def one_triangle():
    return (np.array([[0.0, 0.0, 0.0], [40.0, 0.0, 5.0], [10.0, 30.0, 0.0]]), [[0, 1, 2]]), []


def flipped_normals():
    V, F = dome()
    return (V, [f[::-1] if k >= quad_of(7, 0) else f for k, f in enumerate(F)]), []  # 30 of 100 quads


ARRAYS = {
    "clean": clean,
    "nonmanifold_edge": nonmanifold_edge,
    "holes": holes,
    "zero_area": zero_area,
    "needle": needle,
    "duplicate_vertices": duplicate_vertices,
    "ngons_concave": ngons_concave,
    "loose": loose,
    "pieces": pieces,
    "one_triangle": one_triangle,
    "flipped_normals": flipped_normals,
}


def arrays(name: str):
    """((V (n,3) mm, polygons as lists), loose edges) of an array case (no bpy)."""
    return ARRAYS[name]()


# ------------------------------------------------------------------------------ in Blender
@dataclass
class Case:
    name: str
    obj: object
    #: the object's mode the operators must leave it in
    mode: str = "OBJECT"
    notes: list = field(default_factory=list)


def make_mesh_object(bpy, V, F, E=(), name="skin"):
    """A mesh object from arrays (polygons of any size, loose edges), active and selected."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in np.asarray(V)], [tuple(map(int, e)) for e in E],
                   [tuple(map(int, f)) for f in F])
    me.validate()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    for o in list(bpy.context.selected_objects):
        o.select_set(False)
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    return ob


def mm_scene(bpy):
    sc = bpy.context.scene
    sc.unit_settings.system = "METRIC"
    sc.unit_settings.scale_length = 0.001
    return sc


def _from_arrays(fn):
    def build(bpy):
        mm_scene(bpy)
        (V, F), E = fn()
        return Case(fn.__name__, make_mesh_object(bpy, V, F, E))

    return build


def _modifiers(bpy):
    mm_scene(bpy)
    (V, F), _ = clean()
    ob = make_mesh_object(bpy, V, F)
    ob.modifiers.new("Subdivision", "SUBSURF").levels = 1
    tex = bpy.data.textures.new("bolus_corpus_noise", "CLOUDS")
    disp = ob.modifiers.new("Displace", "DISPLACE")
    disp.texture = tex
    disp.strength = 3.0
    return Case("modifiers", ob, notes=["operators read the mesh data, not the evaluated (modified) mesh"])


def _transformed(kind):
    def build(bpy):
        mm_scene(bpy)
        (V, F), _ = clean()
        ob = make_mesh_object(bpy, V, F)
        if kind == "scale_nonuniform":
            ob.scale = (1.5, 0.6, 1.0)
        elif kind == "scale_negative":
            ob.scale = (-1.0, 1.0, 1.0)
        else:
            ob.rotation_euler = (math.radians(120.0), math.radians(-35.0), math.radians(50.0))
            ob.location = (30.0, -20.0, 100.0)
        bpy.context.view_layer.update()
        return Case(kind, ob)

    build.__name__ = kind
    return build


def _edit_nothing_selected(bpy):
    mm_scene(bpy)
    (V, F), _ = clean()
    ob = make_mesh_object(bpy, V, F)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="DESELECT")
    return Case("edit_nothing_selected", ob, mode="EDIT")


def _nan(bpy):
    mm_scene(bpy)
    (V, F), _ = clean()
    ob = make_mesh_object(bpy, V, F)
    V = V.copy()
    V[NAN_VERTEX, 2] = math.nan  # after Mesh.validate(), which would set it to 0
    ob.data.vertices.foreach_set("co", V.ravel())
    ob.data.update()
    assert math.isnan(ob.data.vertices[NAN_VERTEX].co[2])
    return Case("nan", ob)


CASES = {name: _from_arrays(fn) for name, fn in ARRAYS.items()}
CASES.update({
    "modifiers": _modifiers,
    "scale_nonuniform": _transformed("scale_nonuniform"),
    "scale_negative": _transformed("scale_negative"),
    "rotated": _transformed("rotated"),
    "edit_nothing_selected": _edit_nothing_selected,
    "nan": _nan,
})
