"""What each step needs, in one place: the operators' polls and the sidebar panel ask here.

Every ``needs_*`` function takes the context and returns None when the step can run on the
active object, else one sentence saying what is missing and what to do.  An operator's
``poll`` is `poll_for`: its needs (`NEEDS`), the first reason as the poll message (the
tooltip of a greyed button, and the text of the RuntimeError a script gets); the panel
shows the same sentence as a label under the greyed step (a new user does not hover over
a greyed button).

Cheap by design (polls run at every redraw): names, attribute and custom-property look-ups,
no mesh data read.  The operator modules are imported inside the functions: they import
this module for their polls.
"""
from __future__ import annotations

from .operator_base import ATTR_FLATTENABILITY, ATTR_PATCH


def needs_mesh(context) -> str | None:
    """The active object is a mesh (every operator works on it)."""
    obj = context.active_object
    if obj is None:
        return "No active object: select the skin surface mesh first"
    if obj.type != "MESH":
        return f"'{obj.name}' is not a mesh: select the skin surface mesh"
    return None


def is_pattern(obj) -> bool:
    from ..operators.unfold import is_pattern_object  # noqa: PLC0415

    return is_pattern_object(obj)


def pattern_source_name(obj) -> str:
    from ..operators.unfold import PATTERN_SUFFIX  # noqa: PLC0415

    return obj.get("bolus_source", obj.name.removesuffix(PATTERN_SUFFIX))


def needs_not_pattern(verb: str):
    """A need: the active object is not a pattern made by Unfold (``verb``: what to do to the source)."""

    def need(context) -> str | None:
        obj = context.active_object
        if is_pattern(obj):
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


def pattern_of(obj):
    """The pattern to export for obj: obj itself (a pattern) or its ``<name>_pattern``; else None."""
    from ..operators.unfold import ATTR_SOURCE_FACE, PATTERN_SUFFIX  # noqa: PLC0415

    import bpy  # noqa: PLC0415

    if obj is None or obj.type != "MESH":
        return None
    if ATTR_SOURCE_FACE in obj.data.attributes:
        return obj
    pat = bpy.data.objects.get(obj.name + PATTERN_SUFFIX)
    if pat is not None and pat.type == "MESH" and ATTR_SOURCE_FACE in pat.data.attributes:
        return pat
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


def is_bolus(obj) -> bool:
    from ..operators.solid import is_bolus_object  # noqa: PLC0415

    return is_bolus_object(obj)


def is_improved(obj) -> bool:
    from ..operators.improve import is_improved_object  # noqa: PLC0415

    return is_improved_object(obj)


def needs_not_bolus(context) -> str | None:
    """Make Bolus: the active object is not itself a bolus."""
    obj = context.active_object
    if is_bolus(obj):
        return (f"'{obj.name}' is a bolus made by Make Bolus: select the skin it was made on "
                f"('{obj.get('bolus_source', '?')}')")
    return None


def needs_not_improved(context) -> str | None:
    """Improve Flattenability: the active object is not an improved surface already."""
    obj = context.active_object
    if is_improved(obj):
        from ..operators.improve import IMPROVED_SUFFIX  # noqa: PLC0415

        src = obj.get("bolus_source", obj.name.removesuffix(IMPROVED_SUFFIX))
        return (f"'{obj.name}' was made by Improve Flattenability: select its source '{src}' "
                "and improve that (with another max gap or method)")
    return None


def parts_source_name(obj) -> str:
    """The name whose ``<name>_part_<i>`` objects Export Print Parts writes (as its run finds them)."""
    own = is_bolus(obj) or is_improved(obj)  # their 'bolus_source' names the skin, their parts are their own
    return obj.name if own else obj.get("bolus_source", obj.name)


def needs_parts(context) -> str | None:
    """Export Print Parts: the oriented part objects exist."""
    from ..operators.printing import part_objects  # noqa: PLC0415

    why = needs_mesh(context)
    if why:
        return why
    source = parts_source_name(context.active_object)
    if not part_objects(source):
        return f"'{source}' has no print parts yet: run Orient Print Parts first"
    return None


def bolus_for(obj):
    """The bolus solid of obj: obj (a bolus), the bolus a part came from, or the skin's ``<name>_bolus``."""
    import bpy  # noqa: PLC0415

    from ..operators.solid import BOLUS_SUFFIX  # noqa: PLC0415

    if obj is None:
        return None
    if is_bolus(obj):
        return obj
    src = bpy.data.objects.get(obj.get("bolus_source", ""))
    if is_bolus(src):
        return src
    b = bpy.data.objects.get(obj.name + BOLUS_SUFFIX)
    return b if is_bolus(b) else None


def needs_bolus_selected(context) -> str | None:
    """The panel's printed-bolus steps (Split, Orient): the active object is a bolus solid.

    Not an operator poll: the operators split and orient any surface too (SPEC; the parts of a
    skin surface are open pieces, not printable), but the guided panel leads to the solid."""
    why = needs_mesh(context)
    if why:
        return why
    obj = context.active_object
    if is_bolus(obj):
        return None
    b = bolus_for(obj)
    if b is not None and obj.get("bolus_source") == b.name:
        return f"'{obj.name}' is a print part: select the bolus '{b.name}' to split it again"
    if b is not None:
        return f"Select the bolus '{b.name}' (made by Make Bolus) to split it into print parts"
    return "Make the bolus first (Make Bolus) or select a bolus object"


def made_object(obj) -> tuple[str, str] | None:
    """(what obj is, the skin it comes from) for a pattern, a bolus or a print part; None for a skin
    (an improved surface is a skin: Unfold and Make Bolus take it)."""
    if obj is None or obj.type != "MESH":
        return None
    if is_pattern(obj):
        return "a pattern made by Unfold", pattern_source_name(obj)
    if is_bolus(obj):
        return "a bolus made by Make Bolus", obj.get("bolus_source", "?")
    if "bolus_part" in obj:  # a print part (orient_parts)
        b = bolus_for(obj)
        return "a print part", (b.get("bolus_source", "?") if b is not None else obj.get("bolus_source", "?"))
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
