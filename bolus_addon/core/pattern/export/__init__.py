"""The pattern file writers, picked by the file's extension from one table.

`WRITERS` maps an extension to a writer ``(drawing, page) -> (bytes, tiles)``; each writer
module imports the drawing (`pattern_drawing.Drawing`), never the other way round.
`write_pattern` lays the pattern out once and writes it atomically.
"""
from __future__ import annotations

import os

from ...errors import BolusError
from ...files import write_atomic
from ..drawing import PAGES, pattern_drawing
from .dxf import drawing_dxf
from .pdf import drawing_pdf
from .svg import drawing_svg

__all__ = ["WRITERS", "FORMATS", "write_pattern", "write_atomic"]


def _svg(drawing, page):
    return drawing_svg(drawing).encode("utf-8"), None


def _dxf(drawing, page):
    return drawing_dxf(drawing), None


#: extension -> writer (drawing, page) -> (file bytes, PDF tiles or None); SVG and DXF are one sheet in mm
WRITERS = {".svg": _svg, ".dxf": _dxf, ".pdf": drawing_pdf}
FORMATS = tuple(WRITERS)


def _target(path) -> tuple[str, str]:
    """(absolute path, extension); BolusError for no path, an unknown extension or a missing folder."""
    if not path:
        raise BolusError("choose a file to write the pattern to")
    path = os.path.abspath(os.fspath(path))
    ext = os.path.splitext(path)[1].lower()
    if ext not in WRITERS:
        raise BolusError(f"the pattern file must end in .svg, .dxf or .pdf, got '{os.path.basename(path)}'")
    folder = os.path.dirname(path)
    if not os.path.isdir(folder):
        raise BolusError(f"cannot write '{path}': the folder '{folder}' does not exist")
    if os.path.isdir(path):
        raise BolusError(f"cannot write '{path}': it is a folder")
    return path, ext


def write_pattern(path, pieces, marks=None, *, page: str = "NONE", label: str = "", title: str = "",
                  seam_allowance_mm: float = 0.0) -> dict:
    """Write the pattern as SVG, DXF or PDF (by the extension of ``path``), atomically.

    path: the file (.svg / .dxf / .pdf; anything else: BolusError naming the three);
    pieces, marks, label, title, seam_allowance_mm: as `pattern_drawing`;
    page: 'NONE' | 'A4' | 'LETTER', the PDF's paper: 'NONE' one page the size of the drawing,
    A4 / Letter tiled with overlap and alignment marks (`pattern_pdf`).

    Returns {"path", "format", "pages", "pieces", "seams", "darts", "width_mm", "height_mm"} and,
    for a PDF, "tiles": [(row, col, x0, y0, w, h)] the drawing's window (paper mm) on every page.
    Nothing is written (and no temporary file left) when anything fails.
    """
    page = str(page or "NONE").upper()
    if page not in ("NONE", *PAGES):
        raise BolusError(f"page must be 'NONE', 'A4' or 'LETTER', got {page!r}")
    path, ext = _target(path)
    drawing = pattern_drawing(pieces, marks, label=label, title=title, seam_allowance_mm=seam_allowance_mm)
    info = {"path": path, "format": ext[1:], "pages": 1, "pieces": len(drawing.pieces),
            "seams": len(marks.seams) if marks is not None else 0,
            "darts": len(marks.darts) if marks is not None else 0,
            "width_mm": drawing.width, "height_mm": drawing.height}
    data, tiles = WRITERS[ext](drawing, page)
    if tiles is not None:
        info["pages"], info["tiles"] = len(tiles), tiles
    write_atomic(path, data)
    return info
