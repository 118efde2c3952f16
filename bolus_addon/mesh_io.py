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
from dataclasses import dataclass, field

import bpy
import numpy as np

from .core.errors import BolusError
from .core.topology import submesh

__all__ = ["Region", "mm_per_unit", "world_mm", "read_region", "size_warning", "check_finite", "read_face_labels", "apply_cuts", "object_mode", "write_attribute", "write_point_colors", "write_face_colors", "polygon_edge_labels", "edges_of_polygons", "polygons_next_to", "set_seams", "show_colors"]


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


def _get(coll, attr: str, n: int, dtype, width: int = 1) -> np.ndarray:
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
        sel = _get(me.polygons, "select", npoly, bool)
        if sel.any():
            region_poly = sel
            selection_only = True
        else:
            warnings.append("No faces selected in Edit Mode: using the whole mesh")
    me.calc_loop_triangles()
    nt = len(me.loop_triangles)
    tri_v = _get(me.loop_triangles, "vertices", nt, np.int64, 3)
    tri_p = _get(me.loop_triangles, "polygon_index", nt, np.int64)
    keep = region_poly[tri_p]
    tri_v, tri_p = tri_v[keep], tri_p[keep]
    co = _get(me.vertices, "co", nv, np.float64, 3)
    scale = mm_per_unit(context.scene)
    F, vert_ids = submesh(tri_v, slice(None))
    V = world_mm(co[vert_ids], obj, scale)
    check_finite(obj, vert_ids, co[vert_ids], V)
    units = size_warning(V, scale)
    if units:
        warnings.append(units)
    if not selection_only and polys is None:
        loose = nv - len(vert_ids)
        if loose:
            warnings.append(f"{loose} loose vertices (in no face) were ignored")
        ne = len(me.edges)
        if ne:
            loop_e = _get(me.loops, "edge_index", len(me.loops), np.int64)
            edges_in_faces = np.zeros(ne, dtype=bool)
            edges_in_faces[loop_e] = True
            nloose = int(ne - edges_in_faces.sum())
            if nloose:
                warnings.append(f"{nloose} loose edges (in no face) were ignored")
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
    _, loop_p = _loop_edges_and_polygons(me)
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


def _loop_edges_and_polygons(me: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(edge index, polygon index) of every loop (corner) of the mesh."""
    npoly = len(me.polygons)
    loop_e = _get(me.loops, "edge_index", len(me.loops), np.int64)
    starts = _get(me.polygons, "loop_start", npoly, np.int64)
    totals = _get(me.polygons, "loop_total", npoly, np.int64)
    order = np.argsort(starts, kind="stable")  # each polygon's loops are contiguous
    return loop_e, np.repeat(order, totals[order])


def polygon_edge_labels(me: bpy.types.Mesh, poly_labels: np.ndarray) -> np.ndarray:
    """(e,) bool: mesh edges whose adjacent polygons carry different labels."""
    loop_e, loop_p = _loop_edges_and_polygons(me)
    lab = np.asarray(poly_labels, dtype=np.int64)[loop_p]
    ne = len(me.edges)
    lo = np.full(ne, np.iinfo(np.int64).max)
    hi = np.full(ne, np.iinfo(np.int64).min)
    np.minimum.at(lo, loop_e, lab)
    np.maximum.at(hi, loop_e, lab)
    return (hi > lo) & (hi != np.iinfo(np.int64).min)


def edges_of_polygons(me: bpy.types.Mesh, poly_ids: np.ndarray) -> np.ndarray:
    """(e,) bool: the edges used by the given polygons."""
    loop_e, loop_p = _loop_edges_and_polygons(me)
    mark = np.zeros(len(me.polygons), dtype=bool)
    mark[poly_ids] = True
    out = np.zeros(len(me.edges), dtype=bool)
    out[loop_e[mark[loop_p]]] = True
    return out


def polygons_next_to(me: bpy.types.Mesh, mask: np.ndarray) -> np.ndarray:
    """(p,) bool: the polygons outside ``mask`` (p,) that share an edge with a polygon in it."""
    loop_e, loop_p = _loop_edges_and_polygons(me)
    edge_in = np.zeros(len(me.edges), dtype=bool)
    edge_in[loop_e[mask[loop_p]]] = True
    out = np.zeros(len(me.polygons), dtype=bool)
    out[loop_p[edge_in[loop_e]]] = True
    return out & ~mask


def set_seams(me: bpy.types.Mesh, seam: np.ndarray, touched: np.ndarray) -> None:
    """Set use_seam = seam on the edges where ``touched`` is True; keep the others."""
    ne = len(me.edges)
    cur = _get(me.edges, "use_seam", ne, bool)
    new = np.where(touched, seam, cur)
    me.edges.foreach_set("use_seam", new)


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


def apply_cuts(me: bpy.types.Mesh, region: Region, res, label_attr: str) -> np.ndarray:
    """Write a `core.cutlines.SmoothCutResult` into the mesh (object mode); returns polygon labels.

    Polygons whose triangles were split (or got different labels) are replaced by the
    result's triangles; every other polygon keeps its vertices, corners and data.  New
    vertices get their data (vertex groups, point attributes) interpolated by Blender
    from the polygon they lie in (``BMVert.copy_from_face_interp``); the corners of the
    new faces (UV maps, corner colours and other corner attributes) are interpolated
    here with the barycentric weights of the result in the input triangle they lie in
    (`_interpolate_corners`: ``BMLoop/BMFace.copy_from_face_interp`` raise a SystemError
    in Blender 4.2); new edges along a split edge copy that edge's data (seams,
    sharpness, creases); ``label_attr`` (a FACE INT attribute) is set from
    ``res.labels``.  The region (e.g. ``read_region(polys=patch faces)``) must have
    been read from the mesh as it is; polygons outside it are not touched.
    The selection and hidden state follow the region (`_carry_flags`): a new face is
    selected (hidden) iff the polygon it came from was.
    """
    import bmesh

    me.calc_loop_triangles()
    tri_loops = _get(me.loop_triangles, "loops", len(me.loop_triangles), np.int64, 3)
    if region.tri_index is None or len(region.tri_index) != len(region.F) or (
        len(region.tri_index) and region.tri_index.max() >= len(tri_loops)
    ):
        raise BolusError("internal error: apply_cuts needs a region read from this mesh")
    tri_loops = tri_loops[region.tri_index]
    attr = me.attributes.get(label_attr)
    if attr is not None and attr.data_type != "INT":  # e.g. INT8 from another tool: BMesh writes INT
        write_attribute(me, label_attr, "INT", "FACE", read_face_labels(me, label_attr))
    corner_data = _corner_attributes(me)
    nv_old = len(me.vertices)
    flags = _read_flags(me)

    npoly = len(me.polygons)
    tri_poly = region.tri_poly
    out_poly = tri_poly[res.face_parent]  # (m',) polygon of every result face
    replaced = np.zeros(npoly, dtype=bool)
    replaced[tri_poly[res.split]] = True
    lo = np.full(npoly, np.iinfo(np.int64).max)
    hi = np.full(npoly, np.iinfo(np.int64).min)
    np.minimum.at(lo, out_poly, res.labels)
    np.maximum.at(hi, out_poly, res.labels)
    replaced |= (hi > lo) & (hi != np.iinfo(np.int64).min)
    poly_label = np.where(hi != np.iinfo(np.int64).min, hi, 0)

    co = _get(me.vertices, "co", len(me.vertices), np.float64, 3)
    bm = bmesh.new()
    try:
        bm.from_mesh(me)
        bm.verts.ensure_lookup_table()
        bm.faces.ensure_lookup_table()
        layer = bm.faces.layers.int.get(label_attr) or bm.faces.layers.int.new(label_attr)
        verts, faces = list(bm.verts), list(bm.faces)  # index tables go stale once we add
        n_in = len(region.vert_ids)
        vmap = [verts[int(i)] for i in region.vert_ids]
        support = [frozenset((int(region.vert_ids[i]),)) for i in range(n_in)]
        for j in range(n_in, len(res.V)):
            src = region.vert_ids[res.vert_src[j]]
            w = res.vert_weights[j]
            v = bm.verts.new(tuple(w @ co[src]))
            v.copy_from_face_interp(faces[int(tri_poly[res.vert_parent[j]])])
            vmap.append(v)
            support.append(frozenset(int(s) for s, x in zip(src, w) if x != 0.0))
        old_faces = [faces[int(p)] for p in np.nonzero(replaced)[0]]
        old_edges = {e for f in old_faces for e in f.edges}
        for f in np.nonzero(~replaced & (hi != np.iinfo(np.int64).min))[0]:
            faces[int(f)][layer] = int(poly_label[f])
        new_faces = np.nonzero(replaced[out_poly])[0]
        created = []
        split_edges = []  # (new edge, the vertex pair of the input edge it is a piece of)
        for k in new_faces.tolist():
            src_face = faces[int(out_poly[k])]
            tri = [int(i) for i in res.F[k]]
            f = bm.faces.new([vmap[i] for i in tri], src_face)
            f[layer] = int(res.labels[k])
            created.append(f)
            for a, b in ((0, 1), (1, 2), (2, 0)):
                sa, sb = support[tri[a]], support[tri[b]]
                both = sa | sb
                if len(both) != 2 or (len(sa) == 1 and len(sb) == 1):
                    continue  # not a piece of a split input edge
                u, v = (verts[i] for i in both)
                orig = bm.edges.get((u, v))
                e = bm.edges.get((vmap[tri[a]], vmap[tri[b]]))
                if orig is not None and e is not None and e is not orig:
                    e.copy_from(orig)
                    split_edges.append((e, tuple(both)))
        bmesh.ops.delete(bm, geom=old_faces, context="FACES_ONLY")
        for e in old_edges:
            if e.is_valid and not e.link_faces:
                bm.edges.remove(e)
        bm.faces.index_update()
        bm.edges.index_update()
        created_index = np.array([f.index for f in created], dtype=np.int64)
        kept_old = np.nonzero(~replaced)[0]
        kept_new = np.array([faces[int(i)].index for i in kept_old], dtype=np.int64)
        pieces = [(e.index, pair) for e, pair in split_edges if e.is_valid]
        bm.to_mesh(me)
    finally:
        bm.free()
    _interpolate_corners(me, region, res, new_faces, created_index, tri_loops, corner_data, nv_old)
    _carry_flags(me, flags, nv_old, np.r_[kept_new, created_index], np.r_[kept_old, out_poly[new_faces]], pieces)
    me.update()
    return read_face_labels(me, label_attr)


def _read_flags(me: bpy.types.Mesh) -> dict:
    """Selection and hidden state of every vertex, edge and polygon, and the edges' vertices (object mode)."""
    out = {"edge_verts": np.sort(_get(me.edges, "vertices", len(me.edges), np.int64, 2), axis=1)}
    for kind, coll in (("vert", me.vertices), ("edge", me.edges), ("face", me.polygons)):
        for flag in ("select", "hide"):
            out[kind, flag] = _get(coll, flag, len(coll), bool)
    return out


def _carry_flags(me: bpy.types.Mesh, old: dict, nv_old: int, face_new: np.ndarray, face_src: np.ndarray,
                 pieces: list) -> None:
    """Make selection and hiding follow the region through `apply_cuts`' re-meshing.

    ``old`` the `_read_flags` of the mesh before; vertices below ``nv_old`` are the old
    ones; ``face_new`` (f,) every polygon of the new mesh, ``face_src`` (f,) the old
    polygon it is or came from; ``pieces`` (new edge index, old edge's vertex pair).
    A face is selected (hidden) iff its polygon was; an edge or vertex is selected iff it
    lies on a selected face or was selected before (a piece of a selected edge too), and
    hidden iff it was or, when new, iff all its faces are; nothing hidden is selected.
    (``bmesh.ops.delete`` flushes the vertex selection into the faces, which scrambled it.)
    """
    npoly, nv, ne = len(me.polygons), len(me.vertices), len(me.edges)
    fhide = np.zeros(npoly, dtype=bool)
    fsel = np.zeros(npoly, dtype=bool)
    fhide[face_new] = old["face", "hide"][face_src]
    fsel[face_new] = old["face", "select"][face_src] & ~fhide[face_new]
    loop_e, loop_p = _loop_edges_and_polygons(me)
    loop_v = _get(me.loops, "vertex_index", len(me.loops), np.int64)
    # old edges by their (sorted) vertex pair: an edge of the new mesh is old iff its pair was
    old_keys = old["edge_verts"][:, 0] * nv + old["edge_verts"][:, 1]
    order = np.argsort(old_keys)
    sorted_keys = old_keys[order]

    def old_edge_of(pairs: np.ndarray) -> np.ndarray:
        """(k,) old edge index of each vertex pair (k,2), or -1."""
        pairs = np.sort(pairs, axis=1)
        keys = pairs[:, 0] * nv + pairs[:, 1]
        pos = np.minimum(np.searchsorted(sorted_keys, keys), len(order) - 1)
        return np.where(sorted_keys[pos] == keys, order[pos], -1)

    edge_old = old_edge_of(_get(me.edges, "vertices", ne, np.int64, 2))
    piece_old = np.full(ne, -1, dtype=np.int64)
    if pieces:
        piece_old[np.array([i for i, _ in pieces], dtype=np.int64)] = old_edge_of(np.array([p for _, p in pieces]))

    def flags_of(n, elem_of_loop, was, kind):
        """(select, hide) of n vertices or edges; was (n,) old index or -1."""
        faces_at = np.bincount(elem_of_loop, minlength=n)
        hidden_at = np.bincount(elem_of_loop, weights=fhide[loop_p], minlength=n)
        on_sel = np.zeros(n, dtype=bool)
        on_sel[elem_of_loop[fsel[loop_p]]] = True
        hide = np.where(was >= 0, old[kind, "hide"][np.maximum(was, 0)], (faces_at > 0) & (hidden_at == faces_at))
        sel = on_sel | ((was >= 0) & old[kind, "select"][np.maximum(was, 0)])
        return sel & ~hide, hide

    vert_old = np.where(np.arange(nv) < nv_old, np.arange(nv), -1)
    vsel, vhide = flags_of(nv, loop_v, vert_old, "vert")
    esel, ehide = flags_of(ne, loop_e, edge_old, "edge")
    esel |= (piece_old >= 0) & old["edge", "select"][np.maximum(piece_old, 0)] & ~ehide
    for coll, sel, hide in ((me.vertices, vsel, vhide), (me.edges, esel, ehide), (me.polygons, fsel, fhide)):
        coll.foreach_set("hide", hide)
        coll.foreach_set("select", sel)


_CORNER_WIDTH = {"FLOAT": 1, "FLOAT2": 2, "FLOAT_VECTOR": 3, "FLOAT_COLOR": 4, "BYTE_COLOR": 4, "INT": 1,
                 "INT8": 1, "BOOLEAN": 1, "INT32_2D": 2, "QUATERNION": 4}
_CORNER_KEY = {"FLOAT": "value", "FLOAT2": "vector", "FLOAT_VECTOR": "vector", "FLOAT_COLOR": "color",
               "BYTE_COLOR": "color", "INT": "value", "INT8": "value", "BOOLEAN": "value", "INT32_2D": "value",
               "QUATERNION": "value"}


def _corner_attributes(me: bpy.types.Mesh) -> dict:
    """{name: (data_type, values (loops, width))} of the user-visible corner attributes."""
    out = {}
    for attr in me.attributes:
        if attr.domain != "CORNER" or attr.name.startswith(".") or attr.data_type not in _CORNER_WIDTH:
            continue
        w = _CORNER_WIDTH[attr.data_type]
        vals = np.empty(len(me.loops) * w, dtype=np.float64)
        attr.data.foreach_get(_CORNER_KEY[attr.data_type], vals)
        out[attr.name] = (attr.data_type, vals.reshape(-1, w))
    return out


def _interpolate_corners(me, region, res, new_faces, created_index, tri_loops, corner_data, nv_old) -> None:
    """Corner attributes of the new faces from the input triangle each lies in.

    A corner at result vertex j of a face lying in input triangle t gets
    sum_c w_c * value(corner c of t), w = j's barycentric weights on t's corners;
    integer and boolean attributes take the value of the corner with the largest weight.
    """
    if not corner_data or len(new_faces) == 0:
        return
    n_in = len(region.vert_ids)
    core_of_mesh = np.full(len(me.vertices), -1, dtype=np.int64)
    core_of_mesh[region.vert_ids] = np.arange(n_in)
    core_of_mesh[nv_old:] = np.arange(n_in, n_in + len(me.vertices) - nv_old)
    starts = _get(me.polygons, "loop_start", len(me.polygons), np.int64)[created_index]
    loop_v = _get(me.loops, "vertex_index", len(me.loops), np.int64)
    loops = starts[:, None] + np.arange(3)[None, :]  # (q,3) the new triangles' corners
    j = core_of_mesh[loop_v[loops]]  # (q,3) result vertex of each corner
    parent = res.face_parent[new_faces]  # (q,) input triangle of each new face
    corners = region.F[parent]  # (q,3) input (region) vertices of the parent triangle
    src = res.vert_src[j]  # (q,3,3)
    w = res.vert_weights[j]
    W = np.zeros((len(new_faces), 3, 3))  # corner x parent corner
    for c in range(3):
        W[:, :, c] = np.where(src == corners[:, None, c, None], w, 0.0).sum(axis=2)
    W /= np.maximum(W.sum(axis=2, keepdims=True), 1e-300)
    parent_loops = tri_loops[parent]  # (q,3)
    for name, (dtype, vals) in corner_data.items():
        pv = vals[parent_loops]  # (q,3 parent corners, width)
        if dtype in {"INT", "INT8", "BOOLEAN", "INT32_2D"}:
            pick = np.argmax(W, axis=2)  # (q,3)
            new = np.take_along_axis(pv, pick[:, :, None], axis=1)
        else:
            new = np.einsum("qcp,qpw->qcw", W, pv)
        attr = me.attributes[name]
        out = np.empty(len(me.loops) * vals.shape[1], dtype=np.float64)
        attr.data.foreach_get(_CORNER_KEY[dtype], out)
        out = out.reshape(len(me.loops), -1)
        out[loops.ravel()] = new.reshape(-1, vals.shape[1])
        if dtype == "BOOLEAN":
            attr.data.foreach_set("value", out.ravel().astype(bool))
        elif dtype in {"INT", "INT8", "INT32_2D"}:
            attr.data.foreach_set("value", np.rint(out.ravel()).astype(np.int32))
        else:
            attr.data.foreach_set(_CORNER_KEY[dtype], out.ravel().astype(np.float32))
