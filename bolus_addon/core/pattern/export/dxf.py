"""The pattern drawing as a DXF for a cutting plotter or laser (ezdxf), in millimetres.

`drawing_dxf` writes one `pattern_drawing.Drawing`: header ``$INSUNITS`` = 4 (mm) and
``$MEASUREMENT`` = 1 (metric), so a cutter does not guess the units; layers

* ``CUT`` - one closed LWPOLYLINE per cut loop of every piece (the outer outline, and
  one per hole),
* ``SEAM_ALLOWANCE`` - the seam allowance, closed and dashed,
* ``MARKS`` - seam ticks, dart legs (dashed), the 50 mm test square,
* ``LABELS`` - TEXT entities (height in mm): piece labels, mark numbers, notes.

DXF's y axis points up: paper (x, y) -> DXF (x, H - y), H the drawing's height, so the
pattern is seen from above as on paper.  Coordinates are written at full precision.
"""
from __future__ import annotations

import io

import numpy as np

from ...errors import BolusError
from ..drawing import CUT, LABELS, MARKS, SEAM_ALLOWANCE, Drawing

__all__ = ["drawing_dxf", "LAYER_COLORS"]

#: ACI colours of the layers (7 = black/white, 1 red, 5 blue, 3 green)
LAYER_COLORS = {CUT: 7, SEAM_ALLOWANCE: 5, MARKS: 1, LABELS: 3}


def drawing_dxf(drawing: Drawing) -> bytes:
    """The DXF file (bytes, DXF R2010) of the drawing, in mm (see the module docstring)."""
    try:
        import ezdxf
        from ezdxf.enums import TextEntityAlignment
    except ImportError as exc:  # pragma: no cover - bundled with the add-on
        raise BolusError(f"DXF export needs the ezdxf package, which is missing: {exc}") from None
    doc = ezdxf.new("R2010", setup=True)  # setup: the standard line types (DASHED) and text styles
    doc.header["$INSUNITS"] = 4
    doc.header["$MEASUREMENT"] = 1
    doc.header["$LUNITS"] = 2
    doc.units = 4
    for name, color in LAYER_COLORS.items():
        doc.layers.add(name, color=color)
    msp = doc.modelspace()
    H = drawing.height

    def pts(P):
        P = np.asarray(P, dtype=np.float64)
        return [(float(x), float(H - y)) for x, y in P]

    def stroke(st):
        attrs = {"layer": st.layer, "const_width": 0.0}
        if st.dashed:
            attrs["linetype"] = "DASHED"
            attrs["ltscale"] = 0.1
        msp.add_lwpolyline(pts(st.points), format="xy", close=st.closed, dxfattribs=attrs)

    def text(t):
        align = TextEntityAlignment.CENTER if t.anchor == "middle" else TextEntityAlignment.LEFT
        x, y = pts(t.pos[None])[0]
        style = "OpenSans-Bold" if t.bold and "OpenSans-Bold" in doc.styles else "OpenSans"
        if style not in doc.styles:
            style = "Standard"
        msp.add_text(t.text, height=float(t.size), dxfattribs={"layer": LABELS, "style": style}).set_placement(
            (x, y), align=align)

    for dp in drawing.pieces:
        for st in dp.cut + dp.seam + dp.marks:
            stroke(st)
        for t in dp.texts + dp.mark_texts:
            text(t)
    for st in drawing.strokes:
        if st.kind != "bar":  # the bar is the square's bottom side
            stroke(st)
    for t in drawing.texts:
        text(t)
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue().encode(doc.output_encoding, errors="replace")
