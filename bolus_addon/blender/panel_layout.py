"""The sidebar's building blocks: step boxes, greyed gates with the reason, buttons with the settings.

`Guide` holds what one draw of the panel needs (the context, the scene's settings, the
sidebar's width, the next step) and draws a step's box with its number, title and hint
(`STEPS`), a column greyed with the reason why the step cannot run (`guide.reason`, the
operators' poll message), and an operator's button carrying the scene's settings
(`OP_SETTINGS`), the next step's larger and pressed.  Labels do not wrap themselves:
`wrapped_label` splits a sentence to the sidebar's width; `draw_table` draws a grid of labels.
"""
from __future__ import annotations

import textwrap

from . import guide

#: operator property <- Scene.bolus property, for the buttons of the panel and the menu
OP_SETTINGS = {
    "bolus.import_dicom": {},
    "bolus.select_area": {"radius_mm": "area_radius_mm", "exclude_cavities": "exclude_cavities"},
    "bolus.saliency_preview": {"smoothing_mm": "smoothing_mm", "color_by": "color_by"},
    "bolus.segment": {"patches": "patches", "eta": "eta", "seed": "seed", "smoothing_mm": "smoothing_mm",
                      "method": "method"},
    "bolus.smooth_cuts": {},
    "bolus.improve_flattenability": {"max_gap_mm": "max_gap_mm", "method": "improve_method", "seed": "seed"},
    "bolus.unfold": {"method": "unfold_method", "refine": "refine", "gap_mm": "gap_mm", "max_el": "max_el_pct",
                     "sheet_thickness_mm": "sheet_thickness_mm"},
    "bolus.export_pattern": {"seam_allowance_mm": "seam_allowance_mm", "page": "page", "label": "label"},
    "bolus.make_shell": {"thickness_mm": "thickness_mm", "clearance_mm": "clearance_mm",
                         "resolution_mm": "resolution_mm", "label": "label"},
    "bolus.print_segment": {"parts": "parts", "method": "print_method", "seed": "seed"},
    "bolus.orient_parts": {"layer_mm": "layer_mm", "skin_side_up": "skin_side_up"},
    "bolus.export_parts": {},
    "bolus.export_rtstruct": {},
    "bolus.build_library": {"directory": "library_dir"},
    "bolus.retrieve": {"filepath": "photo_path", "directory": "library_dir", "count": "retrieve_count",
                       "method": "retrieve_method"},
}

#: (number, title, icon, hint: what it does and what it needs) of every step, in order
STEPS = {
    "ct": ("0", "Import planning CT", "IMPORT", "The skin from a DICOM CT folder: the CT at a HU threshold, or its "
                                               "structure set's External ROI (optional: else import an STL in mm)"),
    "area": ("1", "Select area", "PIVOT_CURSOR", "Faces around the 3D cursor (needs: the skin, the cursor on it)"),
    "preview": ("2", "Preview", "COLOR", "Where the skin cannot lie flat (needs: the skin)"),
    "segment": ("3", "Segment", "MESH_ICOSPHERE", "Patches that flatten well (needs: the skin in one piece)"),
    "cuts": ("4", "Smooth cuts", "IPO_EASE_IN_OUT", "Smooth patch borders, changes the mesh (needs: patches)"),
    "improve": ("5", "Improve (optional)", "MOD_SMOOTH", "A flatter copy, at most Max gap off the skin "
                                                         "(needs: the skin)"),
    "sheet": ("6a", "Sheet pattern", "UV", "Flat pattern at true size, then export (needs: the skin, "
                                          "best with patches)"),
    "print": ("6b", "Printed bolus", "MOD_SOLIDIFY", "Solid, print parts, orient, export STL (needs: the skin)"),
    "planning": ("6c", "Export to planning system", "EXPORT", "The bolus as an RTSTRUCT on its planning CT (needs: "
                                                          "a closed solid on a DICOM skin, or the CT folder)"),
    "library": ("7", "Bolus library", "ASSET_MANAGER", "A stored bolus like a photo, to start from (needs: a folder "
                                                     "of .blend / .stl / .obj models, a photo)"),
}
#: the step each operator belongs to
STEP_OF = {"bolus.import_dicom": "ct", "bolus.export_rtstruct": "planning", "bolus.select_area": "area", "bolus.saliency_preview": "preview", "bolus.segment": "segment",
           "bolus.smooth_cuts": "cuts", "bolus.improve_flattenability": "improve", "bolus.unfold": "sheet",
           "bolus.export_pattern": "sheet", "bolus.make_shell": "print", "bolus.print_segment": "print",
           "bolus.orient_parts": "print", "bolus.export_parts": "print", "bolus.build_library": "library",
           "bolus.retrieve": "library"}


def set_settings(op, idname: str, s) -> None:
    """The Scene.bolus settings onto the operator properties of a button (`OP_SETTINGS`)."""
    for op_name, scene_name in OP_SETTINGS.get(idname, {}).items():
        setattr(op, op_name, getattr(s, scene_name))


def draw_table(layout, heads, rows, alert=()) -> None:
    """A table of labels: a header row, then one row per tuple of strings; rows whose
    index is in `alert` are drawn in red."""
    grid = layout.grid_flow(row_major=True, columns=len(heads), even_columns=True, align=True)
    for text in heads:
        grid.label(text=text)
    alert = set(alert)
    for i, row in enumerate(rows):
        for text in row:
            if i in alert:
                cell = grid.row()
                cell.alert = True
                cell.label(text=text)
            else:
                grid.label(text=text)


def wrapped_label(layout, text: str, width: int, icon: str = "NONE") -> None:
    """text on as many label lines as the sidebar's width needs (labels do not wrap themselves)."""
    for i, line in enumerate(textwrap.wrap(text, width) or [""]):
        layout.label(text=line, icon=icon if i == 0 else "BLANK1")


def text_width(context) -> int:
    """About how many characters a label line of the sidebar holds (44 headless)."""
    region = getattr(context, "region", None)
    if region is None or not getattr(region, "width", 0):
        return 44
    scale = context.preferences.system.ui_scale if context.preferences else 1.0
    return max(20, int(region.width / (7.0 * scale)))


class Guide:
    """What one draw of the panel needs: the context, the settings, the width, the next step."""

    def __init__(self, context):
        self.context = context
        self.s = context.scene.bolus
        self.obj = context.active_object
        self.width = text_width(context)
        self.next_text, self.next = guide.next_step(context)
        self.not_skin = guide.needs_skin(context)

    def step(self, layout, key: str):
        """A box with the step's number, title (an arrow when it holds the next step) and hint."""
        number, title, icon, hint = STEPS[key]
        box = layout.box()
        is_next = any(STEP_OF[i] == key for i in self.next)
        box.label(text=f"{number}  {title}", icon="FORWARD" if is_next else icon)
        col = box.column(align=True)
        col.scale_y = 0.8
        wrapped_label(col, hint, self.width)
        return box

    def gate(self, layout, why: str | None):
        """A column greyed when ``why`` (the reason, shown above it as a label) says the input is missing."""
        if why:
            wrapped_label(layout, why, self.width, icon="INFO")
        col = layout.column()
        col.enabled = not why
        return col

    def gate_op(self, layout, idname: str, skin: bool = False):
        """`gate` with the operator's poll reason; ``skin``: a step on the skin, greyed on a made
        object (a pattern, a bolus, a part) with the way back to the skin instead."""
        why = (self.not_skin if skin else None) or guide.reason(idname, self.context)
        return self.gate(layout, why)

    def button(self, layout, idname: str, text: str | None = None, icon: str = "NONE"):
        """The operator's button with the scene's settings; the next step's larger and pressed."""
        row = layout.row(align=True)
        is_next = idname in self.next
        if is_next:
            row.scale_y = 1.5
        kw = {"icon": icon, "depress": is_next}
        if text is not None:
            kw["text"] = text
        op = row.operator(idname, **kw)
        set_settings(op, idname, self.s)
        return op
