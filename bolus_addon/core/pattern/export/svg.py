"""The flat pattern as an SVG at true scale (1 mm on the pattern = 1 mm on paper).

* `drawing_svg` - the SVG writer of `pattern_drawing.Drawing` (one drawing, three writers:
  also `pattern_dxf`, `pattern_pdf`): width and height in mm with a viewBox in mm, the
  pattern seen from above (+y up on paper), one ``<g id="patch-<label>">`` per piece
  with its cut lines, optional dashed seam allowance, its label and its marks, the
  50 mm test square;
* `pattern_svg` - pieces (and marks) in, document out (`pattern_drawing` + `drawing_svg`);
* `svg_outline_paths` - the cut lines read back into pattern millimetres.

`outline_loops` / `outline_loop_indices` live in `pattern_drawing`, `offset_polygon` and
`signed_area` in `polygon_offset`; they are re-exported here.
"""
from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np

from ...errors import BolusError
from ..drawing import (
    PRINT_NOTE,
    SKIN_NOTE,
    TEST_SQUARE_MM,
    Drawing,
    Stroke,
    Text,
    outline_loop_indices,
    outline_loops,
    pattern_drawing,
)
from ..polygon_offset import offset_polygon, signed_area

__all__ = [
    "outline_loops",
    "outline_loop_indices",
    "offset_polygon",
    "signed_area",
    "pattern_svg",
    "svg_outline_paths",
    "drawing_svg",
    "SCALE_BAR_MM",
]

SVG_NS = "http://www.w3.org/2000/svg"
#: the side of the test square (its bottom side is the scale bar) the user checks the print with
SCALE_BAR_MM = TEST_SQUARE_MM


# --------------------------------------------------------------------------- SVG
def _fmt(v: float, decimals: int) -> str:
    s = f"{v:.{decimals}f}"
    return s[1:] if s.startswith("-") and float(s) == 0 else s


def _path_d(P: np.ndarray, decimals: int) -> str:
    f = [f"{_fmt(x, decimals)} {_fmt(y, decimals)}" for x, y in P]
    return "M " + " L ".join(f) + " Z"


def _safe_id(label: str, taken: set) -> str:
    base = "patch-" + (re.sub(r"[^A-Za-z0-9_.-]", "_", label) or "_")
    name, k = base, 2
    while name in taken:
        name, k = f"{base}-{k}", k + 1
    taken.add(name)
    return name


def _stroke(parent, st: Stroke, f, path_decimals: int) -> None:
    """Closed cut / seam-allowance loops as ``<path class=cut|seam>`` (what `svg_outline_paths`
    reads), everything else as ``<polyline>`` / ``<polygon>`` (never a path)."""
    attrs = {"class": st.kind, "fill": "none", "stroke": "#000000", "stroke-width": f(st.width)}
    if st.dashed:
        attrs["stroke-dasharray"] = "2 1"
    if st.kind in ("cut", "seam"):
        attrs["d"] = _path_d(st.points, path_decimals)
        if st.kind == "cut":
            attrs["stroke-linejoin"] = "round"
        ET.SubElement(parent, "path", attrs)
        return
    attrs["points"] = " ".join(f"{f(x)},{f(y)}" for x, y in st.points)
    ET.SubElement(parent, "polygon" if st.closed else "polyline", attrs)


def _text(parent, t: Text, f) -> None:
    attrs = {"class": t.kind, "x": f(t.pos[0]), "y": f(t.pos[1]), "font-size": f(t.size),
             "font-family": "sans-serif", "fill": "#000000"}
    if t.anchor == "middle":
        attrs["text-anchor"] = "middle"
    if t.bold:
        attrs["font-weight"] = "bold"
    if t.kind in ("print-note", "pattern-title", "square-label"):
        attrs["id"] = {"print-note": "print-note", "pattern-title": "pattern-title",
                       "square-label": "scale-label"}[t.kind]
    ET.SubElement(parent, "text", attrs).text = t.text


def drawing_svg(drawing: Drawing, decimals: int = 3, path_decimals: int = 5) -> str:
    """The `pattern_drawing.Drawing` as an SVG document (str): width, height and viewBox in mm.

    One ``<g class="patch">`` per piece with its cut paths, dashed seam-allowance paths and
    label texts, and a ``<g class="marks">`` inside it with the seam ticks, numbers, dart
    legs and the skin-side mark; then the footer: the test square (``<polygon
    id="test-square">``, its bottom side ``<line id="scale-bar">``) and the notes.
    """
    D = drawing
    f = lambda v: _fmt(v, decimals)  # noqa: E731
    root = ET.Element("svg", {
        "xmlns": SVG_NS, "version": "1.1",
        "width": f"{f(D.width)}mm", "height": f"{f(D.height)}mm", "viewBox": f"0 0 {f(D.width)} {f(D.height)}",
    })
    ET.SubElement(root, "title").text = D.title or "Bolus pattern"
    ET.SubElement(root, "desc").text = (
        "Bolus pattern at true scale: 1 user unit = 1 mm. Solid lines are cut lines, dashed lines the "
        f"seam allowance. {PRINT_NOTE[0].upper() + PRINT_NOTE[1:]}; the test square must measure "
        f"{TEST_SQUARE_MM:g} mm. {SKIN_NOTE[0].upper() + SKIN_NOTE[1:]}.")
    ET.SubElement(root, "metadata", {"id": "bolus-frame"}).text = json.dumps(
        {"units": "mm", "paper_x": "x + ox", "paper_y": "oy - y", "ox": D.frame["ox"], "oy": D.frame["oy"],
         "seam_allowance_mm": D.seam_allowance_mm})
    g_all = ET.SubElement(root, "g", {"id": "patches"})
    taken: set = set()
    for dp in D.pieces:
        g = ET.SubElement(g_all, "g", {"id": _safe_id(dp.name, taken), "class": "patch"})
        for st in dp.cut + dp.seam:
            _stroke(g, st, f, path_decimals)
        for t in dp.texts:
            if t.kind != "skin-side":
                _text(g, t, f)
        gm = ET.SubElement(g, "g", {"class": "marks"})
        for st in dp.marks:
            _stroke(gm, st, f, path_decimals)
        for t in dp.mark_texts + [t for t in dp.texts if t.kind == "skin-side"]:
            _text(gm, t, f)
    g = ET.SubElement(root, "g", {"id": "scale"})
    for st in D.strokes:
        if st.kind == "bar":
            (a, b) = st.points
            ET.SubElement(g, "line", {"id": "scale-bar", "x1": f(a[0]), "y1": f(a[1]), "x2": f(b[0]),
                                      "y2": f(b[1]), "stroke": "#000000", "stroke-width": f(st.width)})
        elif st.kind == "square":
            pts = " ".join(f"{f(x)},{f(y)}" for x, y in st.points)
            ET.SubElement(g, "polygon", {"id": "test-square", "points": pts, "fill": "none", "stroke": "#000000",
                                         "stroke-width": f(st.width)})
        else:
            _stroke(g, st, f, path_decimals)
    for t in D.texts:
        _text(g, t, f)
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def pattern_svg(islands, seam_allowance_mm: float = 0.0, title: str = "", margin_mm: float = 10.0,
                decimals: int = 3, path_decimals: int = 5, *, marks=None, label: str = "") -> str:
    """SVG document (str) of laid-out islands at true scale.

    Parameters
    ----------
    islands : [{"UV": (n,2) mm, "F": (m,3), "label": str, "EL": float, "EA": float, ...}] in
        pattern coordinates (already laid out); EL and EA are ratios (0.0123 is shown as
        "EL 1.23 %"), either may be missing; see `pattern_drawing.pattern_drawing`
    seam_allowance_mm, margin_mm : lengths >= 0 (BolusError otherwise)
    decimals, path_decimals : decimals of numbers and of outline coordinates: rounding
        every corner of a ragged 250-corner outline to 1 um changes its perimeter by up
        to about 0.02 mm, to 0.01 um by about 1e-4 mm
    marks : `pattern_marks.PatternMarks` of the same pattern, or None; label: the user's
        label (e.g. patient ID) on every piece

    Returns
    -------
    The document: the page is ``margin_mm`` around the pattern plus a footer with the
    50 mm test square; width and height in mm, viewBox in mm, +y of the pattern up on paper.
    """
    D = pattern_drawing(islands, marks, label=label, title=title, seam_allowance_mm=seam_allowance_mm,
                        margin_mm=margin_mm, decimals=decimals)
    return drawing_svg(D, decimals, path_decimals)


_TOKEN = re.compile(r"[A-Za-z]|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _parse_d(d: str) -> list[np.ndarray]:
    """Sub-paths [(k,2)] of an SVG path made of M/L/H/V/Z commands (absolute or relative)."""
    toks = _TOKEN.findall(d)
    subpaths, cur, pos, cmd, i = [], [], np.zeros(2), None, 0
    while i < len(toks):
        t = toks[i]
        if t.isalpha():
            cmd, i = t, i + 1
            if cmd in "Zz":
                if cur:
                    subpaths.append(np.array(cur))
                    pos = np.array(cur[0])
                cur = []
            elif cmd not in "MmLlHhVv":
                raise BolusError(f"unsupported SVG path command {cmd!r} (only straight lines are read)")
            continue
        if cmd is None or cmd in "Zz":
            raise BolusError("malformed SVG path data")
        rel = cmd.islower()
        if cmd in "MmLl":
            p = np.array([float(toks[i]), float(toks[i + 1])]) + (pos if rel else 0)
            i += 2
            if cmd in "Mm":
                if cur:
                    subpaths.append(np.array(cur))
                cur = []
                cmd = "l" if rel else "L"  # further pairs are line-tos
        else:
            v = float(toks[i]) + (pos[0 if cmd in "Hh" else 1] if rel else 0)
            i += 1
            p = np.array([v, pos[1]]) if cmd in "Hh" else np.array([pos[0], v])
        cur.append(p)
        pos = p
    if cur:
        subpaths.append(np.array(cur))
    out = []
    for P in subpaths:
        if len(P) > 1 and np.allclose(P[0], P[-1], rtol=0, atol=1e-12):
            P = P[:-1]
        out.append(P)
    return out


def svg_outline_paths(svg_text: str, kind: str = "cut") -> list[np.ndarray]:
    """Cut lines (or ``kind="seam"``) of a `pattern_svg` document as polylines [(k,2)] in pattern mm.

    Undoes the margin and the y flip recorded in the document, so the loops come back
    in the coordinates the islands were given in (to the written precision), in order.
    """
    try:
        root = ET.fromstring(svg_text)
    except ET.ParseError as exc:
        raise BolusError(f"not a readable SVG document: {exc}") from None
    ox, oy = 0.0, None
    for el in root.iter():
        if el.tag.rsplit("}", 1)[-1] == "metadata" and el.get("id") == "bolus-frame":
            frame = json.loads(el.text)
            ox, oy = float(frame["ox"]), float(frame["oy"])
    if oy is None:  # not written by pattern_svg: flip about the page height only
        oy = float(root.get("viewBox", "0 0 0 0").split()[3])
    out = []
    for el in root.iter():
        if el.tag.rsplit("}", 1)[-1] == "path" and kind in (el.get("class") or "").split():
            for P in _parse_d(el.get("d", "")):
                out.append(np.stack([P[:, 0] - ox, oy - P[:, 1]], axis=1))
    return out
