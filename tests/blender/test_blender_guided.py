"""The guided panel: steps in order, greyed with the reason, the next step
marked; every operator's poll gives a reason for missing input; F3 finds every operator (the
Bolus menu) with a label and a description of what it does, needs and makes.

The panel is drawn headless into the recording layout of test_blender_panel.py.
"""
from __future__ import annotations

import textwrap

import numpy as np
import pytest
from bpy_helpers import make_object
from meshgen import spherical_cap
from test_blender_panel import RecordingLayout, draw_panel

pytestmark = pytest.mark.blender

#: the steps' titles, in the order the panel must show them
STEP_TITLES = ["0  Import planning CT", "1  Select area", "2  Preview", "3  Segment", "4  Smooth cuts",
               "5  Improve (optional)", "6a  Sheet pattern", "6b  Printed bolus", "6c  Export to planning system"]


def bolus_operators(bpy) -> list[str]:
    """'bolus.segment', ... : every registered operator of the add-on."""
    return sorted(f"bolus.{name}" for name in dir(bpy.ops.bolus) if not name.startswith("_"))


#: the library's operators work on a folder and a photo, the planning CT's import on a folder, not on the
#: active object: never greyed for it
LIBRARY_OPS = {"bolus.build_library", "bolus.retrieve", "bolus.import_dicom"}


def op(bpy, idname):
    return getattr(bpy.ops.bolus, idname.split(".")[1])


def refusal(bpy, idname) -> str:
    """The poll message of an operator that must refuse: poll() False, and calling it raises
    RuntimeError carrying the message (what Blender 5.0 and 5.2 give a script)."""
    f = op(bpy, idname)
    assert not f.poll(), f"{idname} should refuse here"
    with pytest.raises(RuntimeError) as e:
        f()
    text = str(e.value)
    assert text.startswith(f"Operator bpy.ops.{idname}.poll() "), text
    return text.removeprefix(f"Operator bpy.ops.{idname}.poll() ")


def labels(log) -> list[str]:
    return [t for kind, t in log if kind == "label"]


def shown(log, text) -> bool:
    """text is on the panel, maybe wrapped over several label lines."""
    return " ".join(" ".join(labels(log)).split()).find(" ".join(text.split())) >= 0


def disabled(log) -> set[str]:
    return {t for kind, t in log if kind == "disabled" and t.startswith("bolus.")}


def next_ops(log) -> set[str]:
    return {t for kind, t in log if kind == "next"}


def sketch(log) -> str:
    """The recorded draw as text (for a person to read): [Button] pressed *[Button]*, greyed (Button)."""
    out, dis, nxt = [], disabled(log), next_ops(log)
    for kind, t in log:
        if kind == "label":
            out.append(t)
        elif kind == "operator":
            name = t.split(".")[1]
            out.append(f"*[{name}]*" if t in nxt else f"({name})" if t in dis else f"[{name}]")
    return "\n".join(out)


# ----------------------------------------------------------------------------- F3: names and descriptions
def test_every_operator_has_a_label_and_a_description(bpy_addon):
    bpy = bpy_addon
    ops = bolus_operators(bpy)
    assert len(ops) >= 11
    for idname in ops:
        rna = op(bpy, idname).get_rna_type()
        label, desc = rna.name, rna.description
        assert label and label[0].isupper() and label == label.strip(), idname
        words = [w for w in label.replace("(", " ").split() if w[0].isalpha() and w not in ("into", "of")]
        assert all(w[0].isupper() for w in words), f"{idname}: label not in Title Case: {label!r}"
        assert len(desc) >= 40, f"{idname}: description too short: {desc!r}"
        assert "Needs " in desc, f"{idname}: the description says what it needs: {desc!r}"


@pytest.mark.smoke
def test_f3_finds_every_operator_in_the_bolus_menu(bpy_addon, scene):
    """F3 (menu search) only finds operators that are in a menu: Object > Bolus and, in Edit
    Mode, Mesh > Bolus list every bolus operator, in the order of the steps."""
    bpy = bpy_addon
    from bolus_addon.blender.panel_layout import OP_SETTINGS

    VIEW3D_MT_bolus = bpy.types.VIEW3D_MT_bolus  # the registered class (the extension's copy of the module)
    for parent in VIEW3D_MT_bolus.parents:
        funcs = getattr(bpy.types, parent)._dyn_ui_initialize()
        assert VIEW3D_MT_bolus.draw_entry in funcs, parent
    log = []

    class Fake:
        layout = RecordingLayout(bpy, log)

    VIEW3D_MT_bolus.draw(Fake(), bpy.context)
    listed = [t for kind, t in log if kind == "operator"]
    assert sorted(listed) == bolus_operators(bpy)
    assert listed == list(OP_SETTINGS)  # step order, as the panel
    log.clear()
    VIEW3D_MT_bolus.draw_entry(Fake(), bpy.context)
    assert log == [("menu", "VIEW3D_MT_bolus")]


# ----------------------------------------------------------------------------- polls with reasons
@pytest.mark.smoke
def test_polls_refuse_missing_input_with_a_reason(bpy_addon, scene):
    bpy = bpy_addon
    mesh_ops = [i for i in bolus_operators(bpy) if i not in LIBRARY_OPS]
    for idname in mesh_ops:  # nothing active
        assert "No active object: select the skin surface mesh first" in refusal(bpy, idname)
    for idname in LIBRARY_OPS:  # a folder and a photo, checked when run
        assert op(bpy, idname).poll(), idname
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.view_layer.objects.active = cam
    for idname in mesh_ops:
        assert "'cam' is not a mesh: select the skin surface mesh" in refusal(bpy, idname)
    V, F = spherical_cap(60.0, 40.0, 3)
    ob = make_object(bpy, V, F, scale_length=0.001)
    assert refusal(bpy, "bolus.smooth_cuts") == "'skin' has no 'bolus_patch' attribute: run Segment into Patches first"
    assert refusal(bpy, "bolus.export_pattern") == ("'skin' has no pattern yet: run Unfold Patches first, or select a "
                                                    "pattern object")
    assert refusal(bpy, "bolus.export_parts") == "'skin' has no print parts yet: run Orient Print Parts first"
    for idname in ("bolus.select_area", "bolus.saliency_preview", "bolus.segment", "bolus.improve_flattenability",
                   "bolus.unfold", "bolus.make_shell", "bolus.print_segment", "bolus.orient_parts"):
        assert op(bpy, idname).poll(), idname
    # in Edit Mode the attribute is seen as well (segment run there)
    bpy.ops.object.mode_set(mode="EDIT")
    try:
        assert not bpy.ops.bolus.smooth_cuts.poll()
        assert bpy.ops.bolus.segment(patches=2) == {"FINISHED"}
        assert bpy.ops.bolus.smooth_cuts.poll()
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")
    assert bpy.ops.bolus.unfold() == {"FINISHED"}
    assert bpy.ops.bolus.export_pattern.poll()  # the skin has a pattern now
    bpy.context.view_layer.objects.active = pat = bpy.data.objects["skin_pattern"]
    assert bpy.ops.bolus.export_pattern.poll()
    for idname, verb in (("bolus.unfold", "unfold that"), ("bolus.improve_flattenability", "improve that"),
                         ("bolus.segment", "segment that"), ("bolus.smooth_cuts", "smooth its cuts")):
        assert refusal(bpy, idname) == f"'skin_pattern' is a pattern made by Unfold: select its source 'skin' and {verb}"
    # the refused pattern is untouched (smooth_cuts would have cut it: it carries bolus_patch)
    assert "bolus_patch" in pat.data.attributes and "bolus_cut_table" not in pat
    bpy.context.view_layer.objects.active = ob


def test_polls_refuse_made_objects(bpy_addon, scene):
    """A bolus is not made into a bolus, an improved surface not improved again."""
    bpy = bpy_addon
    V, F = spherical_cap(40.0, 50.0, 3)
    V = V + np.random.default_rng(1).uniform(-0.3, 0.3, V.shape)
    make_object(bpy, V, F, scale_length=0.001)
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=0.5) == {"FINISHED"}
    bpy.context.view_layer.objects.active = bpy.data.objects["skin_improved"]
    assert refusal(bpy, "bolus.improve_flattenability").startswith(
        "'skin_improved' was made by Improve Flattenability: select its source 'skin' and improve that")
    bpy.context.view_layer.objects.active = bpy.data.objects["skin"]
    assert bpy.ops.bolus.make_shell(thickness_mm=4.0, resolution_mm=1.0) == {"FINISHED"}
    bpy.context.view_layer.objects.active = bpy.data.objects["skin_bolus"]
    assert refusal(bpy, "bolus.make_shell") == ("'skin_bolus' is a bolus made by Make Bolus: select the skin it was "
                                                "made on ('skin')")


# ----------------------------------------------------------------------------- the panel through a case
def panel_state(bpy):
    log = draw_panel(bpy)
    return log, disabled(log), next_ops(log)


def test_panel_steps_are_numbered_in_order_with_the_unit_and_the_disclaimer(bpy_addon, scene):
    bpy = bpy_addon
    log = draw_panel(bpy)
    idx = [labels(log).index(t) for t in STEP_TITLES]
    assert idx == sorted(idx)
    assert "1 unit = 1000 mm; every figure is in mm" in labels(log)
    assert shown(log, "A planning aid, not a medical device: check every bolus on the planning CT before treatment")
    # the order of the buttons follows the steps
    first = {}
    for kind, t in log:
        if kind == "operator":
            first.setdefault(t, len(first))
    assert list(first) == ["bolus.import_dicom", "bolus.select_area", "bolus.saliency_preview", "bolus.segment",
                           "bolus.smooth_cuts", "bolus.improve_flattenability", "bolus.unfold", "bolus.export_pattern",
                           "bolus.make_shell", "bolus.print_segment", "bolus.orient_parts", "bolus.export_parts",
                           "bolus.export_rtstruct", "bolus.build_library", "bolus.retrieve"]


def test_panel_warns_in_red_when_the_size_says_the_units_are_wrong(bpy_addon, scene):
    """A 120 mm cap in a scene of 1 unit = 1 m is 120 m across: red, with the unit scale to set."""
    bpy = bpy_addon
    V, F = spherical_cap(60.0, 40.0, 2)
    make_object(bpy, V, F, scale_length=1.0)
    log = draw_panel(bpy)
    red = " ".join(t for kind, t in log if kind == "alert")
    assert "larger than 3 m" in red and "Unit Scale to 0.001" in red, red
    bpy.context.scene.unit_settings.scale_length = 0.001  # the same mesh in mm: no warning
    assert not [t for kind, t in draw_panel(bpy) if kind == "alert"]


def test_panel_walks_a_whole_case(bpy_addon, scene):
    """Empty scene, skin, area selected, previewed, segmented, cut, improved, unfolded, bolus,
    parts: at each stage the steps whose input is missing are greyed with the reason shown,
    and the next step is pressed."""
    bpy = bpy_addon
    all_ops = set(bolus_operators(bpy)) - LIBRARY_OPS
    print_ops = {"bolus.print_segment", "bolus.orient_parts"}
    skin_steps = {"bolus.select_area", "bolus.saliency_preview", "bolus.segment", "bolus.smooth_cuts",
                  "bolus.improve_flattenability", "bolus.unfold", "bolus.make_shell"}

    # empty scene: everything greyed, the reason shown, nothing pressed
    log, dis, nxt = panel_state(bpy)
    assert dis == all_ops and not nxt
    assert shown(log, "No active object: select the skin surface mesh first")
    assert shown(log, "Next: Select the skin surface mesh (an STL imported in mm)")

    # a skin: select the area next; smooth cuts, the exports and the print steps greyed, with reasons
    V, F = spherical_cap(80.0, 50.0, 3)
    ob = make_object(bpy, V, F, scale_length=0.001)
    log, dis, nxt = panel_state(bpy)
    assert dis == {"bolus.smooth_cuts", "bolus.export_pattern", "bolus.export_parts"} | print_ops
    assert nxt == {"bolus.select_area"}
    for why in ("'skin' has no 'bolus_patch' attribute: run Segment into Patches first",
                "'skin' has no pattern yet: run Unfold Patches first, or select a pattern object",
                "Make the bolus first (Make Bolus) or select a bolus object",
                "'skin' has no print parts yet: run Orient Print Parts first"):
        assert shown(log, why), why
    print("\n--- skin\n" + sketch(log))

    # the area selected (Edit Mode): preview next
    bpy.context.scene.cursor.location = tuple(V[np.argmax(V[:, 2])])  # 1 unit = 1 mm
    assert bpy.ops.bolus.select_area(radius_mm=45.0) == {"FINISHED"}
    assert ob.mode == "EDIT"
    log, dis, nxt = panel_state(bpy)
    assert nxt == {"bolus.saliency_preview"} and "bolus.smooth_cuts" in dis
    assert bpy.ops.bolus.saliency_preview() == {"FINISHED"}
    log, dis, nxt = panel_state(bpy)
    assert nxt == {"bolus.segment"} and shown(log, "Next: 3 Segment into Patches")
    assert any(t.startswith("Σϖ =") for t in labels(log))
    assert bpy.ops.bolus.segment(patches=3) == {"FINISHED"}
    log, dis, nxt = panel_state(bpy)
    assert nxt == {"bolus.smooth_cuts"} and "bolus.smooth_cuts" not in dis
    assert not shown(log, "has no 'bolus_patch' attribute")
    print("\n--- segmented\n" + sketch(log))
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    log, dis, nxt = panel_state(bpy)
    assert nxt == {"bolus.unfold", "bolus.make_shell"}
    assert dis == {"bolus.export_pattern", "bolus.export_parts"} | print_ops
    bpy.ops.object.mode_set(mode="OBJECT")

    # improved (optional): the improved surface selected, improving it again is greyed with the reason
    assert bpy.ops.bolus.improve_flattenability(max_gap_mm=0.5) == {"FINISHED"}
    bpy.context.view_layer.objects.active = bpy.data.objects["skin_improved"]
    log, dis, nxt = panel_state(bpy)
    assert "bolus.improve_flattenability" in dis
    assert shown(log, "'skin_improved' was made by Improve Flattenability: select its source 'skin'")
    assert nxt == {"bolus.unfold", "bolus.make_shell"}  # it carries the patches: unfold or make a bolus
    bpy.context.view_layer.objects.active = ob

    # unfolded: export next, from the skin or from the pattern (where unfold and the steps before are greyed)
    assert bpy.ops.bolus.unfold() == {"FINISHED"}
    log, dis, nxt = panel_state(bpy)
    assert nxt == {"bolus.export_pattern"} and "bolus.export_pattern" not in dis
    bpy.context.view_layer.objects.active = bpy.data.objects["skin_pattern"]
    log, dis, nxt = panel_state(bpy)
    assert nxt == {"bolus.export_pattern"}
    assert dis == skin_steps | {"bolus.export_parts"} | print_ops  # only the export is left
    assert shown(log, "'skin_pattern' is a pattern made by Unfold: the steps on the skin are greyed (select 'skin' "
                      "for them)")
    assert labels(log).count("Select the skin 'skin' for this step") == 7  # under each greyed skin step
    assert any(t.startswith("skin_pattern: EL") for t in labels(log))
    bpy.context.view_layer.objects.active = ob

    # the bolus: from the skin the guide says to select it; selected, split next
    assert bpy.ops.bolus.make_shell(thickness_mm=4.0, resolution_mm=1.0) == {"FINISHED"}
    bolus = bpy.data.objects["skin_bolus"]
    bpy.data.objects.remove(bpy.data.objects["skin_pattern"])  # the sheet branch not taken
    log, dis, nxt = panel_state(bpy)
    assert shown(log, "Select the bolus 'skin_bolus' (made by Make Bolus) to split it into print parts")
    assert print_ops <= dis and shown(log, "Next: 6b Select 'skin_bolus', then Split into Print Parts")
    bpy.context.view_layer.objects.active = bolus
    log, dis, nxt = panel_state(bpy)
    assert nxt == {"bolus.print_segment"} and dis == skin_steps | {"bolus.export_pattern", "bolus.export_parts"}
    assert shown(log, "'skin_bolus' is a bolus made by Make Bolus: the steps on the skin are greyed (select 'skin'")
    assert labels(log).count("Select the skin 'skin' for this step") == 7
    assert any(t.startswith("skin_bolus: ") and t.endswith(" g") for t in labels(log))
    print("\n--- bolus selected\n" + sketch(log))
    assert bpy.ops.bolus.print_segment(parts=2) == {"FINISHED"}
    log, dis, nxt = panel_state(bpy)
    assert nxt == {"bolus.orient_parts"} and "bolus.export_parts" in dis
    assert bpy.ops.bolus.orient_parts() == {"FINISHED"}
    log, dis, nxt = panel_state(bpy)
    assert nxt == {"bolus.export_parts"} and "bolus.export_parts" not in dis
    assert "whole" in labels(log)  # the orientation table
    # a part selected: export next; splitting the part is greyed with the way back to the bolus
    bpy.context.view_layer.objects.active = bpy.data.objects["skin_bolus_part_0"]
    log, dis, nxt = panel_state(bpy)
    assert nxt == {"bolus.export_parts"} and dis == skin_steps | print_ops | {"bolus.export_pattern"}
    assert shown(log, "'skin_bolus_part_0' is a print part: the steps on the skin are greyed (select 'skin'")
    assert shown(log, "'skin_bolus_part_0' is a print part: select the bolus 'skin_bolus' to split it again")


def test_long_reasons_wrap_to_the_sidebar(bpy_addon, scene):
    """Labels do not wrap in Blender: a reason longer than a line is drawn on several."""
    bpy = bpy_addon
    from bolus_addon.blender.panel_layout import wrapped_label

    log = []
    text = "'skin' has no pattern yet: run Unfold Patches first, or select a pattern object"
    wrapped_label(RecordingLayout(bpy, log), text, 30)
    assert [t for _, t in log] == textwrap.wrap(text, 30) and len(log) == 3
