"""The pattern drawing as a PDF (fpdf2, vectors and text only, unit mm): one page or tiled.

`drawing_pdf(drawing, page)`:

* ``page='NONE'`` - one page the drawing's size (for a plotter or a print shop);
* ``'A4'`` / ``'LETTER'`` - the drawing tiled over pages for a home printer: each page
  shows a window of ``cw x ch`` mm of the drawing (paper size less `PAGE_MARGIN_MM` on
  every side and the footer strip), neighbouring windows overlap by `TILE_OVERLAP_MM`;
  registration crosses sit in the middle of the overlap strips (in drawing coordinates,
  so the same cross shows on both pages: lay one on the other), corner marks frame every
  window, and every page's footer carries its own 50 mm test square, "row r col c of
  R x C" and "print at 100 %, no scaling".  Portrait or landscape, whichever needs fewer
  pages (portrait on a tie).

Home printers drift about 1 mm per page: measure the test square on every page.
Text uses the PDF core font Helvetica (Latin-1; other characters print as "?").
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from ...errors import BolusError
from ..drawing import PAGES, TEST_SQUARE_MM, Drawing, Stroke, Text, test_square_strokes

__all__ = ["drawing_pdf", "tile_grid", "TILE_OVERLAP_MM", "PAGE_MARGIN_MM", "FOOTER_MM", "MAX_PAGE_MM"]

#: neighbouring tiles show this much of the drawing twice
TILE_OVERLAP_MM = 10.0
#: no drawing within this distance of the paper's edge (what home printers cannot print)
PAGE_MARGIN_MM = 8.0
#: the footer strip of a tile: the test square (50 mm) and the notes
FOOTER_MM = 60.0
#: registration cross arm length and corner mark length (mm)
CROSS_MM, CORNER_MM = 4.0, 6.0
PT_PER_MM = 72.0 / 25.4
#: the largest page side a PDF may have (14400 pt, ISO 32000)
MAX_PAGE_MM = 14400 / PT_PER_MM
TILE_NOTE = "print at 100 %, no scaling; the square must measure 50 mm"


def tile_grid(W: float, H: float, paper: tuple[float, float]) -> tuple[int, int, float, float]:
    """(rows, cols, window width cw, window height ch) of a W x H mm drawing on paper (w, h) mm."""
    cw = paper[0] - 2 * PAGE_MARGIN_MM
    ch = paper[1] - 2 * PAGE_MARGIN_MM - FOOTER_MM
    if cw <= TILE_OVERLAP_MM or ch <= TILE_OVERLAP_MM:
        raise BolusError(f"the paper {paper[0]:g} x {paper[1]:g} mm is too small to tile on")
    cols = max(1, math.ceil((W - TILE_OVERLAP_MM) / (cw - TILE_OVERLAP_MM) - 1e-9))
    rows = max(1, math.ceil((H - TILE_OVERLAP_MM) / (ch - TILE_OVERLAP_MM) - 1e-9))
    return rows, cols, cw, ch


def _latin1(s: str) -> str:
    return s.encode("latin-1", "replace").decode("latin-1")


class _Pen:
    """Draws Strokes and Texts of the drawing shifted by (dx, dy) onto the current fpdf page."""

    def __init__(self, pdf, dx: float = 0.0, dy: float = 0.0):
        self.pdf, self.dx, self.dy = pdf, dx, dy

    def stroke(self, st: Stroke) -> None:
        pdf = self.pdf
        pdf.set_line_width(st.width)
        if st.dashed:
            pdf.set_dash_pattern(dash=2, gap=1)
        pts = [(float(x + self.dx), float(y + self.dy)) for x, y in st.points]
        if st.closed:
            pdf.polygon(pts, style="D")
        else:
            pdf.polyline(pts, style="D")
        if st.dashed:
            pdf.set_dash_pattern()

    def text(self, t: Text) -> None:
        pdf = self.pdf
        pdf.set_font("helvetica", "B" if t.bold else "", t.size * PT_PER_MM)
        s = _latin1(t.text)
        x = float(t.pos[0] + self.dx)
        if t.anchor == "middle":
            x -= pdf.get_string_width(s) / 2
        pdf.text(x, float(t.pos[1] + self.dy), s)


def _box(P) -> tuple:
    P = np.asarray(P).reshape(-1, 2)
    return P[:, 0].min(), P[:, 1].min(), P[:, 0].max(), P[:, 1].max()


def _items(drawing: Drawing) -> list:
    """Every stroke and text of the drawing as (kind 's'|'t', item, bbox)."""
    out = []
    for dp in drawing.pieces:
        for st in dp.cut + dp.seam + dp.marks:
            out.append(("s", st, _box(st.points)))
        for t in dp.texts + dp.mark_texts:
            out.append(("t", t, _text_box(t)))
    for st in drawing.strokes:
        if st.kind != "bar":
            out.append(("s", st, _box(st.points)))
    for t in drawing.texts:
        out.append(("t", t, _text_box(t)))
    return out


def _text_box(t: Text) -> tuple:
    w = 0.7 * t.size * len(t.text)
    x0 = t.pos[0] - (w / 2 if t.anchor == "middle" else 0)
    return x0, t.pos[1] - t.size, x0 + w, t.pos[1] + 0.3 * t.size


def _cross(pen: _Pen, x: float, y: float) -> None:
    pen.stroke(Stroke(np.array([[x - CROSS_MM, y], [x + CROSS_MM, y]]), False, "MARKS", "cross", 0.15))
    pen.stroke(Stroke(np.array([[x, y - CROSS_MM], [x, y + CROSS_MM]]), False, "MARKS", "cross", 0.15))


def drawing_pdf(drawing: Drawing, page: str = "NONE") -> tuple[bytes, list]:
    """(PDF bytes, tiles [(row, col, x0, y0, w, h)]: the drawing's window (paper mm) on every page)."""
    try:
        with warnings.catch_warnings():  # fpdf2 warns that it cannot add images without Pillow: it adds none
            warnings.filterwarnings("ignore", message="Pillow could not be imported")
            from fpdf import FPDF
    except ImportError as exc:  # pragma: no cover - bundled with the add-on
        raise BolusError(f"PDF export needs the fpdf2 package, which is missing: {exc}") from None
    page = str(page or "NONE").upper()
    W, H = drawing.width, drawing.height
    items = _items(drawing)
    if page == "NONE":
        if max(W, H) > MAX_PAGE_MM:
            raise BolusError(f"the pattern ({W:.0f} x {H:.0f} mm) is too large for one PDF page (at most "
                             f"{MAX_PAGE_MM:.0f} mm a side): choose A4 or Letter to tile it, or export a DXF")
        pdf = FPDF(unit="mm", format=(W, H))
        _setup(pdf, drawing)
        pdf.add_page()
        pen = _Pen(pdf)
        for kind, it, _ in items:
            pen.stroke(it) if kind == "s" else pen.text(it)
        return bytes(pdf.output()), [(0, 0, 0.0, 0.0, W, H)]
    if page not in PAGES:
        raise BolusError(f"page must be 'NONE', 'A4' or 'LETTER', got {page!r}")
    portrait = PAGES[page]
    options = [(portrait, tile_grid(W, H, portrait)), (portrait[::-1], tile_grid(W, H, portrait[::-1]))]
    paper, (rows, cols, cw, ch) = min(options, key=lambda o: (o[1][0] * o[1][1], o[0][0] > o[0][1]))
    sx, sy = cw - TILE_OVERLAP_MM, ch - TILE_OVERLAP_MM
    M = PAGE_MARGIN_MM
    pdf = FPDF(unit="mm", format=paper)
    _setup(pdf, drawing)
    tiles = []
    for r in range(rows):
        for c in range(cols):
            x0, y0 = c * sx, r * sy
            tiles.append((r, c, x0, y0, cw, ch))
            pdf.add_page()
            pen = _Pen(pdf, M - x0, M - y0)
            with pdf.rect_clip(M, M, cw, ch):
                for kind, it, (a0, b0, a1, b1) in items:
                    if a1 >= x0 and a0 <= x0 + cw and b1 >= y0 and b0 <= y0 + ch:
                        pen.stroke(it) if kind == "s" else pen.text(it)
                # registration crosses in the middle of the overlap strips (drawing coordinates)
                xs = [k * sx + TILE_OVERLAP_MM / 2 for k in range(1, cols)]
                ys = [k * sy + TILE_OVERLAP_MM / 2 for k in range(1, rows)]
                for x in xs:
                    for y in [y0 + ch / 4, y0 + 3 * ch / 4] + ys:
                        _cross(pen, x, y)
                for y in ys:
                    for x in [x0 + cw / 4, x0 + 3 * cw / 4]:
                        _cross(pen, x, y)
            _page_frame(pdf, paper, cw, ch, r, c, rows, cols)
    return bytes(pdf.output()), tiles


def _setup(pdf, drawing: Drawing) -> None:
    pdf.set_auto_page_break(False)
    pdf.set_margins(0, 0, 0)
    pdf.set_draw_color(0, 0, 0)
    pdf.set_text_color(0, 0, 0)
    pdf.set_title(_latin1(drawing.title or "Bolus pattern"))
    pdf.set_creator("Bolus add-on")


def _page_frame(pdf, paper, cw: float, ch: float, r: int, c: int, rows: int, cols: int) -> None:
    """Corner marks of the window, the footer's test square, "row r col c" and the print note."""
    M = PAGE_MARGIN_MM
    pen = _Pen(pdf)
    for x, y, ux, uy in ((M, M, 1, 1), (M + cw, M, -1, 1), (M, M + ch, 1, -1), (M + cw, M + ch, -1, -1)):
        pen.stroke(Stroke(np.array([[x + ux * CORNER_MM, y], [x, y], [x, y + uy * CORNER_MM]]), False, "MARKS",
                          "corner", 0.25))
    sq, lab = test_square_strokes(M, M + ch + 6.0)
    pen.stroke(sq)
    pen.text(lab)
    x = M + TEST_SQUARE_MM + 8.0
    pen.text(Text(f"row {r + 1} col {c + 1} of {rows} x {cols}", np.array([x, M + ch + 12.0]), 4.0, "tile",
                  "start", True))
    pen.text(Text(TILE_NOTE, np.array([x, M + ch + 19.0]), 3.0, "tile-note", "start"))
    pen.text(Text("overlap the pages by the crosses (10 mm strips)", np.array([x, M + ch + 25.0]), 3.0,
                  "tile-note", "start"))
