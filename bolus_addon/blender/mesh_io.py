"""Blender mesh <-> numpy arrays, the only place that touches mesh data.

`read_region` turns the active object's mesh into a `Region`: world-space vertices in
millimetres, triangles from Blender's own triangulation (`loop_triangles`, which
handles concave n-gons) and the maps back to the mesh's vertices and polygons.
Writers put results back as attributes, always for the whole mesh, with a fill value
outside the region.  Every reader copies: the core never sees Blender memory, and the
mesh is only written when an operator has finished computing.
"""
from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.errors import BolusError
from ..core.mesh.remesh_maps import label_range
from ..core.mesh.topology import submesh

__all__ = ["Region", "mm_per_unit", "world_mm", "read_region", "size_warning", "check_finite", "read_face_labels", "object_mode", "write_attribute", "write_point_colors", "write_face_colors", "polygon_edge_labels", "edges_of_polygons", "polygons_next_to", "set_seams", "show_colors", "polygon_corners", "new_mesh", "json_prop"]


def mm_per_unit(scene: bpy.types.Scene) -> float:
    """Millimetres in one Blender unit (SPEC: one unit = scale_length metres)."""
    return float(scene.unit_settings.scale_length) * 1000.0


def world_mm(co: np.ndarray, obj: bpy.types.Object, mm: float) -> np.ndarray:
    """Local coordinates co (n,3) of obj -> world coordinates in millimetres (n,3).

    The one world->mm conversion of the add-on; mm is `mm_per_unit(scene)`.  Non-finite
    input stays non-finite (`check_finite` names it)."""
    M = np.array(obj.matrix_world, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        return (np.asarray(co, dtype=np.float64) @ M[:3, :3].T + M[:3, 3]) * mm


@dataclass
class Region:
    """The part of a mesh an operator works on (SPEC "The region").

    V (n,3) float64 world coordinates in mm of the region's vertices;
    F (m,3) int64 triangles indexing V;
    vert_ids (n,) mesh vertex index of each row of V;
    tri_poly (m,) mesh polygon index of each triangle;
    poly_ids (p,) the mesh polygons in the region;
    tri_index (m,) index of each triangle in ``mesh.loop_triangles``.
    """

    obj: bpy.types.Object
    V: np.ndarray
    F: np.ndarray
    vert_ids: np.ndarray
    tri_poly: np.ndarray
    poly_ids: np.ndarray
    mm_per_unit: float
    selection_only: bool
    warnings: list[str] = field(default_factory=list)
    tri_index: np.ndarray | None = None

    @property
    def mesh(self) -> bpy.types.Mesh:
        return self.obj.data

    def on_vertices(self, values, fill=0.0) -> np.ndarray:
        """Values (n, ...) on the region's vertices -> one per mesh vertex, ``fill`` (a scalar or
        one row, e.g. an RGBA colour) elsewhere."""
        values = np.asarray(values)
        out = np.full((len(self.mesh.vertices),) + values.shape[1:], fill, dtype=np.result_type(values, fill))
        out[self.vert_ids] = values
        return out

    def on_polygons(self, values, fill=-1) -> np.ndarray:
        """Values (m, ...) on the region's triangles -> one per mesh polygon (a polygon takes
        the value of its triangles, which must agree), ``fill`` outside the region."""
        values = np.asarray(values)
        out = np.full((len(self.mesh.polygons),) + values.shape[1:], fill, dtype=np.result_type(values, fill))
        out[self.tri_poly] = values
        return out


def get_array(coll, attr: str, n: int, dtype, width: int = 1) -> np.ndarray:
    out = np.empty(n * width, dtype=dtype)
    coll.foreach_get(attr, out)
    return out.reshape(-1, width) if width > 1 else out


def active_mesh_object(context) -> bpy.types.Object:
    obj = context.active_object
    if obj is None:
        raise BolusError("No active object: select the skin surface mesh first")
    if obj.type != "MESH":
        raise BolusError(f"'{obj.name}' is a {obj.type.lower()}, not a mesh: select the skin surface mesh")
    return obj


def read_region(context, obj: bpy.types.Object | None = None, polys: np.ndarray | None = None) -> Region:
    """Read the region (SPEC: selected faces in Edit Mode, else the whole mesh).

    polys (p,) bool: these polygons are the region whatever is selected (for operators
    that work on the patches, which were fixed by the region of `segment`).  Every
    region is checked here for every operator: NaN/inf coordinates are refused
    (`check_finite`), a size that says the units are wrong gives a warning (`size_warning`)."""
    obj = active_mesh_object(context) if obj is None else obj
    if obj.mode == "EDIT":
        obj.update_from_editmode()
    me = obj.data
    nv, npoly = len(me.vertices), len(me.polygons)
    if npoly == 0:
        raise BolusError(f"'{obj.name}' has no faces: the bolus tools need a surface mesh")
    warnings: list[str] = []
    selection_only = False
    region_poly = np.ones(npoly, dtype=bool)
    if polys is not None:
        region_poly = np.asarray(polys, dtype=bool)
        if region_poly.shape != (npoly,) or not region_poly.any():
            raise BolusError(f"internal error: a region of {region_poly.sum()} of {npoly} polygons")
    elif obj.mode == "EDIT":
        sel = get_array(me.polygons, "select", npoly, bool)
        if sel.any():
            region_poly = sel
            selection_only = True
        else:
            warnings.append("No faces selected in Edit Mode: using the whole mesh")
    me.calc_loop_triangles()
    nt = len(me.loop_triangles)
    tri_v = get_array(me.loop_triangles, "vertices", nt, np.int64, 3)
    tri_p = get_array(me.loop_triangles, "polygon_index", nt, np.int64)
    keep = region_poly[tri_p]
    tri_v, tri_p = tri_v[keep], tri_p[keep]
    co = get_array(me.vertices, "co", nv, np.float64, 3)
    scale = mm_per_unit(context.scene)
    F, vert_ids = submesh(tri_v, slice(None))
    V = world_mm(co[vert_ids], obj, scale)
    check_finite(obj, vert_ids, co[vert_ids], V)
    units = size_warning(V, scale)
    if units:
        warnings.append(units)
    if not selection_only and polys is None:
        warnings += _loose_warnings(me, len(vert_ids))
    warnings += modifier_warnings(obj)
    return Region(
        obj=obj,
        V=V,
        F=F,
        vert_ids=vert_ids,
        tri_poly=tri_p,
        poly_ids=np.nonzero(region_poly)[0],
        mm_per_unit=scale,
        selection_only=selection_only,
        warnings=warnings,
        tri_index=np.nonzero(keep)[0],
    )


def modifier_warnings(obj: bpy.types.Object) -> list[str]:
    """A warning when the object shows modifiers: the bolus tools read its mesh data, without them."""
    mods = [m.name for m in obj.modifiers if m.show_viewport]
    if not mods:
        return []
    return [f"'{obj.name}' has {len(mods)} modifier(s) ({', '.join(mods)}) that the bolus tools do not see: they "
            "work on the mesh as it is without them (as in Edit Mode); to use the shape shown, apply them first "
            "(Object > Apply > Visual Geometry to Mesh)"]


def _loose_warnings(me: bpy.types.Mesh, used_vertices: int) -> list[str]:
    """Warnings for the vertices and edges of the whole mesh that are in no face."""
    out = []
    loose = len(me.vertices) - used_vertices
    if loose:
        out.append(f"{loose} loose vertices (in no face) were ignored")
    ne = len(me.edges)
    if ne:
        edges_in_faces = np.zeros(ne, dtype=bool)
        edges_in_faces[get_array(me.loops, "edge_index", len(me.loops), np.int64)] = True
        nloose = int(ne - edges_in_faces.sum())
        if nloose:
            out.append(f"{nloose} loose edges (in no face) were ignored")
    return out


def check_finite(obj: bpy.types.Object, vert_ids: np.ndarray, co: np.ndarray, V: np.ndarray) -> None:
    """Refuse NaN or infinite coordinates (local ``co`` or world ``V``, both (n,3)) with the vertex index."""
    bad = ~np.isfinite(V).all(axis=1)
    if not bad.any():
        return
    k = int(np.argmax(bad))
    first = int(vert_ids[k])
    where = ", ".join(f"{x:g}" for x in co[k])
    more = f" ({int(bad.sum())} vertices in all)" if bad.sum() > 1 else ""
    if np.isfinite(co[k]).all():
        raise BolusError(
            f"'{obj.name}' has a transform that makes vertex {first} infinite or NaN in world space{more}: "
            "fix the object's scale/rotation (Object > Apply > All Transforms, or Alt+S/Alt+R to clear)"
        )
    raise BolusError(
        f"vertex {first} of '{obj.name}' has an invalid coordinate ({where}){more}: a bolus needs finite "
        "coordinates; delete or fix such vertices first (e.g. re-export the surface from the planning system)"
    )


#: a region outside this size range (bounding-box diagonal, mm) is probably in the wrong units
MIN_SIZE_MM = 5.0
MAX_SIZE_MM = 3000.0
#: (unit scale, what a file in that unit needs) offered when the size looks wrong
_UNIT_SCALES = ((0.001, "mm"), (0.01, "cm"), (1.0, "m"))


def size_warning(V: np.ndarray, mm_per_unit_: float) -> str | None:
    """A warning when the region (V (n,3) mm) is larger than 3 m or smaller than 5 mm across.

    The usual cause is a file in other units than the scene's (an STL in mm in a scene
    of 1 unit = 1 m); the advice names the Unit Scale that would give a body-sized region.
    """
    if len(V) == 0:
        return None
    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    if MIN_SIZE_MM <= diag <= MAX_SIZE_MM or diag == 0.0:
        return None
    units = diag / mm_per_unit_  # the size in Blender units
    current = mm_per_unit_ / 1000.0
    # the unit scale giving a size closest (log) to a typical treatment region, 200 mm
    best = min(_UNIT_SCALES, key=lambda su: abs(np.log(units * su[0] * 1000.0 / 200.0)))
    size = f"{diag / 1000.0:.4g} m" if diag > MAX_SIZE_MM else f"{diag:.3g} mm"
    kind = "larger than 3 m" if diag > MAX_SIZE_MM else "smaller than 5 mm"
    advice = (
        f"if the mesh is in {best[1]}{' (as STLs from planning systems are)' if best[1] == 'mm' else ''}, "
        f"set Scene > Units > Unit Scale "
        f"to {best[0]:g} (now {current:g}; then it is {units * best[0] * 1000.0:.3g} mm across), or scale the object"
        if best[0] != current
        else "check the units of the file and scale the object to its real size"
    )
    return (f"The region is {size} across (bounding-box diagonal), {kind}: the scene's units are probably wrong; "
            f"{advice}. Sizes, areas and patterns are only right at true scale.")


@contextlib.contextmanager
def object_mode(obj: bpy.types.Object):
    """Leave Edit Mode for the duration of a write (edit-mesh data would overwrite it)."""
    was_edit = obj.mode == "EDIT"
    if was_edit:
        bpy.ops.object.mode_set(mode="OBJECT")
    try:
        yield
    finally:
        if was_edit:
            bpy.ops.object.mode_set(mode="EDIT")


_SIZE = {"POINT": lambda me: len(me.vertices), "FACE": lambda me: len(me.polygons), "EDGE": lambda me: len(me.edges)}


def write_attribute(me: bpy.types.Mesh, name: str, kind: str, domain: str, values: np.ndarray) -> None:
    """Create or replace attribute ``name`` (kind 'FLOAT' or 'INT') on ``domain``."""
    values = np.asarray(values)
    if len(values) != _SIZE[domain](me):
        raise BolusError(f"internal error: {name} has {len(values)} values for the {domain} domain")
    attr = me.attributes.get(name)
    if attr is not None and (attr.data_type != kind or attr.domain != domain):
        me.attributes.remove(attr)
        attr = None
    if attr is None:
        attr = me.attributes.new(name=name, type=kind, domain=domain)
    dtype = np.float32 if kind == "FLOAT" else np.int32
    attr.data.foreach_set("value", values.astype(dtype).ravel())


def write_point_colors(me: bpy.types.Mesh, name: str, rgba: np.ndarray) -> None:
    """Create or replace a FLOAT_COLOR point attribute and make it the displayed one."""
    _write_colors(me, name, "POINT", rgba)


def write_face_colors(me: bpy.types.Mesh, name: str, rgba_per_face: np.ndarray) -> None:
    """Flat colour per polygon, stored on corners (colour attributes have no face domain)."""
    _, loop_p = loop_edges_and_polygons(me)
    _write_colors(me, name, "CORNER", np.asarray(rgba_per_face)[loop_p])


def _write_colors(me: bpy.types.Mesh, name: str, domain: str, rgba: np.ndarray) -> None:
    attr = me.color_attributes.get(name)
    if attr is not None and (attr.data_type != "FLOAT_COLOR" or attr.domain != domain):
        me.color_attributes.remove(attr)
        attr = None
    if attr is None:
        attr = me.color_attributes.new(name=name, type="FLOAT_COLOR", domain=domain)
    attr.data.foreach_set("color", np.asarray(rgba, dtype=np.float32).ravel())
    show_colors(me, name)


def show_colors(me: bpy.types.Mesh, name: str) -> None:
    """Make colour attribute ``name`` the active and the rendered one."""
    attr = me.color_attributes[name]
    me.color_attributes.active_color = attr
    me.color_attributes.render_color_index = list(me.color_attributes).index(attr)


def loop_edges_and_polygons(me: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(edge index, polygon index) of every loop (corner) of the mesh."""
    npoly = len(me.polygons)
    loop_e = get_array(me.loops, "edge_index", len(me.loops), np.int64)
    starts = get_array(me.polygons, "loop_start", npoly, np.int64)
    totals = get_array(me.polygons, "loop_total", npoly, np.int64)
    order = np.argsort(starts, kind="stable")  # each polygon's loops are contiguous
    return loop_e, np.repeat(order, totals[order])


def polygon_edge_labels(me: bpy.types.Mesh, poly_labels: np.ndarray) -> np.ndarray:
    """(e,) bool: mesh edges whose adjacent polygons carry different labels."""
    loop_e, loop_p = loop_edges_and_polygons(me)
    lo, hi, present = label_range(loop_e, np.asarray(poly_labels, dtype=np.int64)[loop_p], len(me.edges))
    return present & (hi > lo)


def edges_of_polygons(me: bpy.types.Mesh, poly_ids: np.ndarray) -> np.ndarray:
    """(e,) bool: the edges used by the given polygons."""
    loop_e, loop_p = loop_edges_and_polygons(me)
    mark = np.zeros(len(me.polygons), dtype=bool)
    mark[poly_ids] = True
    out = np.zeros(len(me.edges), dtype=bool)
    out[loop_e[mark[loop_p]]] = True
    return out


def polygons_next_to(me: bpy.types.Mesh, mask: np.ndarray) -> np.ndarray:
    """(p,) bool: the polygons outside ``mask`` (p,) that share an edge with a polygon in it."""
    loop_e, loop_p = loop_edges_and_polygons(me)
    edge_in = np.zeros(len(me.edges), dtype=bool)
    edge_in[loop_e[mask[loop_p]]] = True
    out = np.zeros(len(me.polygons), dtype=bool)
    out[loop_p[edge_in[loop_e]]] = True
    return out & ~mask


def set_seams(me: bpy.types.Mesh, seam: np.ndarray, touched: np.ndarray) -> None:
    """Set use_seam = seam on the edges where ``touched`` is True; keep the others."""
    ne = len(me.edges)
    cur = get_array(me.edges, "use_seam", ne, bool)
    new = np.where(touched, seam, cur)
    me.edges.foreach_set("use_seam", new)


def polygon_corners(me: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(loop_start (P,), loop_total (P,), loop vertex (L,)) of a mesh's polygons."""
    out = [np.empty(n, dtype=np.int64) for n in (len(me.polygons), len(me.polygons), len(me.loops))]
    me.polygons.foreach_get("loop_start", out[0])
    me.polygons.foreach_get("loop_total", out[1])
    me.loops.foreach_get("vertex_index", out[2])
    return out[0], out[1], out[2]


def new_mesh(name: str, co: np.ndarray, corner_vert: np.ndarray, loop_starts: np.ndarray) -> bpy.types.Mesh:
    """A mesh from vertex positions (N,3), polygon corners (c,) and their first corners (p,)."""
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(co))
    me.vertices.foreach_set("co", co.ravel())
    me.loops.add(len(corner_vert))
    me.loops.foreach_set("vertex_index", corner_vert)
    me.polygons.add(len(loop_starts))
    me.polygons.foreach_set("loop_start", loop_starts)
    me.update(calc_edges=True)
    me.validate(clean_customdata=False)
    return me


def json_prop(ob, key: str):
    """The JSON table an operator left in custom property ``key`` of ``ob``, or None (no
    object, no property, or not readable: callers then show or use no table)."""
    if ob is None or key not in ob:
        return None
    try:
        return json.loads(ob[key])
    except (ValueError, TypeError):
        return None


def _edit_owner(me: bpy.types.Mesh) -> bpy.types.Object | None:
    """The object editing ``me`` in Edit Mode, if any."""
    for ob in bpy.data.objects:
        if ob.data is me and ob.mode == "EDIT":
            return ob
    return None


def read_face_labels(data: bpy.types.Mesh | bpy.types.Object, name: str) -> np.ndarray | None:
    """(p,) int values of the FACE attribute ``name`` of a mesh (or an object's mesh), or None.

    Safe in Edit Mode, where attribute data lives in the edit-mesh (the mesh's own arrays
    read as empty): the edit-mesh is written back first (so the result matches
    ``me.polygons`` and `read_region`) and the values are read from it.
    """
    obj = data if isinstance(data, bpy.types.Object) else None
    me = obj.data if obj is not None else data
    attr = me.attributes.get(name)
    if attr is None or attr.domain != "FACE" or attr.data_type not in {"INT", "INT8"}:
        return None
    if me.is_editmode:
        obj = obj if obj is not None and obj.mode == "EDIT" else _edit_owner(me)
        if obj is not None:
            obj.update_from_editmode()
        import bmesh  # noqa: PLC0415 (only under Blender)

        bm = bmesh.from_edit_mesh(me)
        layer = bm.faces.layers.int.get(name)
        if layer is not None:
            return np.fromiter((f[layer] for f in bm.faces), dtype=np.int64, count=len(bm.faces))
        if obj is None:  # pragma: no cover - an edit-mesh always has an object in Edit Mode
            raise BolusError(f"internal error: cannot read '{name}' in Edit Mode")
        with object_mode(obj):  # INT8 layers have no bmesh accessor
            return read_face_labels(me, name)
    out = np.empty(len(me.polygons), dtype=np.int64)
    attr.data.foreach_get("value", out)
    return out
