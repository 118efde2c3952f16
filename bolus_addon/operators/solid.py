"""Operator `bolus.make_shell` (SPEC; seed 1.1): the printable bolus solid.

From the region (Edit Mode selection, else the whole mesh) `core.solid.shell.make_shell` builds
one closed, manifold, outward-wound solid whose inner face lies on the skin (moved out by the
clearance) and whose outer face lies at the true distance ``thickness_mm`` from it; the rest
of the skin is passed along so a bolus that would run into the face elsewhere is refused.
With a label, `core.solid.engrave.engrave_labels` engraves it and the L / R markers on the
outer face (outlines from Blender's built-in font, `blender.labels`).

The result is a new object ``<name>_bolus`` (world units, identity transform, beside the
source; an existing one is replaced, so the user can re-run with another thickness): face
attribute ``bolus_shell_side`` (SIDE_* of core.solid), the figures as custom properties, and
two mesh datablocks kept with a fake user for `print_segment` (`blender.solid_io`): the skin
region and the plain (un-engraved) solid.  The source is never changed; Blender data is
created only after every computation succeeded, and removed again if writing it fails.
"""
from __future__ import annotations

import time
from types import SimpleNamespace

import bpy
import numpy as np
from mathutils import Matrix

from ..blender import mesh_io, mesh_region
from ..blender.guide import poll_for
from ..blender.labels import engrave_with, label_outlines, left_vector
from ..blender.objects import (
    ATTR_SHELL_SIDE,
    BOLUS_SUFFIX,
    DICOM_PROPS,
    PROP_CLEARANCE,
    PROP_DENSITY,
    PROP_HOLES,
    PROP_LABEL,
    PROP_MASS,
    PROP_PREFIX,
    PROP_RESOLUTION,
    PROP_SKIN_MESH,
    PROP_SOLID_MESH,
    PROP_SOURCE,
    PROP_THICKNESS,
    PROP_THICKNESS_MAX,
    PROP_THICKNESS_MEAN,
    PROP_THICKNESS_MIN,
    PROP_VOLUME,
    SKIN_SUFFIX,
    SOLID_SUFFIX,
    is_bolus_object,
    part_objects,
)
from ..blender.operator_base import BolusOperator, time_limit
from ..blender.properties import clearance_property, label_property, resolution_property, thickness_property
from ..blender.solid_io import remove_mesh, stored_meshes, tri_mesh
from ..core.errors import BolusError
from ..core.solid.manifold import closed_report
from ..core.solid.shell import check_shell_request, make_shell

#: a wall thinner than this fraction of the one asked is reported (the minimum thickness must be >= 0.95 t)
THIN_FRACTION = 0.95
DEFAULT_DENSITY = 1.04


def clear_bolus_props(obj) -> None:
    """Remove every custom property of ours from obj (a re-run writes them anew)."""
    for k in [k for k in obj.keys() if k.startswith(PROP_PREFIX)]:
        del obj[k]


class BOLUS_OT_make_shell(BolusOperator, bpy.types.Operator):
    """Make a printable bolus: a closed solid of the given thickness on the selected skin region (seed 1.1). Needs a skin region at true size, not closed; makes a new object '<name>_bolus' with its volume, mass and wall figures, the skin unchanged"""

    bl_idname = "bolus.make_shell"
    bl_label = "Make Bolus"

    thickness_mm: thickness_property()
    clearance_mm: clearance_property()
    resolution_mm: resolution_property()
    label: label_property()

    @classmethod
    def poll(cls, context):  # not on a bolus (would make '<name>_bolus_bolus')
        return poll_for(cls, context)

    # long: prepare / compute (modal: a worker thread) / finish, see blender/operator_base.py
    def prepare(self, context):
        t0 = time.perf_counter()
        t, c, res = float(self.thickness_mm), float(self.clearance_mm), float(self.resolution_mm)
        check_shell_request(t, c, res)  # bad settings are refused before any work
        src = mesh_io.active_mesh_object(context)
        name = src.name + BOLUS_SUFFIX
        old = bpy.data.objects.get(name)
        if old is not None and not is_bolus_object(old):
            raise BolusError(f"an object named '{name}' exists and is not a bolus made by Make Bolus: "
                             "rename or delete it first")
        self.progress(0.0, "reading the region")
        region, topo, warnings = self.read_region(context, allow_nonmanifold=False)
        check_shell_request(t, c, res, area_mm2=float(topo.areas.sum()))
        others = self._rest_of_skin(context, region)
        skin_F = _world_winding(region.obj, region.F)
        label = self.label.strip()
        return SimpleNamespace(t0=t0, t=t, c=c, res=res, time_limit=time_limit(context), region=region,
                               warnings=warnings, others=others,
                               skin_F=skin_F, label=label, outlines=label_outlines(label) if label else None,
                               left=left_vector(context))

    @staticmethod
    def compute(job, progress):
        """(shell, V, F, side after engraving, the engraving's notes, closed_report of the result)."""
        shell = make_shell(job.region.V, job.skin_F, job.t, job.c, job.res, others=job.others,
                           time_limit_s=job.time_limit,
                           progress=lambda f, text: progress(0.85 * f, text))
        V, F, side, notes = shell.V, shell.F, np.asarray(shell.side), []
        if job.label:
            progress(0.87, "engraving the label")
            V, F, side, _, notes = engrave_with(V, F, side, job.outlines, job.label, job.left)
        progress(0.95, "checking the bolus")
        return shell, V, F, side, list(notes), closed_report(V, F)

    def finish(self, context, job, result):
        shell, V, F, side, notes, final = result
        t, c, t0, region, skin_F, label = job.t, job.c, job.t0, job.region, job.skin_F, job.label
        warnings = job.warnings + notes
        self.progress(0.95, "writing the bolus")
        density = float(getattr(getattr(context.scene, "bolus", None), "density_g_cm3", DEFAULT_DENSITY))
        if not final["closed"]:  # the core's solids are closed by construction: never write an open one
            raise BolusError(f"internal error: the bolus came out open ({final['boundary_edges']} open edges, "
                             f"{final['nonmanifold_edges']} non-manifold): nothing was made")
        volume_cm3 = final["volume_mm3"] / 1000.0
        obj = self._write(context, region, skin_F, shell, V, F, side, label, density, volume_cm3)
        warnings += list(shell.warnings)
        warnings += thin_warnings(shell, t - c)
        self.warn_all(warnings)
        self.report({"INFO"}, shell_summary(obj.name, shell, t, c, volume_cm3, density, time.perf_counter() - t0))
        return {"FINISHED"}

    def _rest_of_skin(self, context, region):
        """(V, F) in mm of the source's faces outside the region, or None when the region is the whole mesh."""
        if not region.selection_only:
            return None
        rest = np.ones(len(region.mesh.polygons), dtype=bool)
        rest[region.poly_ids] = False
        if not rest.any():
            return None
        other = mesh_region.read_region(context, region.obj, polys=rest)
        return other.V, _world_winding(other.obj, other.F)

    def _write(self, context, region, skin_F, shell, V, F, side, label, density, volume_cm3):
        """Create the meshes and the object (or refill ``<name>_bolus``); nothing is left if this fails."""
        src, scale = region.obj, region.mm_per_unit
        name = src.name + BOLUS_SUFFIX
        created = []
        try:
            skin_me = tri_mesh(name + SKIN_SUFFIX, region.V / scale, skin_F)
            created.append(skin_me)
            solid_me = tri_mesh(name + SOLID_SUFFIX, shell.V / scale, shell.F)
            created.append(solid_me)
            mesh_io.write_attribute(solid_me, ATTR_SHELL_SIDE, "INT", "FACE", np.asarray(shell.side))
            me = tri_mesh(name, V / scale, F)
            created.append(me)
            mesh_io.write_attribute(me, ATTR_SHELL_SIDE, "INT", "FACE", side)
            obj = _link_bolus(context, src, name, me)
        except Exception:
            for m in created:
                remove_mesh(m)
            raise
        for m, suffix in ((skin_me, SKIN_SUFFIX), (solid_me, SOLID_SUFFIX)):
            m.name = name + suffix  # free now that the old ones are gone (else Blender adds .001)
            m.use_fake_user = True
        me.name = name
        clear_bolus_props(obj)
        obj[PROP_THICKNESS] = float(self.thickness_mm)
        obj[PROP_VOLUME] = volume_cm3
        obj[PROP_THICKNESS_MIN] = float(shell.thickness_min)
        obj[PROP_THICKNESS_MAX] = float(shell.thickness_max)
        obj[PROP_THICKNESS_MEAN] = float(shell.thickness_mean)
        obj[PROP_MASS] = volume_cm3 * density
        obj[PROP_DENSITY] = density
        obj[PROP_CLEARANCE] = float(self.clearance_mm)
        obj[PROP_RESOLUTION] = float(self.resolution_mm)
        obj[PROP_LABEL] = label
        obj[PROP_SOURCE] = src.name
        obj[PROP_SKIN_MESH] = skin_me.name
        obj[PROP_SOLID_MESH] = solid_me.name
        obj[PROP_HOLES] = int(shell.holes)
        for key in DICOM_PROPS:  # a bolus on a DICOM skin goes back onto that CT
            if key in src:
                obj[key] = src[key]
        return obj


def _world_winding(obj, F: np.ndarray) -> np.ndarray:
    """Triangles F (m,3) wound so their normals point where Blender shows them in world space: a
    mirroring transform (negative determinant) reverses the winding, and Blender flips the normals."""
    M = np.array(obj.matrix_world, dtype=np.float64)[:3, :3]
    return F[:, ::-1].copy() if np.linalg.det(M) < 0 else F


def _link_bolus(context, src, name: str, me) -> bpy.types.Object:
    """``name`` showing ``me``: the existing bolus object refilled (its old meshes and part objects
    removed), or a new object in the source's collection; identity transform."""
    obj = bpy.data.objects.get(name)
    if obj is None:
        obj = bpy.data.objects.new(name, me)
        coll = src.users_collection[0] if src.users_collection else context.scene.collection
        coll.objects.link(obj)
    else:
        old, stored = obj.data, stored_meshes(obj)
        obj.data = me
        for m in stored:
            remove_mesh(m)
        if old is not None and old.users == 0:
            remove_mesh(old)
        for part in part_objects(name):  # print parts of the old bolus: out of date
            pme = part.data
            bpy.data.objects.remove(part, do_unlink=True)
            if pme is not None and pme.users == 0:
                remove_mesh(pme)
    obj.matrix_world = Matrix.Identity(4)
    return obj


def thin_warnings(shell, wall: float) -> list[str]:
    """A warning when the measured wall is thinner than THIN_FRACTION of the one asked (``wall`` mm)."""
    if not np.isfinite(shell.thickness_min) or shell.thickness_min >= THIN_FRACTION * wall:
        return []
    if any(f"{shell.thickness_min:.2f} mm" in w for w in shell.warnings):  # the core already named the spot
        return []
    return [f"thin spot: the wall measures {shell.thickness_min:.2f} mm at its thinnest, under "
            f"{THIN_FRACTION * 100:.0f} % of the {wall:g} mm asked (mean {shell.thickness_mean:.2f} mm); "
            "try a finer resolution or check the skin there"]


def shell_summary(name, shell, t, c, volume_cm3, density, seconds) -> str:
    holes = int(shell.holes)
    return (f"Made '{name}': {volume_cm3:.1f} cm³, {volume_cm3 * density:.1f} g at {density:g} g/cm³; wall "
            f"{shell.thickness_min:.2f} / {shell.thickness_mean:.2f} / {shell.thickness_max:.2f} mm "
            f"(min / mean / max; {t - c:g} mm asked{f', clearance {c:g} mm' if c else ''}); "
            f"{holes} hole{'s' if holes != 1 else ''} kept open; {seconds:.1f} s")


classes = (BOLUS_OT_make_shell,)
