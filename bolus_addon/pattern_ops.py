"""Operators `bolus.unfold` and `bolus.export_pattern` (SPEC; seed 3.5, 4.5).

`unfold` never touches the source: it reads the region and its `bolus_patch` labels
and builds a new object ``<name>_pattern`` in z = 0 at true size (1 mm of pattern =
1 mm on the patient, in scene units), whose polygons are the source's polygons with
their corner order, one island per patch.  From the sidebar it runs modally, one patch
per step, with a progress bar; Esc cancels and leaves nothing behind.
"""
from __future__ import annotations

import json
import os
import re

import bpy
import numpy as np
from bpy.props import StringProperty
from mathutils import Matrix

from . import mesh_io
from .core.colormap import diverging_linear_rgba
from .core.errors import BolusError
from .core.overlap import signed_areas
from .core.pattern_svg import pattern_svg
from .core.piece_advice import DEFAULT_WARN_FRACTION, piece_advice
from .core.saliency import DEFAULT_SMOOTHING_MM
from .core.topology import MeshTopology, face_areas
from .core.unfold import assemble_pattern, iter_unfold_patches, polygon_area_error, polygon_errors
from .operators import ATTR_PATCH, BolusOperator
from .properties import gap_property, refine_property, seam_allowance_property, unfold_method_property

ATTR_SOURCE_FACE = "bolus_source_face"
ATTR_AREA_COLOR = "bolus_area_distortion"
PROP_PATTERN_TABLE = "bolus_pattern_table"
PATTERN_SUFFIX = "_pattern"
class _UnfoldJob:
    """The state of one unfolding: inputs, the patch iterator and the finished patches."""

    def __init__(self, context, method: str, refine: bool, gap_mm: float, progress=None):
        """progress(fraction, text): the core's progress (overall fraction, "patch k/n: step")."""
        self.region = region = mesh_io.read_region(context)
        self.warnings = list(region.warnings)
        me = region.mesh
        poly_labels = mesh_io.read_face_labels(region.obj, ATTR_PATCH)  # safe in Edit Mode
        if poly_labels is None:
            poly_labels = np.zeros(len(me.polygons), dtype=np.int64)
            self.warnings.append(f"no '{ATTR_PATCH}' attribute (run Segment first): unfolded as a single patch")
        tri_labels = poly_labels[region.tri_poly]
        outside = tri_labels < 0
        if outside.all():
            raise BolusError("none of the region's faces belongs to a patch: run Segment on this region first")
        if outside.any():
            # expected when a region was segmented: said once, as INFO (finish)
            self.infos = [f"{len(np.unique(region.tri_poly[outside]))} faces outside the segmented patches "
                          "(bolus_patch = -1) were left out of the pattern"]
        topo = MeshTopology(region.V, region.F)
        bad = int(topo.degenerate_faces().sum())
        if bad:
            raise BolusError(f"{bad} faces have zero area; remove them first (Mesh > Clean Up > Degenerate Dissolve)")
        # a patch cut in two by the region (or edited) becomes one island per connected piece
        _, comp = topo.face_components(np.where(outside, -1, tri_labels))
        comp = np.where(outside, -1, comp)
        uniq, self.islands = np.unique(comp, return_inverse=True)
        self.islands = self.islands - (1 if (uniq < 0).any() else 0)
        self.island_patch = np.full(int(self.islands.max()) + 1, -1, dtype=np.int64)
        self.island_patch[self.islands[~outside]] = tri_labels[~outside]
        self.poly_labels = poly_labels
        self.gap_mm = gap_mm
        self.iter = iter_unfold_patches(region.V, region.F, self.islands, method=method.lower(),
                                        refine_rounds=3 if refine else 0, progress=progress)
        self.done: list = []
        self.count = len(self.island_patch)

    def step(self) -> bool:
        """Unfold the next island; False when all are done."""
        try:
            _, _, u = next(self.iter)
        except StopIteration:
            return False
        self.done.append(u)
        return True


def is_pattern_object(obj) -> bool:
    """True for a ``<name>_pattern`` object made by Unfold."""
    return (obj is not None and obj.type == "MESH"
            and (PROP_PATTERN_TABLE in obj or ATTR_SOURCE_FACE in obj.data.attributes))


def diagnose_pieces(context, job: _UnfoldJob, rows: list[dict]) -> float:
    """Add to every row its pattern/skin area ratio, its angle excess/deficit and, when
    EL, EA (above ``Scene.bolus.warn_distortion_pct``), flips or overlaps make it a piece
    not to cut as it is, ``warn`` and the advice of `core.piece_advice`.  Returns the limit in %."""
    settings = getattr(context.scene, "bolus", None)
    warn_pct = float(getattr(settings, "warn_distortion_pct", DEFAULT_WARN_FRACTION * 100.0))
    sigma = float(getattr(settings, "smoothing_mm", DEFAULT_SMOOTHING_MM))
    region = job.region
    pieces_of = np.bincount(job.island_patch[job.island_patch >= 0])
    seen: dict[int, int] = {}
    for k, (u, row) in enumerate(zip(job.done, rows)):
        p = row["patch"]
        seen[p] = seen.get(p, 0) + 1
        row["name"] = f"patch {p}" + (f" piece {seen[p]}/{pieces_of[p]}" if pieces_of[p] > 1 else "")
        skin = float(face_areas(region.V[u.vert_origin], u.F).sum())
        row["area_ratio"] = float(signed_areas(u.UV, u.F).sum()) / skin if skin > 0 else 0.0
        Fk = region.F[job.islands == k]
        used, inv = np.unique(Fk.ravel(), return_inverse=True)
        try:
            adv = piece_advice(region.V[used], inv.reshape(-1, 3), row["EL"], row["EA"], row["flipped"],
                               row["overlaps"], threshold=warn_pct / 100.0, sigma_mm=sigma)
        except BolusError as exc:  # the figures are still worth a warning
            row.update(kind="", excess_rad=None, deficit_rad=None, advice=f"(no diagnosis: {exc})",
                       short_advice="", warn=bool(row["EL"] * 100 > warn_pct or row["EA"] * 100 > warn_pct
                                                  or row["flipped"] or row["overlaps"]))
            continue
        row.update(kind=adv.kind, excess_rad=adv.excess_rad, deficit_rad=adv.deficit_rad, advice=adv.advice,
                   short_advice=adv.short_advice, warn=adv.distorted)
    return warn_pct


def piece_warning(row: dict, warn_pct: float) -> str:
    """The WARNING for a piece not to cut as it is: its figures and the advice."""
    return (f"{row['name'].capitalize()}: EL {row['EL'] * 100:.1f} %, EA {row['EA'] * 100:.1f} %, pattern area "
            f"{row['area_ratio']:.2f} of the skin, {row['flipped']} flipped and {row['overlaps']} overlapping "
            f"triangles: above the {warn_pct:g} % limit, do not cut it as it is; {row['advice']}")


def core_notes(messages) -> tuple[list[str], list[str]]:
    """The core's per-patch messages as (warnings, infos): what they say about the pattern
    stays a warning, their advice to segment into more patches is dropped (the piece's own
    advice replaces it: more patches make angle-excess pieces worse), and the note that the
    unfolding started from a conformal map is information, not a problem."""
    warnings, infos = [], []
    for msg in messages:
        if msg.startswith("started from a conformal map"):
            infos.append(msg)
            continue
        msg = re.sub(r"[;:,]?\s*(segment|split) (it |the patch )?into more (patches|pieces)[^;]*", "", msg).strip()
        if msg:
            warnings.append(msg)
    return warnings, infos


def build_pattern_object(context, job: _UnfoldJob) -> bpy.types.Object:
    """Create (or refill) ``<name>_pattern`` from a finished job; returns it."""
    region = job.region
    src = region.obj
    me_src = region.mesh
    pattern = assemble_pattern(region.F, job.islands, job.done, gap_mm=job.gap_mm)
    keep_tri = pattern.tri_patch >= 0
    # polygon corners: the source corners of every region polygon, mapped to the pattern
    # vertex that the polygon's triangles use at that corner (vertices on a cut appear twice)
    lowest = np.full(len(me_src.polygons), np.iinfo(np.int64).max)
    np.minimum.at(lowest, region.tri_poly, job.islands)
    polys = region.poly_ids[lowest[region.poly_ids] >= 0]
    starts = np.empty(len(me_src.polygons), dtype=np.int64)
    sizes = np.empty(len(me_src.polygons), dtype=np.int64)
    me_src.polygons.foreach_get("loop_start", starts)
    me_src.polygons.foreach_get("loop_total", sizes)
    loop_v = np.empty(len(me_src.loops), dtype=np.int64)
    me_src.loops.foreach_get("vertex_index", loop_v)
    psz = sizes[polys]
    corner_idx = np.repeat(starts[polys] - np.concatenate([[0], np.cumsum(psz)[:-1]]), psz) + np.arange(psz.sum())
    corner_src = loop_v[corner_idx]  # mesh vertex ids
    corner_poly = np.repeat(polys, sizes[polys])
    nv = len(me_src.vertices)
    tri_src_v = region.vert_ids[region.F[keep_tri]]  # (t,3) mesh vertex ids
    tri_pat_v = pattern.F[keep_tri]
    tri_poly = np.repeat(region.tri_poly[keep_tri], 3)
    key = tri_poly * nv + tri_src_v.ravel()
    ukey, first = np.unique(key, return_index=True)
    lookup = tri_pat_v.ravel()[first]
    pos = np.searchsorted(ukey, corner_poly * nv + corner_src)
    corner_pat = lookup[pos]
    scale = region.mm_per_unit
    verts = np.zeros((len(pattern.UV), 3), dtype=np.float32)  # what the mesh will store
    verts[:, :2] = pattern.UV / scale
    pattern.UV = verts[:, :2].astype(np.float64) * scale  # report the errors of the stored pattern
    poly_sizes = sizes[polys]
    name = src.name + PATTERN_SUFFIX
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(verts))
    me.vertices.foreach_set("co", verts.ravel())
    me.loops.add(len(corner_pat))
    me.loops.foreach_set("vertex_index", corner_pat)
    me.polygons.add(len(polys))
    loop_starts = np.concatenate([[0], np.cumsum(poly_sizes)[:-1]]) if len(polys) else np.zeros(0, np.int64)
    me.polygons.foreach_set("loop_start", loop_starts)
    me.update(calc_edges=True)
    me.validate(clean_customdata=False)
    # errors exactly as SPEC measures them (n-gons fanned from the first corner)
    V_src_mm = np.empty(nv * 3)
    me_src.vertices.foreach_get("co", V_src_mm)
    M = np.array(src.matrix_world)
    V_src_mm = (V_src_mm.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]) * scale
    patch_of_poly = job.poly_labels[polys]
    errors = polygon_errors(V_src_mm, corner_src, pattern.UV, corner_pat, poly_sizes, groups=patch_of_poly)
    mesh_io.write_attribute(me, ATTR_SOURCE_FACE, "INT", "FACE", polys)
    mesh_io.write_attribute(me, ATTR_PATCH, "INT", "FACE", patch_of_poly)
    distortion = polygon_area_error(V_src_mm, corner_src, pattern.UV, corner_pat, poly_sizes)
    mesh_io.write_attribute(me, "bolus_area_error", "FLOAT", "FACE", distortion)
    mesh_io.write_face_colors(me, ATTR_AREA_COLOR, diverging_linear_rgba(distortion, 0.1))
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
    rows = []
    for k, u in enumerate(job.done):
        p = int(job.island_patch[k])
        el, ea, fl = errors.get(p, (u.EL, u.EA, u.flipped))
        rows.append({"island": k, "patch": p, "faces": int(np.count_nonzero(job.islands == k)), "EL": el, "EA": ea,
                     "flipped": fl, "overlaps": u.overlaps, "cut": u.cut, "seconds": round(u.seconds, 3),
                     "iterations": u.iterations, "method": u.method})
    warn_pct = diagnose_pieces(context, job, rows)
    total = errors[None]
    obj["bolus_EL"] = total[0]
    obj["bolus_EA"] = total[1]
    obj["bolus_source"] = src.name
    obj[PROP_PATTERN_TABLE] = json.dumps({"EL": total[0], "EA": total[1], "flipped": total[2], "warn_pct": warn_pct,
                                          "islands": rows})
    job.rows = rows
    job.warn_pct = warn_pct
    job.total = total
    return obj


class BOLUS_OT_unfold(BolusOperator, bpy.types.Operator):
    """Unfold every patch into a flat, true-scale pattern object (mass-spring with crossed springs, ch. 4.5)"""

    bl_idname = "bolus.unfold"
    bl_label = "Unfold Patches"

    method: unfold_method_property()
    refine: refine_property()
    gap_mm: gap_property()

    _timer = None
    _job = None

    @classmethod
    def poll(cls, context):
        if not super().poll(context):
            return False
        obj = context.active_object
        if is_pattern_object(obj):  # would make '<name>_pattern_pattern'
            src = obj.get("bolus_source", obj.name.removesuffix(PATTERN_SUFFIX))
            cls.poll_message_set(f"'{obj.name}' is a pattern made by Unfold: select its source '{src}' "
                                 "and unfold that")
            return False
        return True

    def run(self, context):
        job = _UnfoldJob(context, self.method, self.refine, self.gap_mm, progress=self.progress)
        while job.step():
            self.progress(len(job.done) / job.count, f"{len(job.done)}/{job.count} islands unfolded")
        return self.finish(context, job)

    def finish(self, context, job: _UnfoldJob):
        with mesh_io.object_mode(job.region.obj):
            obj = build_pattern_object(context, job)
        self.warn_all(job.warnings)
        for msg in getattr(job, "infos", []):
            self.report({"INFO"}, msg)
        for u, row in zip(job.done, job.rows):
            warnings, infos = core_notes(u.warnings)
            self.warn_all(f"{row['name']}: {w}" for w in warnings)
            for msg in infos:
                self.report({"INFO"}, f"{row['name']}: {msg}")
            if row["cut"]:
                self.report({"INFO"}, f"{row['name']}: not a disk, {row['cut']}")
        self.report({"INFO"}, f"Unfolded {len(job.done)} islands into '{obj.name}': EL {job.total[0] * 100:.2f} %, "
                              f"EA {job.total[1] * 100:.2f} %, {job.total[2]} flipped faces")
        for row in job.rows:
            self.report({"INFO"}, f"{row['name'].capitalize()}: {row['faces']} triangles, EL {row['EL'] * 100:.3f} %, "
                                  f"EA {row['EA'] * 100:.3f} %, flipped {row['flipped']}, pattern area "
                                  f"{row['area_ratio']:.3f} of the skin, {row['seconds']:.2f} s")
        bad = [row for row in job.rows if row.get("warn")]
        warn_pct = job.warn_pct
        self.warn_all(piece_warning(row, warn_pct) for row in bad)
        if bad:  # last, so the status bar shows it
            self.report({"WARNING"}, f"{len(bad)} of {len(job.rows)} pattern pieces are not fit to cut "
                                     f"(EL or EA above {warn_pct:g} %, or folded over): "
                                     + ", ".join(row["name"] for row in bad) + "; see the advice above")
        return {"FINISHED"}

    # interactive: one island per timer tick, Esc cancels.  BolusOperator guards both:
    # errors become reports (abort() first for modal), no window falls back to execute.
    def invoke(self, context, event):
        self._job = _UnfoldJob(context, self.method, self.refine, self.gap_mm, progress=self.progress)
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.01, window=context.window)
        wm.modal_handler_add(self)
        self.report({"INFO"}, f"Unfolding {self._job.count} islands (Esc to cancel)")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self.abort(context)
            self.report({"WARNING"}, "Unfolding cancelled: nothing was created")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"RUNNING_MODAL"}
        more = self._job.step()
        self.progress(len(self._job.done) / max(self._job.count, 1))
        if more and len(self._job.done) < self._job.count:
            return {"RUNNING_MODAL"}
        self.abort(context)
        return self.finish(context, self._job)

    def abort(self, context):
        """Remove the timer and the progress bar of the modal run (also after an error)."""
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()


def pattern_object_for(context) -> bpy.types.Object:
    """The active pattern object, or the pattern of the active source object."""
    obj = mesh_io.active_mesh_object(context)
    if ATTR_SOURCE_FACE in obj.data.attributes:
        return obj
    pat = bpy.data.objects.get(obj.name + PATTERN_SUFFIX)
    if pat is not None and pat.type == "MESH" and ATTR_SOURCE_FACE in pat.data.attributes:
        return pat
    raise BolusError(f"'{obj.name}' has no pattern yet: run Unfold Patches first")


def pattern_islands(context, pat: bpy.types.Object) -> list[dict]:
    """The pattern object's islands in mm, for the SVG (one per patch)."""
    me = pat.data
    scale = mesh_io.mm_per_unit(context.scene)
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    M = np.array(pat.matrix_world)
    P = (co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3])[:, :2] * scale
    me.calc_loop_triangles()
    nt = len(me.loop_triangles)
    tri = np.empty(nt * 3, dtype=np.int64)
    me.loop_triangles.foreach_get("vertices", tri)
    tri_poly = np.empty(nt, dtype=np.int64)
    me.loop_triangles.foreach_get("polygon_index", tri_poly)
    patch = np.empty(len(me.polygons), dtype=np.int64)
    me.attributes[ATTR_PATCH].data.foreach_get("value", patch)
    table = {}
    if PROP_PATTERN_TABLE in pat:
        try:
            for r in json.loads(pat[PROP_PATTERN_TABLE])["islands"]:
                table.setdefault(r["patch"], r)
        except (ValueError, KeyError, TypeError):
            table = {}
    F = tri.reshape(-1, 3)
    islands = []
    for p in np.unique(patch):
        Fp = F[patch[tri_poly] == p]
        verts, inv = np.unique(Fp.ravel(), return_inverse=True)
        row = table.get(int(p), {})
        islands.append({"UV": P[verts], "F": inv.reshape(-1, 3), "label": f"Patch {int(p)}",
                        "EL": row.get("EL"), "EA": row.get("EA")})
    return islands


class BOLUS_OT_export_pattern(BolusOperator, bpy.types.Operator):
    """Write the pattern as an SVG at true scale (print at 100 %), one labelled outline per patch"""

    bl_idname = "bolus.export_pattern"
    bl_label = "Export Pattern (SVG)"
    bl_options = {"REGISTER"}

    filepath: StringProperty(name="File", subtype="FILE_PATH", default="")
    filter_glob: StringProperty(default="*.svg", options={"HIDDEN"})
    seam_allowance_mm: seam_allowance_property()

    def invoke(self, context, event):
        if not self.filepath:
            obj = context.active_object
            base = obj.name if obj is not None else "pattern"
            self.filepath = bpy.path.abspath("//") + base.removesuffix(PATTERN_SUFFIX) + "_pattern.svg" if bpy.data.filepath else base + "_pattern.svg"
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def run(self, context):
        if not self.filepath:
            raise BolusError("choose a file to write the SVG to")
        path = bpy.path.abspath(self.filepath)
        if not path.lower().endswith(".svg"):
            path += ".svg"
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise BolusError(f"the folder '{folder}' does not exist")
        pat = pattern_object_for(context)
        islands = pattern_islands(context, pat)
        svg = pattern_svg(islands, seam_allowance_mm=self.seam_allowance_mm,
                          title=f"{pat.get('bolus_source', pat.name)}: bolus pattern")
        try:
            with open(path, "w", encoding="utf-8") as fh:
                fh.write(svg)
        except OSError as exc:
            raise BolusError(f"could not write '{path}': {exc.strerror or exc}") from exc
        self.report({"INFO"}, f"Wrote {len(islands)} patches to {path} (print at 100 %, check the 50 mm bar)")
        return {"FINISHED"}


classes = (BOLUS_OT_unfold, BOLUS_OT_export_pattern)
