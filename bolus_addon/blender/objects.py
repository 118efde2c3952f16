"""The names of what the add-on makes, each defined once, and the look-ups that recognise it.

Object suffixes (``<name>_pattern``, ``<name>_bolus``, ``<name>_part_<i>`` ...), mesh
attributes (``bolus_patch``, ``bolus_print_part`` ...) and custom properties (``bolus_source``,
``bolus_*_table`` ...): scripts outside the add-on read them (docs/operators.md lists them), so
the strings never change.  "SPEC" marks the names the contract fixes; the others are ours.

The predicates and look-ups below read names, attributes and custom properties only, never
mesh data: the operators' polls and the panel call them at every redraw.
"""
from __future__ import annotations

import re

import bpy

# ------------------------------------------------------------------ object suffixes
PATTERN_SUFFIX = "_pattern"  #: the pattern Unfold makes of ``<name>``
IMPROVED_SUFFIX = "_improved"  #: the surface Improve Flattenability makes of ``<name>``
BOLUS_SUFFIX = "_bolus"  #: SPEC: the solid Make Bolus makes of ``<name>``
SKIN_SUFFIX = "_skin"  #: ``<name>_bolus_skin``: the skin region a bolus was made on (a kept mesh)
SOLID_SUFFIX = "_solid"  #: ``<name>_bolus_solid``: the bolus before its labels (a kept mesh)
PART_INFIX = "_part_"  #: SPEC: ``<name>_part_<i>``, the print parts Orient Print Parts makes

# ------------------------------------------------------------------ mesh attributes
#: SPEC: the preview (point domain) and the patches (face domain)
ATTR_FLATTENABILITY = "bolus_flattenability"
ATTR_SALIENCY = "bolus_saliency"
ATTR_SALIENCY_COLOR = "bolus_saliency_color"
ATTR_PATCH = "bolus_patch"
#: a display colour per patch (corner domain, so borders stay crisp)
ATTR_PATCH_COLOR = "bolus_patch_color"
#: the improved surface: the air gap in mm (point domain) and its colours
ATTR_AIR_GAP = "bolus_air_gap"
ATTR_AIR_GAP_COLOR = "bolus_air_gap_color"
#: the pattern: source polygon, piece and source vertex of each face / vertex, the area error
ATTR_SOURCE_FACE = "bolus_source_face"
ATTR_PIECE = "bolus_piece"
ATTR_SOURCE_VERTEX = "bolus_source_vertex"
ATTR_AREA_COLOR = "bolus_area_distortion"
ATTR_AREA_ERROR = "bolus_area_error"
#: SPEC: the print part of each face; its colours and the overhang colours of a part object
ATTR_PRINT_PART = "bolus_print_part"
ATTR_PRINT_PART_COLOR = "bolus_print_part_color"
ATTR_OVERHANG_COLOR = "bolus_overhang"
#: SPEC: the side of the bolus solid each face belongs to (SIDE_* of core.solid)
ATTR_SHELL_SIDE = "bolus_shell_side"
#: a FACE INT attribute that carries the treatment area through `mesh_cuts.apply_cuts`; removed afterwards
ATTR_AREA_TMP = "bolus_area_tmp"

# ------------------------------------------------------------------ custom properties
PROP_PREFIX = "bolus_"  #: every custom property of ours starts so (a re-run clears them)
PROP_SOURCE = "bolus_source"  #: the object a made object comes from
#: the preview's figures and the tables the panel shows
PROP_SUM_VARPI = "bolus_sum_varpi"
PROP_FLV = "bolus_flv"
PROP_PATCH_TABLE = "bolus_patch_table"
PROP_CUT_TABLE = "bolus_cut_table"  #: one row per border (method, turning before/after, shift)
#: the improved surface
PROP_IMPROVE_TABLE = "bolus_improve_table"
PROP_MAX_GAP = "bolus_max_gap_mm"
PROP_FLV_BEFORE = "bolus_FLV_before"
PROP_FLV_AFTER = "bolus_FLV_after"
PROP_SUM_VARPI_BEFORE = "bolus_sum_varpi_before"
PROP_SUM_VARPI_AFTER = "bolus_sum_varpi_after"
PROP_MAX_AIR_GAP = "bolus_max_air_gap_mm"
#: the pattern
PROP_PATTERN_TABLE = "bolus_pattern_table"
PROP_EL = "bolus_EL"
PROP_EA = "bolus_EA"
PROP_SHEET_THICKNESS = "bolus_sheet_thickness_mm"
PROP_MAX_EL = "bolus_max_el"
#: SPEC: a print part's build direction and figures; ours: its source and index, the tables
PROP_DIRECTION = "bolus_print_direction"
PROP_WQ = "bolus_WQ"
PROP_WU = "bolus_WU"
PROP_SUPPORT = "bolus_support_volume_mm3"
PROP_PRINT_TABLE = "bolus_print_table"
PROP_ORIENT_TABLE = "bolus_orient_table"
PROP_PART_SOURCE = PROP_SOURCE  #: a part object: the object it is a part of
PROP_PART_INDEX = "bolus_part"
PROP_CONNECTORS = "bolus_connectors"  #: a split bolus solid: its joints and connectors (JSON)
#: SPEC: the bolus solid's thickness, volume and wall; ours: the rest of its figures and stored meshes
PROP_THICKNESS = "bolus_thickness_mm"
PROP_VOLUME = "bolus_volume_cm3"
PROP_THICKNESS_MIN = "bolus_thickness_min_mm"
PROP_THICKNESS_MAX = "bolus_thickness_max_mm"
PROP_THICKNESS_MEAN = "bolus_thickness_mean_mm"
PROP_MASS = "bolus_mass_g"
PROP_DENSITY = "bolus_density_g_cm3"
PROP_CLEARANCE = "bolus_clearance_mm"
PROP_RESOLUTION = "bolus_resolution_mm"
PROP_LABEL = "bolus_label"
PROP_SKIN_MESH = "bolus_skin_mesh"
PROP_SOLID_MESH = "bolus_solid_mesh"
PROP_HOLES = "bolus_holes"
#: SPEC: the scene's last retrieval; ours: the last library build (scene), an imported match's file
PROP_RETRIEVAL = "bolus_retrieval"
PROP_RETRIEVAL_INFO = "bolus_retrieval_info"  #: ours: the last retrieval's method, photo and confidence
PROP_LIBRARY = "bolus_library"
PROP_MATCH_SOURCE = "bolus_library_model"
#: SPEC: a skin imported from a planning CT (and every object made from it): its frame of
#: reference, study, CT series, CT folder and patient, so the bolus goes back onto that CT
PROP_DICOM_FRAME = "bolus_dicom_frame_uid"
PROP_DICOM_STUDY = "bolus_dicom_study_uid"
PROP_DICOM_SERIES = "bolus_dicom_ct_series_uid"
PROP_DICOM_DIR = "bolus_dicom_ct_dir"
PROP_DICOM_PATIENT = "bolus_dicom_patient_id"
DICOM_PROPS = (PROP_DICOM_FRAME, PROP_DICOM_STUDY, PROP_DICOM_SERIES, PROP_DICOM_DIR, PROP_DICOM_PATIENT)


# ------------------------------------------------------------------ what an object is
def is_pattern_object(obj) -> bool:
    """True for a ``<name>_pattern`` object made by Unfold."""
    return (obj is not None and obj.type == "MESH"
            and (PROP_PATTERN_TABLE in obj or ATTR_SOURCE_FACE in obj.data.attributes))


def is_improved_object(obj) -> bool:
    """True for a ``<name>_improved`` object made by Improve Flattenability."""
    return obj is not None and obj.type == "MESH" and PROP_IMPROVE_TABLE in obj


def is_bolus_object(obj) -> bool:
    """True for a solid made by Make Bolus (it carries the face attribute ``bolus_shell_side``)."""
    return obj is not None and obj.type == "MESH" and ATTR_SHELL_SIDE in obj.data.attributes


def is_solid_part(part) -> bool:
    """A part object made from a bolus solid (its source carries ``bolus_shell_side``)."""
    src = bpy.data.objects.get(part.get(PROP_PART_SOURCE, ""))
    return is_bolus_object(src)


# ------------------------------------------------------------------ the objects that belong together
def part_objects(source_name: str) -> list[bpy.types.Object]:
    """The ``<name>_part_<i>`` objects of a source, by part index."""
    pat = re.compile(re.escape(source_name + PART_INFIX) + r"(\d+)$")
    found = [(int(m.group(1)), ob) for ob in bpy.data.objects if (m := pat.match(ob.name))]
    return [ob for _, ob in sorted(found, key=lambda t: t[0])]


def parts_source_name(obj) -> str:
    """The name whose ``<name>_part_<i>`` objects Export Print Parts writes (as its run finds them):
    the 'bolus_source' of a bolus or an improved surface names the skin it was made from, their
    parts are their own; a print part's names the object it is a part of."""
    own = is_bolus_object(obj) or is_improved_object(obj)
    return obj.name if own else obj.get(PROP_PART_SOURCE, obj.name)


def pattern_source_name(obj) -> str:
    """The skin a pattern was unfolded from."""
    return obj.get(PROP_SOURCE, obj.name.removesuffix(PATTERN_SUFFIX))


def pattern_of(obj):
    """The pattern to export for obj: obj itself (a pattern) or its ``<name>_pattern``; else None."""
    if obj is None or obj.type != "MESH":
        return None
    if ATTR_SOURCE_FACE in obj.data.attributes:
        return obj
    pat = bpy.data.objects.get(obj.name + PATTERN_SUFFIX)
    if pat is not None and pat.type == "MESH" and ATTR_SOURCE_FACE in pat.data.attributes:
        return pat
    return None


def bolus_for(obj):
    """The bolus solid of obj: obj (a bolus), the bolus a part came from, or the skin's ``<name>_bolus``."""
    if obj is None:
        return None
    if is_bolus_object(obj):
        return obj
    src = bpy.data.objects.get(obj.get(PROP_SOURCE, ""))
    if is_bolus_object(src):
        return src
    b = bpy.data.objects.get(obj.name + BOLUS_SUFFIX)
    return b if is_bolus_object(b) else None


def improved_of(obj):
    """The improved surface to show figures of: obj itself or its ``<name>_improved``."""
    if obj is None:
        return None
    if PROP_IMPROVE_TABLE in obj:
        return obj
    return bpy.data.objects.get(obj.name + IMPROVED_SUFFIX)


def print_source(obj):
    """The object whose print tables to show: obj, or the source a print part names (a bolus and an
    improved surface name their skin in 'bolus_source' too, but their parts are their own)."""
    if (obj is not None and PROP_PART_SOURCE in obj and not is_bolus_object(obj)
            and PROP_IMPROVE_TABLE not in obj):
        return bpy.data.objects.get(obj[PROP_PART_SOURCE], obj)
    return obj


def dicom_source(obj):
    """The first object along the source chain (obj, its ``bolus_source``, that one's ...) that
    carries the DICOM frame (``bolus_dicom_frame_uid``), or None."""
    seen = set()
    while obj is not None and obj.name not in seen:
        if PROP_DICOM_FRAME in obj:
            return obj
        seen.add(obj.name)
        obj = bpy.data.objects.get(str(obj.get(PROP_SOURCE, "")))
    return None
