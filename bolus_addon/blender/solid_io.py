"""A bolus solid's Blender data: triangle meshes in world units, and the two meshes a bolus keeps.

Make Bolus writes the bolus object ``<name>_bolus`` and keeps two mesh datablocks with a fake
user, named in its custom properties: the skin region it was made on (``<name>_bolus_skin``)
and the plain solid before its labels were engraved (``<name>_bolus_solid``, with
``bolus_shell_side``).  Split into Print Parts reads them back (`stored_solid`), so a re-run
starts again from the plain solid.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..core.errors import BolusError
from . import mesh_io
from .objects import ATTR_SHELL_SIDE, PROP_PREFIX, PROP_SKIN_MESH, PROP_SOLID_MESH, PROP_SOURCE


def tri_mesh(name: str, co: np.ndarray, F: np.ndarray) -> bpy.types.Mesh:
    """A mesh of triangles F (m,3) on vertex positions co (n,3) in world units."""
    F = np.asarray(F, dtype=np.int64)
    me = mesh_io.new_mesh(name, np.asarray(co, dtype=np.float64), F.reshape(-1), np.arange(0, 3 * len(F), 3))
    if len(me.polygons) != len(F):
        bpy.data.meshes.remove(me)
        raise BolusError(f"internal error: Blender dropped {len(F) - len(me.polygons)} invalid triangles of '{name}'")
    return me


def read_tri_mesh(me: bpy.types.Mesh, mm: float) -> tuple[np.ndarray, np.ndarray]:
    """(V (n,3) mm, F (m,3) int64) of a mesh of triangles stored in world units (no transform)."""
    V = mesh_io.get_array(me.vertices, "co", len(me.vertices), np.float64, 3) * mm
    me.calc_loop_triangles()
    F = mesh_io.get_array(me.loop_triangles, "vertices", len(me.loop_triangles), np.int64, 3)
    if len(F) != len(me.polygons):
        raise BolusError(f"the stored mesh '{me.name}' is no longer made of triangles: run Make Bolus again")
    return V, F


def remove_mesh(me) -> None:
    """Remove the mesh datablock ``me`` (None, or one already removed: nothing)."""
    if me is not None and me.name in bpy.data.meshes:
        bpy.data.meshes.remove(me)


def stored_meshes(obj) -> list:
    """The skin and plain-solid datablocks a bolus object names (those that still exist)."""
    return [m for m in (bpy.data.meshes.get(obj.get(k, "")) for k in (PROP_SKIN_MESH, PROP_SOLID_MESH))
            if m is not None]


def stored_solid(obj, mm: float):
    """(skin V, skin F, solid V, solid F, solid side) in mm from the datablocks a bolus names."""
    meshes = []
    for key in (PROP_SKIN_MESH, PROP_SOLID_MESH):
        me = bpy.data.meshes.get(obj.get(key, ""))
        if me is None:
            raise BolusError(f"'{obj.name}' has lost its stored {key.removeprefix(PROP_PREFIX).replace('_', ' ')} "
                             f"('{obj.get(key, '')}'): run Make Bolus again on '{obj.get(PROP_SOURCE, 'the skin')}'")
        meshes.append(me)
    skin_V, skin_F = read_tri_mesh(meshes[0], mm)
    V, F = read_tri_mesh(meshes[1], mm)
    side = mesh_io.read_face_labels(meshes[1], ATTR_SHELL_SIDE)
    if side is None:
        raise BolusError(f"the stored solid '{meshes[1].name}' has no '{ATTR_SHELL_SIDE}': run Make Bolus again")
    return skin_V, skin_F, V, F, side
