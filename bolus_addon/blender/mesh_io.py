"""Blender mesh data <-> numpy arrays: units, attributes, colours, seams, new meshes.

The one world->mm conversion (`world_mm`, `mm_per_unit`); readers of face labels, corners
and edges; writers that put results back as attributes, always for the whole mesh, with a
fill value outside the region (the region itself is read by `mesh_region`).  Every reader
copies: the core never sees Blender memory, and the mesh is only written when an operator
has finished computing.
"""
from __future__ import annotations

import contextlib
import json

import bpy
import numpy as np

from ..core.errors import BolusError
from . import compat
from ..core.mesh.remesh_maps import label_range

__all__ = ["mm_per_unit", "world_mm", "get_array", "active_mesh_object", "read_face_labels", "object_mode",
           "write_attribute", "write_point_colors", "write_face_colors", "loop_edges_and_polygons",
           "polygon_edge_labels", "edges_of_polygons", "polygons_next_to", "set_seams", "show_colors",
           "polygon_corners", "new_mesh", "json_prop"]


def mm_per_unit(scene: bpy.types.Scene) -> float:
    """Millimetres in one Blender unit (SPEC: one unit = scale_length metres)."""
    return float(scene.unit_settings.scale_length) * 1000.0


def world_mm(co: np.ndarray, obj: bpy.types.Object, mm: float) -> np.ndarray:
    """Local coordinates co (n,3) of obj -> world coordinates in millimetres (n,3).

    The one world->mm conversion of the add-on; mm is `mm_per_unit(scene)`.  Non-finite
    input stays non-finite (`mesh_region.check_finite` names it)."""
    M = np.array(obj.matrix_world, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        return (np.asarray(co, dtype=np.float64) @ M[:3, :3].T + M[:3, 3]) * mm


def get_array(coll, attr: str, n: int, dtype, width: int = 1) -> np.ndarray:
    """A copy of ``coll``'s ``attr`` for its n elements: (n,) or (n, width) of ``dtype``.

    Through the mesh's own attribute where there is one (`compat.native_attribute`)."""
    native = compat.native_attribute(coll, attr, n * width)
    if native is not None:
        data, key, stored = native
        raw = np.empty(n * width, dtype=stored)
        data.foreach_get(key, raw)
        out = raw.astype(dtype, copy=False)
    else:
        out = np.empty(n * width, dtype=dtype)
        coll.foreach_get(attr, out)
    return out.reshape(-1, width) if width > 1 else out


def active_mesh_object(context) -> bpy.types.Object:
    """The active object, a mesh; else BolusError saying what to select."""
    obj = context.active_object
    if obj is None:
        raise BolusError("No active object: select the skin surface mesh first")
    if obj.type != "MESH":
        raise BolusError(f"'{obj.name}' is a {obj.type.lower()}, not a mesh: select the skin surface mesh")
    return obj


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
    native = compat.native_attribute(me.edges, "use_seam", ne)
    if native is None:  # no seam layer yet: no edge has a seam
        me.edges.foreach_set("use_seam", np.where(touched, seam, False))
        return
    data, key, dtype = native
    cur = np.empty(ne, dtype=dtype)
    data.foreach_get(key, cur)
    data.foreach_set(key, np.where(touched, seam, cur).astype(dtype))


def polygon_corners(me: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(loop_start (P,), loop_total (P,), loop vertex (L,)) of a mesh's polygons."""
    npoly = len(me.polygons)
    return (get_array(me.polygons, "loop_start", npoly, np.int64), get_array(me.polygons, "loop_total", npoly, np.int64),
            get_array(me.loops, "vertex_index", len(me.loops), np.int64))


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
    ``me.polygons`` and `mesh_region.read_region`) and the values are read from it.
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
