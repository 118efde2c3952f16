"""What each step needs, in one place: the operators' polls and the sidebar panel ask here.

Every ``needs_*`` function takes the context and returns None when the step can run on the
active object, else one sentence saying what is missing and what to do.  An operator's
``poll`` is `poll_for`: its needs (`NEEDS`), the first reason as the poll message (the
tooltip of a greyed button, and the text of the RuntimeError a script gets); the panel
shows the same sentence as a label under the greyed step (a new user does not hover over
a greyed button).

Cheap by design (polls run at every redraw): names, attribute and custom-property look-ups
(`objects`), no mesh data read.  `next_step` tells the panel which step comes next.
"""
from __future__ import annotations

import bpy

from . import mesh_io
from .objects import (
    ATTR_FLATTENABILITY,
    ATTR_PATCH,
    ATTR_PRINT_PART,
    IMPROVED_SUFFIX,
    PROP_CUT_TABLE,
    PROP_PART_INDEX,
    PROP_PART_SOURCE,
    PROP_PATCH_TABLE,
    PROP_SOURCE,
    bolus_for,
    is_bolus_object,
    is_improved_object,
    is_pattern_object,
    part_objects,
    parts_source_name,
    pattern_of,
    pattern_source_name,
)


def needs_mesh(context) -> str | None:
    """The active object is a mesh (every operator works on it)."""
    obj = context.active_object
    if obj is None:
        return "No active object: select the skin surface mesh first"
    if obj.type != "MESH":
        return f"'{obj.name}' is not a mesh: select the skin surface mesh"
    return None


def needs_not_pattern(verb: str):
    """A need: the active object is not a pattern made by Unfold (``verb``: what to do to the source)."""

    def need(context) -> str | None:
        obj = context.active_object
        if is_pattern_object(obj):
            return f"'{obj.name}' is a pattern made by Unfold: select its source '{pattern_source_name(obj)}' and {verb}"
        return None

    return need


def needs_patches(context) -> str | None:
    """Smooth Cut Lines: the active skin has patches (``bolus_patch``, from Segment into Patches)."""
    why = needs_mesh(context) or needs_not_pattern("smooth its cuts")(context)
    if why:
        return why
    obj = context.active_object
    if ATTR_PATCH not in obj.data.attributes:
        return f"'{obj.name}' has no '{ATTR_PATCH}' attribute: run Segment into Patches first"
    return None


def needs_pattern(context) -> str | None:
    """Export Pattern: the active object is a pattern, or a skin that has one."""
    why = needs_mesh(context)
    if why:
        return why
    obj = context.active_object
    if pattern_of(obj) is None:
        return f"'{obj.name}' has no pattern yet: run Unfold Patches first, or select a pattern object"
    return None


def needs_not_bolus(context) -> str | None:
    """Make Bolus: the active object is not itself a bolus."""
    obj = context.active_object
    if is_bolus_object(obj):
        return (f"'{obj.name}' is a bolus made by Make Bolus: select the skin it was made on "
                f"('{obj.get(PROP_SOURCE, '?')}')")
    return None


def needs_not_improved(context) -> str | None:
    """Improve Flattenability: the active object is not an improved surface already."""
    obj = context.active_object
    if is_improved_object(obj):
        src = obj.get(PROP_SOURCE, obj.name.removesuffix(IMPROVED_SUFFIX))
        return (f"'{obj.name}' was made by Improve Flattenability: select its source '{src}' "
                "and improve that (with another max gap or method)")
    return None


def needs_parts(context) -> str | None:
    """Export Print Parts: the oriented part objects exist."""
    why = needs_mesh(context)
    if why:
        return why
    source = parts_source_name(context.active_object)
    if not part_objects(source):
        return f"'{source}' has no print parts yet: run Orient Print Parts first"
    return None


def needs_bolus_selected(context) -> str | None:
    """The panel's printed-bolus steps (Split, Orient): the active object is a bolus solid.

    Not an operator poll: the operators split and orient any surface too (SPEC; the parts of a
    skin surface are open pieces, not printable), but the guided panel leads to the solid."""
    why = needs_mesh(context)
    if why:
        return why
    obj = context.active_object
    if is_bolus_object(obj):
        return None
    b = bolus_for(obj)
    if b is not None and obj.get(PROP_SOURCE) == b.name:
        return f"'{obj.name}' is a print part: select the bolus '{b.name}' to split it again"
    if b is not None:
        return f"Select the bolus '{b.name}' (made by Make Bolus) to split it into print parts"
    return "Make the bolus first (Make Bolus) or select a bolus object"


def made_object(obj) -> tuple[str, str] | None:
    """(what obj is, the skin it comes from) for a pattern, a bolus or a print part; None for a skin
    (an improved surface is a skin: Unfold and Make Bolus take it)."""
    if obj is None or obj.type != "MESH":
        return None
    if is_pattern_object(obj):
        return "a pattern made by Unfold", pattern_source_name(obj)
    if is_bolus_object(obj):
        return "a bolus made by Make Bolus", obj.get(PROP_SOURCE, "?")
    if PROP_PART_INDEX in obj:  # a print part (orient_parts)
        b = bolus_for(obj)
        return "a print part", (b.get(PROP_SOURCE, "?") if b is not None else obj.get(PROP_SOURCE, "?"))
    return None


def needs_skin(context) -> str | None:
    """The panel's steps on the skin (1 to Unfold, Make Bolus): the active object is not a pattern, a
    bolus or a print part.  Not an operator poll (those refuse what they must, see `NEEDS`): the guide
    leads back to the skin."""
    made = made_object(context.active_object)
    return None if made is None else f"Select the skin '{made[1]}' for this step"


def has_preview(obj) -> bool:
    return obj is not None and obj.type == "MESH" and ATTR_FLATTENABILITY in obj.data.attributes


def has_patches(obj) -> bool:
    return obj is not None and obj.type == "MESH" and ATTR_PATCH in obj.data.attributes


#: what each operator needs (its poll and the panel ask `reason`); an operator not listed needs a mesh
NEEDS = {
    "bolus.import_dicom": (),  # a new object from a folder: nothing selected is needed
    "bolus.segment": (needs_mesh, needs_not_pattern("segment that")),
    "bolus.smooth_cuts": (needs_patches,),
    "bolus.improve_flattenability": (needs_mesh, needs_not_pattern("improve that"), needs_not_improved),
    "bolus.unfold": (needs_mesh, needs_not_pattern("unfold that")),
    "bolus.export_pattern": (needs_pattern,),
    "bolus.make_shell": (needs_mesh, needs_not_bolus),
    "bolus.export_parts": (needs_parts,),
}


def reason(idname: str, context) -> str | None:
    """Why the operator ``idname`` ('bolus.unfold') cannot run on the active object now, or None."""
    for need in NEEDS.get(idname, (needs_mesh,)):
        why = need(context)
        if why:
            return why
    return None


def poll_for(cls, context) -> bool:
    """An operator's poll: `reason` for its bl_idname, as the poll message when there is one."""
    why = reason(cls.bl_idname, context)
    if why:
        cls.poll_message_set(why)
        return False
    return True


def smooth_cuts_done(obj) -> bool:
    """Smooth Cut Lines has run on obj (on an improved surface: on its source), or there is no
    border to smooth (one patch)."""
    if is_improved_object(obj):
        obj = bpy.data.objects.get(obj.get(PROP_SOURCE, ""), obj)
    if PROP_CUT_TABLE in obj:
        return True
    t = mesh_io.json_prop(obj, PROP_PATCH_TABLE)
    return isinstance(t, dict) and (bool(t.get("smooth_cuts")) or len(t.get("patches", [])) <= 1)


def next_step(context) -> tuple[str, set[str]]:
    """(what to do next, the operators to highlight) from what the active object has."""
    obj = context.active_object
    if needs_mesh(context):
        return "Select the skin surface mesh (an STL imported in mm)", set()
    if is_pattern_object(obj):
        return "6a Export the pattern (SVG, DXF or PDF)", {"bolus.export_pattern"}
    if is_bolus_object(obj):
        if ATTR_PRINT_PART not in obj.data.attributes:
            return "6b Split into Print Parts", {"bolus.print_segment"}
        if not part_objects(obj.name):
            return "6b Orient Print Parts", {"bolus.orient_parts"}
        return "6b Export Print Parts (STL)", {"bolus.export_parts"}
    b = bolus_for(obj)
    if b is not None and obj.get(PROP_PART_SOURCE) == b.name:  # a print part
        return "6b Export Print Parts (STL)", {"bolus.export_parts"}
    if pattern_of(obj) is not None:
        return "6a Export the pattern (or 6b Make Bolus)", {"bolus.export_pattern"}
    if b is not None:
        return f"6b Select '{b.name}', then Split into Print Parts", set()
    if has_patches(obj):
        if smooth_cuts_done(obj):
            return "6a Unfold Patches or 6b Make Bolus", {"bolus.unfold", "bolus.make_shell"}
        return "4 Smooth Cut Lines", {"bolus.smooth_cuts"}
    if has_preview(obj):
        return "3 Segment into Patches", {"bolus.segment"}
    if obj.mode == "EDIT" and obj.data.total_face_sel > 0:
        return "2 Flattenability Preview of the selected faces", {"bolus.saliency_preview"}
    return "1 Select Treatment Area (or select faces in Edit Mode)", {"bolus.select_area"}
