"""Writing a cut into a Blender mesh: `apply_cuts` (BMesh), the selection and hidden
state carried through it, and corner data (UV maps, colours) interpolated onto the new
faces.  The numeric maps (label ranges, old-edge lookup, corner weights) are in
`core.mesh.remesh_maps`; this module only reads and writes Blender data.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..core.errors import BolusError
from ..core.mesh.remesh_maps import corner_weights, label_range, pair_index
from .mesh_io import get_array, loop_edges_and_polygons, read_face_labels, write_attribute
from .mesh_region import Region

__all__ = ["apply_cuts"]


def apply_cuts(me: bpy.types.Mesh, region: Region, res, label_attr: str) -> np.ndarray:
    """Write a `core.cuts.cutlines.SmoothCutResult` into the mesh (object mode); returns polygon labels.

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
    tri_loops = _region_triangle_loops(me, region)
    attr = me.attributes.get(label_attr)
    if attr is not None and attr.data_type != "INT":  # e.g. INT8 from another tool: BMesh writes INT
        write_attribute(me, label_attr, "INT", "FACE", read_face_labels(me, label_attr))
    corner_data = _corner_attributes(me)
    nv_old = len(me.vertices)
    flags = _read_flags(me)
    out_poly = region.tri_poly[res.face_parent]  # (m',) polygon of every result face
    replaced, poly_label, touched = _replaced_polygons(len(me.polygons), region.tri_poly, out_poly, res)
    new_faces = np.nonzero(replaced[out_poly])[0]
    created_index, kept_old, kept_new, pieces = _rebuild(me, region, res, label_attr, out_poly, replaced,
                                                         poly_label, touched, new_faces)
    _interpolate_corners(me, region, res, new_faces, created_index, tri_loops, corner_data, nv_old)
    _carry_flags(me, flags, nv_old, np.r_[kept_new, created_index], np.r_[kept_old, out_poly[new_faces]], pieces)
    me.update()
    return read_face_labels(me, label_attr)


def _region_triangle_loops(me: bpy.types.Mesh, region: Region) -> np.ndarray:
    """(m,3) the corners (loops) of the region's triangles, checked against the mesh."""
    me.calc_loop_triangles()
    tri_loops = get_array(me.loop_triangles, "loops", len(me.loop_triangles), np.int64, 3)
    if region.tri_index is None or len(region.tri_index) != len(region.F) or (
        len(region.tri_index) and region.tri_index.max() >= len(tri_loops)
    ):
        raise BolusError("internal error: apply_cuts needs a region read from this mesh")
    return tri_loops[region.tri_index]


def _replaced_polygons(npoly: int, tri_poly, out_poly, res):
    """(replaced (p,) bool, label (p,) int, touched (p,) bool) of the mesh's polygons.

    A polygon is replaced when one of its triangles was split or its result faces got
    different labels; ``touched``: the polygon has result faces (its label is set)."""
    replaced = np.zeros(npoly, dtype=bool)
    replaced[tri_poly[res.split]] = True
    lo, hi, touched = label_range(out_poly, res.labels, npoly)
    replaced |= touched & (hi > lo)
    return replaced, np.where(touched, hi, 0), touched


def _rebuild(me, region, res, label_attr, out_poly, replaced, poly_label, touched, new_faces):
    """Replace the polygons in ``replaced`` by the result's triangles with BMesh.

    Returns (created_index (q,), kept_old (k,), kept_new (k,), pieces): the new mesh's
    index of every created face, the old and new index of every kept polygon, and
    (new edge index, old edge's vertex pair) of every piece of a split edge."""
    import bmesh

    co = get_array(me.vertices, "co", len(me.vertices), np.float64, 3)
    bm = bmesh.new()
    try:
        bm.from_mesh(me)
        bm.verts.ensure_lookup_table()
        bm.faces.ensure_lookup_table()
        layer = bm.faces.layers.int.get(label_attr) or bm.faces.layers.int.new(label_attr)
        verts, faces = list(bm.verts), list(bm.faces)  # index tables go stale once we add
        vmap, support = _new_vertices(bm, verts, faces, region, res, co)
        old_faces = [faces[int(p)] for p in np.nonzero(replaced)[0]]
        old_edges = {e for f in old_faces for e in f.edges}
        for f in np.nonzero(~replaced & touched)[0]:
            faces[int(f)][layer] = int(poly_label[f])
        created, split_edges = _new_faces(bm, layer, verts, faces, vmap, support, res, out_poly, new_faces)
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
    return created_index, kept_old, kept_new, pieces


def _new_vertices(bm, verts, faces, region, res, co):
    """BMesh vertices of the result (old ones reused, new ones interpolated) and, for
    each, the set of old vertices it is a combination of."""
    n_in = len(region.vert_ids)
    vmap = [verts[int(i)] for i in region.vert_ids]
    support = [frozenset((int(region.vert_ids[i]),)) for i in range(n_in)]
    for j in range(n_in, len(res.V)):
        src = region.vert_ids[res.vert_src[j]]
        w = res.vert_weights[j]
        v = bm.verts.new(tuple(w @ co[src]))
        v.copy_from_face_interp(faces[int(region.tri_poly[res.vert_parent[j]])])
        vmap.append(v)
        support.append(frozenset(int(s) for s, x in zip(src, w) if x != 0.0))
    return vmap, support


def _new_faces(bm, layer, verts, faces, vmap, support, res, out_poly, new_faces):
    """Create the result's triangles that replace polygons; new edges along a split
    input edge copy its data.  Returns (created faces, [(edge, old vertex pair)])."""
    created, split_edges = [], []
    for k in new_faces.tolist():
        tri = [int(i) for i in res.F[k]]
        f = bm.faces.new([vmap[i] for i in tri], faces[int(out_poly[k])])
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
    return created, split_edges


def _read_flags(me: bpy.types.Mesh) -> dict:
    """Selection and hidden state of every vertex, edge and polygon, and the edges' vertices (object mode)."""
    out = {"edge_verts": get_array(me.edges, "vertices", len(me.edges), np.int64, 2)}
    for kind, coll in (("vert", me.vertices), ("edge", me.edges), ("face", me.polygons)):
        for flag in ("select", "hide"):
            out[kind, flag] = get_array(coll, flag, len(coll), bool)
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
    loop_e, loop_p = loop_edges_and_polygons(me)
    loop_v = get_array(me.loops, "vertex_index", len(me.loops), np.int64)
    edge_old = pair_index(old["edge_verts"], get_array(me.edges, "vertices", ne, np.int64, 2), nv)
    piece_old = np.full(ne, -1, dtype=np.int64)
    if pieces:
        piece_old[np.array([i for i, _ in pieces], dtype=np.int64)] = pair_index(
            old["edge_verts"], np.array([p for _, p in pieces]), nv)

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
_DISCRETE = {"INT", "INT8", "BOOLEAN", "INT32_2D"}


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
    sum_c w_c * value(corner c of t), w = j's barycentric weights on t's corners
    (`core.mesh.remesh_maps.corner_weights`); integer and boolean attributes take the value
    of the corner with the largest weight.
    """
    if not corner_data or len(new_faces) == 0:
        return
    n_in = len(region.vert_ids)
    core_of_mesh = np.full(len(me.vertices), -1, dtype=np.int64)
    core_of_mesh[region.vert_ids] = np.arange(n_in)
    core_of_mesh[nv_old:] = np.arange(n_in, n_in + len(me.vertices) - nv_old)
    starts = get_array(me.polygons, "loop_start", len(me.polygons), np.int64)[created_index]
    loop_v = get_array(me.loops, "vertex_index", len(me.loops), np.int64)
    loops = starts[:, None] + np.arange(3)[None, :]  # (q,3) the new triangles' corners
    parent = res.face_parent[new_faces]  # (q,) input triangle of each new face
    W = corner_weights(core_of_mesh[loop_v[loops]], region.F[parent], res.vert_src, res.vert_weights)
    parent_loops = tri_loops[parent]  # (q,3)
    for name, (dtype, vals) in corner_data.items():
        pv = vals[parent_loops]  # (q,3 parent corners, width)
        if dtype in _DISCRETE:
            new = np.take_along_axis(pv, np.argmax(W, axis=2)[:, :, None], axis=1)
        else:
            new = np.einsum("qcp,qpw->qcw", W, pv)
        attr = me.attributes[name]
        out = np.empty(len(me.loops) * vals.shape[1], dtype=np.float64)
        attr.data.foreach_get(_CORNER_KEY[dtype], out)
        out = out.reshape(len(me.loops), -1)
        out[loops.ravel()] = new.reshape(-1, vals.shape[1])
        if dtype == "BOOLEAN":
            attr.data.foreach_set("value", out.ravel().astype(bool))
        elif dtype in _DISCRETE:
            attr.data.foreach_set("value", np.rint(out.ravel()).astype(np.int32))
        else:
            attr.data.foreach_set(_CORNER_KEY[dtype], out.ravel().astype(np.float32))
