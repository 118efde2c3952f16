"""Operators `bolus.import_dicom` and `bolus.export_rtstruct` (SPEC): the planning CT in, the bolus back.

Import: `core.dicom.planning.import_skin` on the folder; the skin becomes a new mesh object in
DICOM patient coordinates (LPS, mm; SPEC's unit rule: 1 mm = 1 / (1000 scale_length) units),
active and selected, with the ``bolus_dicom_*`` custom properties (`objects.DICOM_PROPS`).
Export: the selected closed solids in world mm (`mesh_region.read_region` of each), on the CT
found through the source chain's ``bolus_dicom_*`` properties (`objects.dicom_source`) or the
folder given; `core.dicom.planning.export_rtstruct` writes the file atomically.  Both run their
core call in `compute`, in a worker thread (progress bar, Esc) from the sidebar, with the folder or
file already chosen or after the file browser (`_BrowseThenThread`); from a script in the main thread.
"""
from __future__ import annotations

import functools
import os

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, StringProperty

from ..blender import mesh_io, mesh_region
from ..blender.objects import (
    PROP_DICOM_DIR,
    PROP_DICOM_FRAME,
    PROP_DICOM_PATIENT,
    PROP_DICOM_SERIES,
    PROP_DICOM_STUDY,
    PROP_PART_INDEX,
    PROP_SOURCE,
    dicom_source,
)
from ..blender.operator_base import BolusOperator
from ..core.dicom.planning import export_rtstruct, import_skin
from ..core.dicom.skin import signed_volume
from ..core.errors import BolusError

SOURCE_ITEMS = [
    ("AUTO", "Auto", "The structure set's External ROI when the folder has one, else the CT"),
    ("CT", "CT", "The iso-surface of the largest body at the HU threshold (couch left out, cavities filled)"),
    ("RTSTRUCT", "RTSTRUCT", "The contours of the External ROI (or the ROI named below), holes respected"),
]


class _BrowseThenThread:
    """The file browser first, then the worker thread: ``invoke`` opens the browser when no path
    is set and marks it (``browsed``); Blender then calls ``execute``, which runs `compute` in a
    worker thread like the sidebar's run (Esc cancels) instead of in the main thread."""

    browsed: BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    def browse(self, context):
        self.browsed = True
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        if self.browsed and getattr(context, "window", None) is not None:
            self.browsed = False
            return self._guarded(functools.partial(BolusOperator._threaded_invoke, self), context, None,
                                 on_error=self.abort)
        return BolusOperator.execute(self, context)


class BOLUS_OT_import_dicom(_BrowseThenThread, BolusOperator, bpy.types.Operator):
    """Import the skin from a planning CT folder (DICOM): from the CT at a HU threshold or from the structure set's External ROI, in patient coordinates (LPS, mm), with the CT's identifiers so the bolus can go back as an RTSTRUCT. Needs a folder of CT slices (uncompressed); makes a new object"""

    bl_idname = "bolus.import_dicom"
    bl_label = "Import Planning CT"

    directory: StringProperty(name="CT folder", subtype="DIR_PATH", default="")
    source: EnumProperty(name="Skin from", items=SOURCE_ITEMS, default="AUTO")
    threshold_hu: FloatProperty(name="Threshold (HU)", default=-350.0, min=-1024.0, max=3000.0,
                                description="The skin is the iso-surface at this CT number (air -1000, fat -100)")
    roi_name: StringProperty(name="ROI name", default="",
                             description="The structure set's ROI to import (empty: the External ROI)")

    modal = BolusOperator._threaded_modal

    @classmethod
    def poll(cls, context):
        if context.mode != "OBJECT":
            cls.poll_message_set("Leave Edit Mode first (Tab): the planning CT comes in as a new object")
            return False
        return True

    def invoke(self, context, event):
        if not self.directory:
            return self.browse(context)
        return BolusOperator._threaded_invoke(self, context, event)

    def prepare(self, context):
        path = bpy.path.abspath(self.directory) if self.directory else ""
        if not path or not os.path.isdir(path):
            raise BolusError(f"'{self.directory}' is not a folder: choose the folder of the planning CT's DICOM files")
        return {"directory": os.path.normpath(path), "source": self.source, "threshold": float(self.threshold_hu),
                "roi": self.roi_name.strip(), "mm": mesh_io.mm_per_unit(context.scene)}

    @staticmethod
    def compute(job, progress):
        return import_skin(job["directory"], job["source"], job["threshold"], job["roi"], progress)

    def finish(self, context, job, skin):
        name = (f"{skin.patient_id}_skin" if skin.patient_id else "ct_skin")[:60]
        V = skin.V / job["mm"]
        corners = np.ascontiguousarray(skin.F, dtype=np.int32).ravel()
        me = mesh_io.new_mesh(name, V, corners, np.arange(0, len(corners), 3, dtype=np.int32))
        for layer in (".select_vert", ".select_edge", ".select_poly"):  # nothing selected: no region yet
            attr = me.attributes.get(layer)
            if attr is not None:
                me.attributes.remove(attr)
        obj = bpy.data.objects.new(name, me)
        context.collection.objects.link(obj)
        for o in context.view_layer.objects:
            o.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        obj[PROP_DICOM_FRAME], obj[PROP_DICOM_STUDY] = skin.frame_uid, skin.study_uid
        obj[PROP_DICOM_SERIES], obj[PROP_DICOM_DIR] = skin.series_uid, skin.directory
        obj[PROP_DICOM_PATIENT] = skin.patient_id
        self.warn_all(skin.warnings)
        how = f"the ROI '{skin.roi_name}'" if skin.source == "RTSTRUCT" else f"the CT at {job['threshold']:g} HU"
        self.report({"INFO"}, f"Imported '{obj.name}' from {how}: {skin.summary}; {len(skin.F):,} triangles "
                              "in patient coordinates (LPS, mm)")
        return {"FINISHED"}


def _selected_solids(context) -> list:
    objs = [o for o in context.selected_objects if o.type == "MESH"]
    act = context.active_object
    if act is not None and act.type == "MESH" and act not in objs:
        objs.insert(0, act)
    if not objs:
        raise BolusError("Select the bolus solid(s) to export (closed meshes)")
    return objs


class BOLUS_OT_export_rtstruct(_BrowseThenThread, BolusOperator, bpy.types.Operator):
    """Export the selected closed solids as an RTSTRUCT on the planning CT their skin came from: exact sections at every CT slice, RT ROI Interpreted Type BOLUS. Needs a closed solid made on a skin from Import Planning CT (or a CT folder). Check the structure in the planning system before use"""

    bl_idname = "bolus.export_rtstruct"
    bl_label = "Export RTSTRUCT"

    filepath: StringProperty(name="File", subtype="FILE_PATH", default="")
    filter_glob: StringProperty(default="*.dcm", options={"HIDDEN"})
    roi_name: StringProperty(name="ROI name", default="Bolus", description="The new ROI's name (one per solid: "
                             "several solids get their object names after it)")
    rel_electron_density: FloatProperty(name="Rel. electron density", default=0.0, min=0.0, max=10.0,
                                        description="Written as the ROI's REL_ELEC_DENSITY when above 0")
    include_existing: BoolProperty(name="Keep the CT's structures", default=True,
                                   description="Carry over the ROIs of the CT folder's structure set")
    ct_directory: StringProperty(name="CT folder", subtype="DIR_PATH", default="",
                                 description="The planning CT (empty: the one the skin was imported from)")

    modal = BolusOperator._threaded_modal

    def invoke(self, context, event):
        if not self.filepath:
            src = dicom_source(context.active_object)
            folder = str(src[PROP_DICOM_DIR]) if src is not None and PROP_DICOM_DIR in src else os.getcwd()
            self.filepath = os.path.join(folder, "RS_bolus.dcm")
            return self.browse(context)
        return BolusOperator._threaded_invoke(self, context, event)

    def prepare(self, context):
        path = bpy.path.abspath(self.filepath) if self.filepath else ""
        if not path:
            raise BolusError("Choose the RTSTRUCT file to write")
        if not path.lower().endswith(".dcm"):
            path += ".dcm"
        objs = _selected_solids(context)
        solids, frames, ct_dir = [], set(), bpy.path.abspath(self.ct_directory) if self.ct_directory else ""
        for obj in objs:
            if PROP_PART_INDEX in obj:
                raise BolusError(f"'{obj.name}' is a print part turned onto the build plate: select the bolus "
                                 f"'{obj.get(PROP_SOURCE, '?')}' (its split parts stay in place there)")
            src = dicom_source(obj)
            if src is None and not ct_dir:
                raise BolusError(f"'{obj.name}' has no DICOM frame (its skin was not imported from a planning CT): "
                                 "give the CT folder (CT folder) to export it on")
            if src is not None:
                frames.add(str(src[PROP_DICOM_FRAME]))
                ct_dir = ct_dir or str(src.get(PROP_DICOM_DIR, ""))
            region = mesh_region.read_region(context, obj=obj, polys=np.ones(len(obj.data.polygons), dtype=bool))
            F = region.F if signed_volume(region.V, region.F) >= 0 else region.F[:, ::-1]  # a mirroring transform
            name = self.roi_name.strip() or "Bolus"
            solids.append((name if len(objs) == 1 else f"{name} {obj.name}", region.V, F))
        if len(frames) > 1:
            raise BolusError("the selected solids come from different CTs: export them one CT at a time")
        return {"path": path, "ct": ct_dir, "solids": solids, "frame": next(iter(frames), ""),
                "density": float(self.rel_electron_density), "existing": bool(self.include_existing)}

    @staticmethod
    def compute(job, progress):
        return export_rtstruct(job["path"], job["ct"], job["solids"], job["density"], job["existing"],
                               job["frame"], progress)

    def finish(self, context, job, res):
        self.warn_all(res["warnings"])
        kept = f", {len(res['existing'])} ROI(s) of the CT's structure set kept" if res["existing"] else ""
        self.report({"INFO"}, f"Wrote {', '.join(res['rois'])} ({res['contours']} contours{kept}) to {job['path']} "
                              f"on {res['summary']}: check the structure in the planning system before use")
        return {"FINISHED"}


classes = (BOLUS_OT_import_dicom, BOLUS_OT_export_rtstruct)
