"""The region an operator works on (SPEC "The region"), read from Blender and checked.

`read_region` turns the active object's mesh into a `Region`: world-space vertices in
millimetres, triangles from Blender's own triangulation (`loop_triangles`, which handles
concave n-gons) and the maps back to the mesh's vertices and polygons.  Every region is
checked here for every operator: NaN/inf coordinates are refused (`check_finite`), a size
that says the scene's units are wrong (`size_warning`), loose vertices and edges and
modifiers the tools do not see give warnings.  Reading copies: the core never sees Blender
memory.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.errors import BolusError
from ..core.mesh.topology import submesh
from .mesh_io import active_mesh_object, get_array, mm_per_unit, world_mm

__all__ = ["Region", "read_region", "size_warning", "check_finite", "modifier_warnings"]


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
