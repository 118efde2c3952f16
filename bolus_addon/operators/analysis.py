"""Analysis operators: `bolus.saliency_preview` (eqs. 4-1..4-4) and `bolus.segment`
(eqs. 3-3..3-8, 4-5); SPEC, docs/operators.md."""
from __future__ import annotations

import json
from types import SimpleNamespace

import bpy
import numpy as np

from ..blender import mesh_io
from ..blender.guide import poll_for
from ..blender.objects import (
    ATTR_FLATTENABILITY,
    ATTR_PATCH,
    ATTR_PATCH_COLOR,
    ATTR_SALIENCY,
    ATTR_SALIENCY_COLOR,
    PROP_FLV,
    PROP_PATCH_TABLE,
    PROP_SUM_VARPI,
)
from ..blender.operator_base import BolusOperator
from ..blender.properties import (
    color_by_property,
    eta_property,
    method_property,
    patches_property,
    seed_property,
    smoothing_property,
)
from ..core.analysis.saliency import analyse, analysis_key
from ..core.analysis.spectral import segment
from ..core.colormap import categorical_linear_rgba, outside_linear_rgba, scalar_to_linear_rgba


#: The last preview's float64 (varpi, saliency), under `analysis_key` of its region and
#: smoothing: `bolus.segment` on the same region and smoothing reuses them instead of
#: recomputing (at 1.12M triangles 17-20 s of the segment's 69 s).  Kept in memory, not
#: read back from the attributes: those are float32, and on a symmetric mesh the rounding
#: can turn the cut (tests/core/analysis/test_core_spectral.py::test_segment_reuses_the_given_analysis).
#: The key hashes the region's exact coordinates and triangles, so any edit, another
#: selection or another smoothing misses and segment recomputes.
LAST_PREVIEW: dict = {}


def remember_preview(V, F, smoothing_mm: float, res) -> None:
    LAST_PREVIEW.clear()
    LAST_PREVIEW[analysis_key(V, F, smoothing_mm)] = (res.varpi.copy(), res.saliency.copy())


def recall_preview(V, F, smoothing_mm: float):
    """(varpi, saliency) of the last preview when it was taken on exactly (V, F, smoothing), else None."""
    return LAST_PREVIEW.get(analysis_key(V, F, smoothing_mm)) if LAST_PREVIEW else None


def show_attribute_colors(context) -> None:
    """Switch visible 3D views in Solid mode to attribute colours (no-op headless)."""
    screen = getattr(context, "screen", None)
    if screen is None:
        return
    for area in screen.areas:
        if area.type == "VIEW_3D":
            for space in area.spaces:
                if space.type == "VIEW_3D" and space.shading.type == "SOLID":
                    space.shading.color_type = "VERTEX"


class BOLUS_OT_saliency_preview(BolusOperator, bpy.types.Operator):
    """Colour the active skin mesh (its selected faces in Edit Mode, else all of it) by where it cannot lie flat (flattenability and saliency, eqs. 4-1..4-4). Needs a surface mesh at true size; makes the attributes bolus_flattenability and bolus_saliency with a colour, and reports Σϖ and FLV"""

    bl_idname = "bolus.saliency_preview"
    bl_label = "Flattenability Preview"

    smoothing_mm: smoothing_property()
    color_by: color_by_property()

    # long: prepare / compute (modal: a worker thread) / finish, see blender/operator_base.py
    def prepare(self, context):
        region, topo, warnings = self.read_region(context, allow_nonmanifold=True)
        return SimpleNamespace(region=region, topo=topo, warnings=warnings, smoothing_mm=float(self.smoothing_mm))

    @staticmethod
    def compute(job, progress):
        progress(0.2, "angle sums and saliency")
        return analyse(job.region.V, job.region.F, job.smoothing_mm, topo=job.topo)

    def finish(self, context, job, res):
        region, warnings = job.region, job.warnings
        self.progress(0.8, "writing attributes")
        obj, me = region.obj, region.mesh
        varpi = region.on_vertices(res.varpi, 0.0)
        sal = region.on_vertices(res.saliency, 0.0)
        shown = res.saliency if self.color_by == "SALIENCY" else res.varpi
        colors = region.on_vertices(scalar_to_linear_rgba(shown), outside_linear_rgba())
        with mesh_io.object_mode(obj):
            mesh_io.write_attribute(me, ATTR_FLATTENABILITY, "FLOAT", "POINT", varpi)
            mesh_io.write_attribute(me, ATTR_SALIENCY, "FLOAT", "POINT", sal)
            mesh_io.write_point_colors(me, ATTR_SALIENCY_COLOR, colors)
            me.update()
        obj[PROP_SUM_VARPI] = res.sum_varpi
        obj[PROP_FLV] = res.flv
        remember_preview(region.V, region.F, job.smoothing_mm, res)
        show_attribute_colors(context)
        self.warn_all(warnings)
        where = "selected faces" if region.selection_only else "whole mesh"
        self.report(
            {"INFO"},
            f"Flattenability of the {where} ({len(region.V)} vertices, smoothing {self.smoothing_mm:g} mm): "
            f"sum varpi = {res.sum_varpi:.4f} rad, FLV = {res.flv:.4g}",
        )
        return {"FINISHED"}


def format_patch_row(row: dict) -> str:
    return (
        f"Patch {row['patch']}: {row['vertices']} vertices, {row['edges']} edges, {row['faces']} triangles, "
        f"{row['area_mm2'] / 100.0:.1f} cm², sum varpi {row['sum_varpi']:.4f}, FLV {row['flv']:.4g}"
    )


class BOLUS_OT_segment(BolusOperator, bpy.types.Operator):
    """Split the active skin (its selected faces in Edit Mode, else all of it) into patches that flatten well (saliency-aware spectral clustering, eqs. 3-3..3-8, 4-5). Needs a manifold surface in one piece; makes the face attribute bolus_patch, seams on the borders and the patch table"""

    bl_idname = "bolus.segment"
    bl_label = "Segment into Patches"

    @classmethod
    def poll(cls, context):
        return poll_for(cls, context)

    patches: patches_property()
    eta: eta_property()
    seed: seed_property()
    smoothing_mm: smoothing_property()
    method: method_property()

    # long: prepare / compute (modal: a worker thread) / finish, see blender/operator_base.py
    def prepare(self, context):
        region, topo, warnings = self.read_region(context, allow_nonmanifold=False)
        return SimpleNamespace(region=region, topo=topo, warnings=warnings, patches=int(self.patches),
                               eta=float(self.eta), smoothing_mm=float(self.smoothing_mm), seed=int(self.seed),
                               method=self.method.lower(),
                               analysis=recall_preview(region.V, region.F, float(self.smoothing_mm)))

    @staticmethod
    def compute(job, progress):
        region = job.region
        return segment(
            region.V,
            region.F,
            patches=job.patches,
            eta=job.eta,
            smoothing_mm=job.smoothing_mm,
            rng=job.seed,
            method=job.method,
            face_groups=region.tri_poly,
            progress=lambda f, t: progress(0.9 * f, t),
            topo=job.topo,
            analysis=job.analysis,
        )

    def finish(self, context, job, seg):
        region, warnings = job.region, job.warnings
        obj, me = region.obj, region.mesh
        poly_labels = region.on_polygons(seg.face_labels.astype(np.int64), -1)
        seams = mesh_io.polygon_edge_labels(me, poly_labels)
        touched = mesh_io.edges_of_polygons(me, region.poly_ids)
        table = [p.as_dict() for p in seg.patches]
        with mesh_io.object_mode(obj):
            mesh_io.write_attribute(me, ATTR_PATCH, "INT", "FACE", poly_labels)
            mesh_io.set_seams(me, seams, touched)
            mesh_io.write_face_colors(me, ATTR_PATCH_COLOR, categorical_linear_rgba(poly_labels))
            me.update()
        obj[PROP_PATCH_TABLE] = json.dumps({"requested": self.patches, "eta": self.eta, "seed": self.seed, "smoothing_mm": self.smoothing_mm, "patches": table})
        if seg.patch_count != self.patches:
            warnings.append(
                f"{seg.patch_count} patches instead of the {self.patches} asked: clusters that fell apart "
                "became separate patches, crumbs were merged into a neighbour"
            )
        self.warn_all(warnings)
        self.report({"INFO"}, f"Segmented '{obj.name}' into {seg.patch_count} patches (attribute '{ATTR_PATCH}', seams on the borders)")
        for row in table:
            self.report({"INFO"}, format_patch_row(row))
        return {"FINISHED"}


classes = (BOLUS_OT_saliency_preview, BOLUS_OT_segment)
