"""Text outlines from Blender's built-in font, for the engraved labels (`blender.labels`).

`text_outline(text)` gives a `core.solid.engrave.TextOutline`: a temporary FONT curve holding the
text is linked to the scene, evaluated to a mesh (its filled glyphs), and the boundary loops of
those triangles (`core.mesh.boundary.boundary_loops`, after merging duplicate vertices) become the
outline polygons -- outer ones counter-clockwise, holes ("A", "B", "8") clockwise -- scaled so
that the cap height (the height of "H") is 1.0, baseline y = 0.  The curve, its object and a
font datablock loaded for it are removed again: nothing stays in bpy.data (works headless, in
``--background``).  Results are cached per string.
"""
from __future__ import annotations

import functools

import bpy
import numpy as np

from ..core.mesh.boundary import boundary_loops
from ..core.solid.engrave import TextOutline
from ..core.errors import BolusError

__all__ = ["text_outline"]

_TMP_NAME = "bolus_text_outline_tmp"


def _glyph_triangles(text: str) -> tuple[np.ndarray, np.ndarray]:
    """The filled glyphs of ``text`` in Blender's built-in font at size 1: (V (n,2), F (m,3))."""
    fonts_before = {f.name for f in bpy.data.fonts}
    cu = bpy.data.curves.new(_TMP_NAME, type="FONT")
    ob = None
    try:
        cu.body = text
        cu.align_x = "LEFT"
        cu.align_y = "TOP_BASELINE"
        cu.size = 1.0
        cu.fill_mode = "BOTH"
        ob = bpy.data.objects.new(_TMP_NAME, cu)
        bpy.context.scene.collection.objects.link(ob)
        ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
        me = ev.to_mesh()
        try:
            n = len(me.vertices)
            co = np.empty(3 * n)
            me.vertices.foreach_get("co", co)
            me.calc_loop_triangles()
            tri = np.empty(3 * len(me.loop_triangles), dtype=np.int64)
            me.loop_triangles.foreach_get("vertices", tri)
        finally:
            ev.to_mesh_clear()
    finally:
        if ob is not None:
            bpy.data.objects.remove(ob, do_unlink=True)
        bpy.data.curves.remove(cu)
        for f in list(bpy.data.fonts):
            if f.name not in fonts_before and f.users == 0:
                bpy.data.fonts.remove(f)
    return co.reshape(-1, 3)[:, :2], tri.reshape(-1, 3)


def _outline_polygons(V: np.ndarray, F: np.ndarray) -> list[np.ndarray]:
    """Boundary loops of the glyph triangles as polygons (k,2): filled side on the left."""
    key = np.round(V * 1e6).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    V, F = V[first], inv.reshape(-1)[F]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 2] != F[:, 0])]
    if len(F) == 0:
        return []
    e1, e2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    if np.sum(e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]) < 0:
        F = F[:, ::-1]  # triangles facing -z: turn them so that outer loops run counter-clockwise
    return [V[loop] for loop in boundary_loops(F) if len(loop) >= 3]


@functools.lru_cache(maxsize=None)
def _cap_height() -> float:
    V, _ = _glyph_triangles("H")
    return float(V[:, 1].max())


@functools.lru_cache(maxsize=256)
def _cached(text: str) -> tuple[tuple[np.ndarray, ...], float]:
    V, F = _glyph_triangles(text)
    polys = _outline_polygons(V, F)
    if not polys:
        raise BolusError(f"the text '{text}' has no visible letters in Blender's built-in font")
    cap = _cap_height()
    polys = tuple(p / cap for p in polys)
    return polys, float(max(p[:, 0].max() for p in polys))


def text_outline(text: str) -> TextOutline:
    """`TextOutline` of one line of ``text`` in Blender's built-in font: polygons (k,2) with cap
    height 1.0 and baseline y = 0, outer outlines counter-clockwise, holes clockwise; width: the
    right end of the last letter.  BolusError for an empty text or one the font cannot show."""
    text = str(text)
    if not text.strip() or "\n" in text:
        raise BolusError(f"cannot engrave {text!r}: give one line of text")
    polys, width = _cached(text)
    return TextOutline([p.copy() for p in polys], width)
