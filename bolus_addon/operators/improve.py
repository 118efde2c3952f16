"""Operator `bolus.improve_flattenability` (SPEC; seed 4.3-4.4, eq. 4-21, Algorithms 4-1, 4-2).

The source is never touched: the region (Edit Mode selection or the whole mesh) and its
`bolus_patch` labels are read, the core's `ImproveJob` moves the region's interior vertices
outward along their normals by 0..max gap (border and patch borders fixed), and the result
is a COPY of the source mesh, ``<name>_improved`` (polygons, UVs, seams, `bolus_patch` and
every attribute kept; same transform as the source), with the moved vertices, the point
attribute `bolus_air_gap` (mm, the distance moved, 0 outside the region), its colour map
`bolus_air_gap_color` and the Table 4-4 figures before / after.  From the sidebar it runs
modally, one job step per timer tick with a progress bar; Esc keeps the best surface so far.
"""
from __future__ import annotations

import json
import time

import bpy
import numpy as np

from ..blender import mesh_io
from ..blender.guide import poll_for
from ..blender.objects import (
    ATTR_AIR_GAP,
    ATTR_AIR_GAP_COLOR,
    ATTR_PATCH,
    IMPROVED_SUFFIX,
    PROP_FLV_AFTER,
    PROP_FLV_BEFORE,
    PROP_IMPROVE_TABLE,
    PROP_MAX_AIR_GAP,
    PROP_MAX_GAP,
    PROP_PREFIX,
    PROP_SOURCE,
    PROP_SUM_VARPI_AFTER,
    PROP_SUM_VARPI_BEFORE,
    is_improved_object,
)
from ..blender.operator_base import BolusOperator, time_limit
from ..blender.properties import improve_method_property, max_gap_property, seed_property
from ..core.analysis.saliency import DEFAULT_SMOOTHING_MM
from ..core.budget import check_budget
from ..core.colormap import outside_linear_rgba, srgb_to_linear
from ..core.errors import BolusError
from ..core.improve.improve import ImproveJob, improve_messages

#: the air-gap colour scale (gap in mm, sRGB): 0 cool blue, 0.5 pale, 1 mm (the clinic's usual
#: limit) warm orange, 2 mm and more red; linear in between
AIR_GAP_STOPS_MM = (0.0, 0.5, 1.0, 2.0)
AIR_GAP_STOPS_SRGB = ((0.23, 0.30, 0.75), (0.87, 0.87, 0.80), (0.96, 0.60, 0.15), (0.78, 0.05, 0.10))


def air_gap_linear_rgba(gap_mm) -> np.ndarray:
    """Gaps (k,) in mm -> linear RGBA (k,4) float32 on the clinical scale of `AIR_GAP_STOPS_MM`."""
    g = np.asarray(gap_mm, dtype=np.float64)
    stops = np.asarray(AIR_GAP_STOPS_SRGB)
    srgb = np.stack([np.interp(g, AIR_GAP_STOPS_MM, stops[:, c]) for c in range(3)], axis=1)
    out = np.ones((len(g), 4), dtype=np.float32)
    out[:, :3] = srgb_to_linear(srgb)
    return out


def _world_winding(obj, F: np.ndarray) -> np.ndarray:
    """Triangles wound so that their normals point where Blender shows them in world space (a
    mirroring transform reverses the winding of the world-space triangles): 'outward' is the
    side the user sees the face normals point to."""
    M = np.array(obj.matrix_world, dtype=np.float64)[:3, :3]
    return F[:, ::-1].copy() if np.linalg.det(M) < 0 else F


class _ImproveRun:
    """One run: the region read from Blender and the core job (nothing written yet)."""

    def __init__(self, op: BolusOperator, context, max_gap_mm: float, method: str, seed: int):
        self.t0 = time.perf_counter()
        self.max_gap_mm, self.method, self.seed = float(max_gap_mm), method, int(seed)
        settings = getattr(context.scene, "bolus", None)
        self.smoothing_mm = float(getattr(settings, "smoothing_mm", DEFAULT_SMOOTHING_MM))
        self.region, _, self.warnings = op.read_region(context, allow_nonmanifold=False)
        src = self.region.obj
        name = src.name + IMPROVED_SUFFIX
        old = bpy.data.objects.get(name)
        if old is not None and not is_improved_object(old):
            raise BolusError(f"an object named '{name}' exists and was not made by Improve Flattenability: "
                             "rename or delete it first")
        poly_labels = mesh_io.read_face_labels(src, ATTR_PATCH)  # safe in Edit Mode
        labels = None if poly_labels is None else poly_labels[self.region.tri_poly]
        self.infos: list[str] = []
        if labels is not None and not (labels >= 0).any():
            labels = None
            self.infos.append(f"no face of the region is in a segmented patch ({ATTR_PATCH} = -1): "
                              "improved as one patch")
        elif labels is not None and (labels < 0).any():
            out = len(np.unique(self.region.tri_poly[labels < 0]))
            self.infos.append(f"{out} faces outside the segmented patches ({ATTR_PATCH} = -1) were left as they are")
        self.patched = labels is not None
        sizes = np.bincount(np.zeros(len(self.region.F), np.int64) if labels is None else labels[labels >= 0])
        check_budget("improve_flattenability", sizes[sizes > 0], f"the region has {len(self.region.F):,} triangles",
                     "select the treatment area first (Select Treatment Area)",
                     limit=time_limit(context))
        self.job = ImproveJob(self.region.V, _world_winding(src, self.region.F), self.max_gap_mm, method=method,
                              rng=self.seed, smoothing_mm=self.smoothing_mm, patch_labels=labels,
                              progress=op.progress, vert_ids=self.region.vert_ids)

    def seconds(self) -> float:
        return time.perf_counter() - self.t0


def _link_improved(context, src, name: str, me) -> bpy.types.Object:
    """``name`` showing ``me`` (an existing improved object refilled, its old mesh freed), else a new
    object in the source's collection; the source's transform either way."""
    obj = bpy.data.objects.get(name)
    if obj is not None:
        old = obj.data
        obj.data = me
        if old is not None and old.users == 0:
            bpy.data.meshes.remove(old)
        for key in list(obj.keys()):  # the last run's figures
            if key.startswith(PROP_PREFIX):
                del obj[key]
    else:
        obj = bpy.data.objects.new(name, me)
        coll = src.users_collection[0] if src.users_collection else context.scene.collection
        coll.objects.link(obj)
    me.name = name  # free now that the old mesh is gone (else Blender adds .001)
    _copy_transform(src, obj)
    context.view_layer.update()  # matrix_world from the channels, for whoever reads it next
    return obj


_TRANSFORM = ("location", "rotation_mode", "rotation_euler", "rotation_quaternion", "rotation_axis_angle", "scale",
              "delta_location", "delta_rotation_euler", "delta_rotation_quaternion", "delta_scale")


def _copy_transform(src, obj) -> None:
    """obj gets src's parent and transform channels, so its world matrix is src's bit for bit
    (assigning matrix_world would decompose and recompose it, off in the last bits)."""
    obj.parent = src.parent
    obj.parent_type = src.parent_type
    obj.matrix_parent_inverse = src.matrix_parent_inverse.copy()
    for key in _TRANSFORM:
        value = getattr(src, key)
        setattr(obj, key, value if isinstance(value, str) else tuple(value))


def improve_table(run: _ImproveRun, res) -> dict:
    """The JSON table of the improved object (`Improvement.table`: the whole region and every patch
    before / after) with the run's status, seed, iterations and whether it was per patch."""
    statuses = [p.status for p in res.patches]
    if res.cancelled:
        status = "cancelled"
    elif "improved" in statuses:
        status = "improved"
    elif all(s in ("flat", "no interior") for s in statuses):
        status = "flat"
    else:
        status = "no gain"
    table = res.table()
    table.update(status=status, seed=run.seed, iterations=int(sum(p.iterations for p in res.patches)),
                 seconds=run.seconds(), per_patch=run.patched, source=run.region.obj.name)
    return table


def build_improved_object(context, run: _ImproveRun, res) -> bpy.types.Object:
    """Create (or refill) ``<name>_improved`` from the core's `Improvement`: a copy of the source mesh
    with the region's vertices moved (world mm -> local units), the air gap and its colours."""
    region = run.region
    src, scale = region.obj, region.mm_per_unit
    name = src.name + IMPROVED_SUFFIX
    delta = np.asarray(res.V, dtype=np.float64) - region.V  # world mm
    moved = np.any(delta != 0.0, axis=1)
    M = np.array(src.matrix_world, dtype=np.float64)[:3, :3]
    with mesh_io.object_mode(src):  # the copy must see the edit-mesh's latest state
        me = src.data.copy()
    try:
        co = mesh_io.get_array(me.vertices, "co", len(me.vertices), np.float64, 3)
        if moved.any():
            # a world displacement d (mm) is M @ l * scale for a local displacement l
            local = np.linalg.solve(M, (delta[moved] / scale).T).T
            co[region.vert_ids[moved]] += local
            me.vertices.foreach_set("co", co.ravel())
        gap = region.on_vertices(np.asarray(res.gap, dtype=np.float64), 0.0)
        mesh_io.write_attribute(me, ATTR_AIR_GAP, "FLOAT", "POINT", gap)
        colors = region.on_vertices(air_gap_linear_rgba(res.gap), outside_linear_rgba())
        mesh_io.write_point_colors(me, ATTR_AIR_GAP_COLOR, colors)
        me.update()
        obj = _link_improved(context, src, name, me)
    except Exception:
        if me.users == 0:
            bpy.data.meshes.remove(me)
        raise
    table = improve_table(run, res)
    wb, wa = res.whole_before, res.whole_after
    obj[PROP_SOURCE] = src.name
    obj[PROP_MAX_GAP] = run.max_gap_mm
    obj[PROP_FLV_BEFORE] = float(wb.flv)
    obj[PROP_FLV_AFTER] = float(wa.flv)
    obj[PROP_SUM_VARPI_BEFORE] = float(wb.sum_varpi)
    obj[PROP_SUM_VARPI_AFTER] = float(wa.sum_varpi)
    obj[PROP_MAX_AIR_GAP] = float(np.max(res.gap, initial=0.0))
    obj[PROP_IMPROVE_TABLE] = json.dumps(table)
    return obj


def improve_reports(run: _ImproveRun, res, obj_name: str) -> list[tuple[str, str]]:
    """(level, text) of every report after a run: the core's (warnings, infos, every patch and the
    whole region before -> after like Table 4-4, "nothing to do", a cancel) and what was made."""
    src = run.region.obj.name
    where = f"the selected faces of '{src}'" if run.region.selection_only else f"'{src}'"
    out = improve_messages(res, where)
    out.append(("INFO", f"made '{obj_name}': the air gap (mm) in the point attribute '{ATTR_AIR_GAP}', shown by "
                        f"'{ATTR_AIR_GAP_COLOR}' (blue 0, orange 1 mm, red 2 mm and more)"))
    return out


class BOLUS_OT_improve_flattenability(BolusOperator, bpy.types.Operator):
    """Move the surface outward along its normals, by at most the max air gap, until it flattens better (eq. 4-21, L-PSO of Algorithms 4-1, 4-2, or a gradient method). Needs a skin region with a border (patches optional); makes a new object '<name>_improved' with the air-gap map, the skin unchanged"""

    bl_idname = "bolus.improve_flattenability"
    bl_label = "Improve Flattenability"

    max_gap_mm: max_gap_property()
    method: improve_method_property()
    seed: seed_property()

    _run = None

    @classmethod
    def poll(cls, context):  # not on a pattern, nor on '<name>_improved' (would make '<name>_improved_improved')
        return poll_for(cls, context)

    def _start(self, context) -> _ImproveRun:
        return _ImproveRun(self, context, self.max_gap_mm, self.method, self.seed)

    def run(self, context):
        run = self._start(context)
        deadline = self.deadline(context, self.progress)  # past the time limit: an ERROR, nothing written
        while run.job.step():
            deadline(run.job.fraction, run.job.text)
        return self.finish(context, run, run.job.result())

    def finish(self, context, run: _ImproveRun, res):
        obj = build_improved_object(context, run, res)
        self.warn_all(run.warnings)
        for msg in run.infos:
            self.report({"INFO"}, msg)
        for level, msg in improve_reports(run, res, obj.name):
            self.report({level}, msg)
        return {"FINISHED"}

    # interactive: one job step per timer tick, Esc keeps the best so far.  BolusOperator guards
    # both: errors become reports (abort() first for modal), no window falls back to execute.
    def invoke(self, context, event):
        self._run = self._start(context)
        self._deadline = self.deadline(context)
        self.start_modal(context)
        self.report({"INFO"}, f"Improving flattenability ({self.method}, max gap {self.max_gap_mm:g} mm; "
                              "Esc keeps the best so far)")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._run.job
        if event.type == "ESC":  # result() before the end: the best so far, cancelled=True
            self.abort(context)
            return self.finish(context, self._run, job.result())
        if event.type != "TIMER":
            return {"RUNNING_MODAL"}
        more = job.step()
        self.progress(job.fraction, job.text)
        deadline = getattr(self, "_deadline", None)  # set by invoke
        if deadline is not None:
            deadline(job.fraction, job.text)  # past the time limit: an ERROR (abort first), nothing written
        if more:
            return {"RUNNING_MODAL"}
        self.abort(context)
        return self.finish(context, self._run, job.result())


classes = (BOLUS_OT_improve_flattenability,)
