"""The labels engraved on a bolus: text outlines from Blender's font, the patient's left.

`core.solid.engrave.engrave_labels` cuts the label (and "<label> <part>" on print parts) and
the L / R markers into the outer face; it needs the outline of every string it writes (read
here from Blender's built-in font, `text_outlines`) and the world vector to the patient's left
(the sidebar's *Patient left*).  The outlines and the vector are read in the main thread;
`engrave_with` is bpy-free, for a worker thread.
"""
from __future__ import annotations

import numpy as np

#: the world axis to the patient's left for each `left_axis` setting (world = DICOM LPS by default)
LEFT_VECTORS = {"+X": (1.0, 0.0, 0.0), "-X": (-1.0, 0.0, 0.0)}


def left_vector(context) -> np.ndarray:
    """(3,) unit world vector to the patient's left (Scene.bolus.left_axis)."""
    settings = getattr(context.scene, "bolus", None)
    return np.array(LEFT_VECTORS[getattr(settings, "left_axis", "+X")], dtype=np.float64)


def label_outlines(label: str, part_count: int | None = None) -> dict:
    """The TextOutline of every string `engrave_labels` needs for ``label`` (Blender's font)."""
    from . import text_outlines  # noqa: PLC0415 (the font needs Blender; only when a label is asked)
    from ..core.solid.engrave import strings_needed  # noqa: PLC0415

    return {s: text_outlines.text_outline(s) for s in strings_needed(label, part_count)}


def engrave(context, V, F, side, label: str, part_labels=None):
    """`core.solid.engrave.engrave_labels` with outlines from Blender's font -> (V, F, side, part labels, warnings)."""
    parts = None if part_labels is None else int(np.max(part_labels)) + 1
    return engrave_with(V, F, side, label_outlines(label, parts), label, left_vector(context), part_labels)


def engrave_with(V, F, side, outlines: dict, label: str, left, part_labels=None):
    """`engrave` with the outlines and the left vector read beforehand (bpy-free: a worker thread's)."""
    from ..core.solid.engrave import engrave_labels  # noqa: PLC0415

    return engrave_labels(V, F, side, outlines, label, left, part_labels=part_labels, return_labels=True)
