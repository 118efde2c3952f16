"""Operator `bolus.unfold` (SPEC; seed 3.5, 4.5); the export is in operators/pattern.py.

`unfold` never touches the source: it reads the region and its `bolus_patch` labels
and builds a new object ``<name>_pattern`` in z = 0 at true size (1 mm of pattern =
1 mm on the patient, in scene units), whose polygons are the source's polygons with
their corner order, one island per patch.  From the sidebar it runs modally, the
unfolding in a worker thread (blender/modal_run.py), with a progress bar; Esc cancels and
leaves nothing behind.  The numbers (islands, polygon corners, float32 positions, errors,
the pattern table and the messages) come from `core.pattern.pattern_mesh`; this module
converts, calls, writes, reports.
"""
from __future__ import annotations

import json

import bpy
import numpy as np
from mathutils import Matrix

from ..blender import mesh_io, mesh_region
from ..blender.guide import poll_for
from ..blender.objects import (
    ATTR_AREA_COLOR,
    ATTR_AREA_ERROR,
    ATTR_PATCH,
    ATTR_PIECE,
    ATTR_SOURCE_FACE,
    ATTR_SOURCE_VERTEX,
    PATTERN_SUFFIX,
    PROP_EA,
    PROP_EL,
    PROP_MAX_EL,
    PROP_PATTERN_TABLE,
    PROP_SHEET_THICKNESS,
    PROP_SOURCE,
)
from ..blender.operator_base import BolusOperator, time_limit
from ..blender.properties import (
    gap_property,
    max_el_property,
    refine_property,
    sheet_thickness_property,
    unfold_method_property,
)
from ..core.analysis.saliency import DEFAULT_SMOOTHING_MM
from ..core.budget import check_budget
from ..core.colormap import diverging_linear_rgba
from ..core.errors import BolusError
from ..core.pattern.pattern_mesh import (
    add_sheet_figures,
    build_pattern,
    collect_pieces,
    diagnose_pieces,
    patch_islands,
    pattern_messages,
    sheet_messages,
)
from ..core.unfold.mid_surface import (
    check_sheet_thickness,
    check_thickness,
    mid_surface,
    piece_bending,
    principal_curvatures,
)
from ..core.unfold.piece_advice import DEFAULT_WARN_FRACTION
from ..core.unfold.sheet_pieces import iter_sheet_pieces

#: |A / A0 - 1| shown at full colour strength in the pattern's area-distortion colours
AREA_COLOR_RANGE = 0.1


def check_max_el(max_el_pct: float) -> float:
    """The EL target as a fraction; BolusError for a value the refinement cannot work to."""
    if not np.isfinite(max_el_pct) or max_el_pct < 0 or 0 < max_el_pct < 0.1:
        raise BolusError(f"Max EL must be 0 (no darts or splits) or at least 0.1 %, got {max_el_pct:g} %")
    return float(max_el_pct) / 100.0


def check_unfold_budget(triangles: int, islands, limit: float | None = None) -> None:
    """BolusError (figures and what to do) when unfolding islands (m,) (-1: left out) would take
    longer than the time budget (core.budget; limit: the user's time limit)."""
    sizes = np.bincount(islands[islands >= 0])
    check_budget("unfold", sizes, f"the region has {triangles:,} triangles in {len(sizes)} islands (the "
                 "connected pieces of its patches)", "select the treatment area first (Select Treatment Area) and "
                 "segment it into smaller patches", limit=limit)


class _UnfoldJob:
    """The state of one unfolding: inputs, the island iterator and the finished islands."""

    def __init__(self, context, method: str, refine: bool, gap_mm: float, max_el_pct: float = 0.0,
                 thickness_mm: float = 0.0, progress=None):
        """Read the region, its labels and the settings (main thread); `start` (bpy-free) does the rest.

        progress(fraction, text): the core's progress (overall fraction, "patch k/n: step"); the
        attribute ``progress`` may be replaced before `start` (a worker thread's)."""
        self.progress = progress
        self.max_el = check_max_el(max_el_pct)
        self.thickness = check_thickness(thickness_mm)
        self.region = region = mesh_region.read_region(context)
        self.warnings = list(region.warnings)
        self.infos: list[str] = []
        poly_labels = mesh_io.read_face_labels(region.obj, ATTR_PATCH)  # safe in Edit Mode
        if poly_labels is None:
            poly_labels = np.zeros(len(region.mesh.polygons), dtype=np.int64)
            self.warnings.append(f"no '{ATTR_PATCH}' attribute (run Segment first): unfolded as a single patch")
        settings = getattr(context.scene, "bolus", None)
        self.warn_pct = float(getattr(settings, "warn_distortion_pct", DEFAULT_WARN_FRACTION * 100.0))
        self.sigma_mm = float(getattr(settings, "smoothing_mm", DEFAULT_SMOOTHING_MM))
        self.curvatures = None
        self.poly_labels = poly_labels
        self.gap_mm = gap_mm
        self.time_limit = time_limit(context)
        self.method, self.refine = method.lower(), bool(refine)
        self.corners = mesh_io.polygon_corners(region.mesh)  # for build_pattern
        self.done: list = []

    def start(self) -> None:
        """bpy-free: the islands, the reference surface and the island iterator."""
        region = self.region
        # a patch cut in two by the region (or edited) becomes one island per connected piece
        self.islands = patch_islands(region.V, region.F, self.poly_labels[region.tri_poly],
                                     face_groups=region.tri_poly, vert_ids=region.vert_ids)
        if self.islands.left_out:  # expected when a region was segmented: said once, as INFO
            self.infos.append(f"{self.islands.left_out} faces outside the segmented patches (bolus_patch = -1) "
                              "were left out of the pattern")
        check_unfold_budget(len(region.F), self.islands.islands, self.time_limit)  # refuse now, not after minutes
        self.V_ref = self._reference(region)
        progress = None if self.progress is None else (lambda f, t="": self.progress(f, t))
        self.iter = iter_sheet_pieces(self.V_ref, region.F, self.islands.islands, max_el=self.max_el,
                                      face_groups=region.tri_poly, sigma_mm=self.sigma_mm, method=self.method,
                                      refine_rounds=3 if self.refine else 0, progress=progress)
        self.count = self.islands.count

    def _reference(self, region) -> np.ndarray:
        """The surface the pattern is unfolded from and measured against: the skin, or with a
        sheet thickness its mid-surface (SPEC), with a warning where the offset was clamped."""
        if self.thickness <= 0:
            return region.V
        check_sheet_thickness(region.V, region.F, self.thickness)
        # the skin's principal curvatures, once for the offset's clamp and the bending advice
        self.curvatures = principal_curvatures(region.V, region.F, self.sigma_mm)
        mid = mid_surface(region.V, region.F, self.thickness, sigma_mm=self.sigma_mm, curvatures=self.curvatures)
        n = int(np.count_nonzero(mid.clamped))
        if n:
            worst = int(np.argmin(np.where(mid.clamped, mid.offset, np.inf)))
            self.warnings.append(
                f"sheet thickness {self.thickness:g} mm: the mid-surface could not be moved out by "
                f"{self.thickness / 2:g} mm at {n} vertices, where the skin curves inwards more tightly than that "
                f"(least {mid.offset[worst]:.2f} mm at vertex {int(region.vert_ids[worst])}): a sheet will not "
                "follow the skin there")
        self.infos.append(f"pattern unfolded from the mid-surface of a {self.thickness:g} mm sheet (the skin moved "
                          f"out by {self.thickness / 2:g} mm)")
        return mid.V

    def step(self) -> bool:
        """Unfold (and refine) the next island; False when all are done."""
        try:
            _, _, res = next(self.iter)
        except StopIteration:
            return False
        self.done.append(res)
        return True


def _link_object(context, src: bpy.types.Object, name: str, me: bpy.types.Mesh) -> bpy.types.Object:
    """The object ``name`` given the mesh ``me`` (its old mesh freed), or a new one beside ``src``."""
    obj = bpy.data.objects.get(name)
    if obj is not None and obj.type == "MESH":
        old = obj.data
        obj.data = me
        if old.users == 0:
            bpy.data.meshes.remove(old)
    else:
        obj = bpy.data.objects.new(name, me)
        coll = src.users_collection[0] if src.users_collection else context.scene.collection
        coll.objects.link(obj)
    obj.matrix_world = Matrix.Identity(4)
    return obj


def compute_pattern(job: _UnfoldJob) -> None:
    """bpy-free, after the last island: job.layout (the pieces, darts and splits) and job.build
    (the pattern's vertices, polygons and figures)."""
    region = job.region
    job.layout = lay = collect_pieces(job.islands, job.done)
    b = build_pattern(job.V_ref, region.F, region.tri_poly, region.vert_ids, lay.islands, lay.unfoldings,
                      job.poly_labels, *job.corners, mm_per_unit=region.mm_per_unit, gap_mm=job.gap_mm)
    diagnose_pieces(job.V_ref, region.F, lay.islands, lay.unfoldings, b.rows, job.warn_pct / 100.0, job.sigma_mm)
    # the EL limit of the advice: the target, or with refinement off the user's warning threshold
    bending = piece_bending(region.V, region.F, lay.islands.islands, job.thickness, [r["EL"] for r in b.rows],
                            job.max_el or job.warn_pct / 100.0, sigma_mm=job.sigma_mm, curvatures=job.curvatures)
    add_sheet_figures(b.rows, lay, bending)
    job.build = b


def build_pattern_object(context, job: _UnfoldJob) -> bpy.types.Object:
    """Create (or refill) ``<name>_pattern`` from a job after `compute_pattern`; returns it."""
    region = job.region
    src = region.obj
    b, lay = job.build, job.layout
    name = src.name + PATTERN_SUFFIX
    me = mesh_io.new_mesh(name, b.co, b.polygons.corner_pat, b.polygons.loop_starts)
    mesh_io.write_attribute(me, ATTR_SOURCE_FACE, "INT", "FACE", b.polygons.polys)
    mesh_io.write_attribute(me, ATTR_PATCH, "INT", "FACE", b.poly_patch)
    mesh_io.write_attribute(me, ATTR_PIECE, "INT", "FACE", b.poly_piece)
    mesh_io.write_attribute(me, ATTR_SOURCE_VERTEX, "INT", "POINT", region.vert_ids[b.vert_source])
    mesh_io.write_attribute(me, ATTR_AREA_ERROR, "FLOAT", "FACE", b.area_error)
    mesh_io.write_face_colors(me, ATTR_AREA_COLOR, diverging_linear_rgba(b.area_error, AREA_COLOR_RANGE))
    obj = _link_object(context, src, name, me)
    el, ea, flipped = b.errors[None]
    obj[PROP_EL] = el
    obj[PROP_EA] = ea
    obj[PROP_SOURCE] = src.name
    obj[PROP_SHEET_THICKNESS] = job.thickness
    obj[PROP_MAX_EL] = job.max_el
    obj[PROP_PATTERN_TABLE] = json.dumps({
        "EL": el, "EA": ea, "flipped": flipped, "warn_pct": job.warn_pct, "max_el": job.max_el,
        "sheet_thickness_mm": job.thickness, "pieces": len(b.rows), "darts": len(lay.darts),
        "splits": len(lay.splits), "unmet": [{"patch": p, "reason": r} for p, r in lay.unmet],
        "islands": b.rows})
    return obj


class BOLUS_OT_unfold(BolusOperator, bpy.types.Operator):
    """Unfold every patch into a flat, true-scale pattern object (mass-spring with crossed springs, ch. 4.5), with darts and splits where a patch would exceed Max EL. Needs a skin surface (its patches from Segment into Patches, else the region is one patch); makes a new object '<name>_pattern' and the piece table"""

    bl_idname = "bolus.unfold"
    bl_label = "Unfold Patches"

    max_el: max_el_property()
    sheet_thickness_mm: sheet_thickness_property()
    method: unfold_method_property()
    refine: refine_property()
    gap_mm: gap_property()

    @classmethod
    def poll(cls, context):  # not on a pattern (would make '<name>_pattern_pattern')
        return poll_for(cls, context)

    # long: prepare / compute (modal: a worker thread) / finish, see blender/operator_base.py
    def prepare(self, context):
        return _UnfoldJob(context, self.method, self.refine, self.gap_mm, self.max_el, self.sheet_thickness_mm,
                          progress=self.progress)

    @staticmethod
    def compute(job, progress):
        job.progress = progress
        job.start()
        while job.step():
            progress(len(job.done) / job.count, f"{len(job.done)}/{job.count} islands unfolded")
        progress(1.0, "building the pattern")
        compute_pattern(job)
        return job

    def finish(self, context, job: _UnfoldJob, result=None):
        with mesh_io.object_mode(job.region.obj):
            obj = build_pattern_object(context, job)
        self.warn_all(job.warnings)
        for msg in job.infos:
            self.report({"INFO"}, msg)
        msgs = pattern_messages(job.layout.unfoldings, job.build.rows, job.build.errors, job.warn_pct, obj.name)
        last = [m for m in msgs if m[1].endswith("see the advice above")]  # the status bar shows the last report
        msgs = [m for m in msgs if m not in last]
        msgs += sheet_messages(job.build.rows, job.layout, job.max_el, job.thickness) + last
        for level, msg in msgs:
            self.report({level}, msg)
        return {"FINISHED"}


classes = (BOLUS_OT_unfold,)

