"""One drawing of the cut pattern, in paper millimetres, for the SVG, DXF and PDF writers.

`pattern_drawing` lays the pattern out once:

* per piece its cut outline(s) (closed; outer loops counter-clockwise, holes clockwise,
  as seen from above), the seam allowance (`polygon_offset.offset_polygon`), the label
  ("patch p piece i/k" or the piece's own label, the user's label such as a patient ID,
  EL / EA) placed inside the piece where it fits best, the skin-side mark ("outer side
  up"), the seam and join matching marks (a tick across the outline at the chain's
  middle and its number inside, the same number on both sides) and dart V marks (the
  two legs as dashed lines from the outline to the apex, "dart");
* a footer with the 50 mm test square (a real square, labelled "50 mm", its bottom side
  the ``scale-bar``), the print note, the skin-side note, the title and the label.

Paper coordinates: x right, y DOWN, origin at the top-left corner of a W x H mm page;
pattern (u, v) mm -> paper (u + ox, oy - v): the pattern is seen from above (from
outside the patient: z up = away from the skin).  The writers (`pattern_svg`,
`pattern_dxf`, `pattern_pdf`) only draw what is here; `write_pattern` picks one by the
file's extension and writes atomically.

Also here (re-exported by `pattern_svg`): `outline_loops` / `outline_loop_indices`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..mesh.boundary import boundary_loops
from ..errors import BolusError
from ..unfold.overlap import as_pattern_arrays
from .label_place import (  # noqa: F401  (the label constants stay importable from here)
    LABEL_CENTROIDS, LABEL_FILL, LABEL_GRID, LABEL_KEEP, LABEL_MIN_SCALE, OUTLINE_SAMPLES, label_place)
from .polygon_offset import offset_polygon, signed_area, winding_numbers

__all__ = [
    "Stroke",
    "Text",
    "DrawnPiece",
    "Drawing",
    "pattern_drawing",
    "outline_loops",
    "outline_loop_indices",
    "TEST_SQUARE_MM",
    "PRINT_NOTE",
    "SKIN_NOTE",
    "PAGES",
]

#: the side of the test square the user measures the print with
TEST_SQUARE_MM = 50.0
#: cut lines: thin enough to cut along precisely, thick enough to print on any printer
CUT_STROKE_MM = 0.3
#: the seam allowance is dashed and a little thinner, so it is not taken for a cut line
SEAM_STROKE_MM = 0.2
#: matching marks and dart legs
MARK_STROKE_MM = 0.25
PRINT_NOTE = "print at 100 % (no fit-to-page)"
SKIN_NOTE = "seen from outside: outer side up, skin side down"
MARKS_NOTE = "same number = edges joined; dashed V = dart, close it"
SKIN_MARK = "outer side up"
#: font sizes (mm): the piece label, its user / EL-EA lines, the footer notes, the title, the marks
FONT_LABEL_MM, FONT_METRICS_MM, FONT_NOTE_MM, FONT_TITLE_MM, FONT_MARK_MM = 5.0, 3.5, 3.0, 4.0, 3.5
#: the skin-side mark under a piece's label
FONT_SKIN_MM = 2.5
#: a seam tick reaches this far each side of the outline; its number sits this far inside
TICK_MM, NUMBER_INSET_MM = 2.5, 5.5
#: a label keeps this far (mm, half a square's side) from a mark's number
KEEP_OUT_MM = 3.5
#: a dart's dashed legs are drawn this far inside its opening (so they do not hide under the cut line)
DART_INSET_MM = 1.5
#: text width per character, in font sizes (bold label, regular metrics line; sans-serif)
CHAR_W_BOLD, CHAR_W_REGULAR = 0.62, 0.55
#: paper sizes (mm, portrait) of the tiled PDF; 'NONE' = one page the drawing's size
PAGES = {"A4": (210.0, 297.0), "LETTER": (215.9, 279.4)}
#: layers (the DXF's names; the SVG's classes are their lower-case kinds)
CUT, SEAM_ALLOWANCE, MARKS, LABELS = "CUT", "SEAM_ALLOWANCE", "MARKS", "LABELS"


# --------------------------------------------------------------------------- outlines
def outline_loop_indices(UV, F) -> list[np.ndarray]:
    """Boundary loops of the flat mesh as vertex indices.

    Parameters
    ----------
    UV : (n,2) mm, F : (m,3) int, m >= 1 (`overlap.as_pattern_arrays` checks them;
        zero-area triangles pass: they do not change the outline)

    Returns
    -------
    [(k_i,)] int64 loops from `cutting.boundary_loops`, largest |area| first; outer loops
    counter-clockwise, holes (inside an odd number of other loops) clockwise, whatever
    the triangles' own turning order.  BolusError for a closed surface (no boundary)
    or non-manifold edges.
    """
    UV, F = as_pattern_arrays(UV, F)
    if len(F) == 0:
        raise BolusError("the pattern piece has no triangles")
    loops = boundary_loops(F)
    if not loops:
        raise BolusError("the pattern piece has no boundary (a closed surface cannot be laid flat)")
    area = np.array([signed_area(UV[lp]) for lp in loops])
    order = np.argsort(-np.abs(area), kind="stable")
    loops, area = [loops[i] for i in order], area[order]
    # nesting depth: how many larger loops contain the midpoint of the loop's first edge
    mids = np.array([0.5 * (UV[lp[0]] + UV[lp[1 % len(lp)]]) for lp in loops])
    depth = np.zeros(len(loops), dtype=np.int64)
    for j, lp in enumerate(loops[:-1]):
        P = UV[lp]
        depth[j + 1:] += winding_numbers(mids[j + 1:], P, np.roll(P, -1, axis=0)) != 0
    out = []
    for lp, a, dep in zip(loops, area, depth):
        want_ccw = dep % 2 == 0
        out.append(lp if (a > 0) == want_ccw else np.concatenate([lp[:1], lp[1:][::-1]]))
    return out


def outline_loops(UV, F) -> list[np.ndarray]:
    """Closed boundary loops [(k_i,2)] mm of the flat mesh UV (n,2), F (m,3), first point not repeated.

    Largest |signed area| first; outer loops counter-clockwise, holes clockwise
    (`outline_loop_indices`).
    """
    UV, F = as_pattern_arrays(UV, F)
    return [UV[lp] for lp in outline_loop_indices(UV, F)]


def _seam_loops(loops: list[np.ndarray], d: float) -> list[np.ndarray]:
    """The seam allowance at d > 0 mm around every cut loop: outer loops grow, holes shrink."""
    seams = []
    for L in loops:
        if signed_area(L) > 0:
            seams.append(offset_polygon(L, d))
        else:  # a hole: the allowance goes into it
            S = offset_polygon(L[::-1], -d)
            if len(S):
                seams.append(S[::-1])
    return seams


# --------------------------------------------------------------------------- drawing
@dataclass
class Stroke:
    """A polyline (k,2) in paper mm; ``kind`` e.g. cut, seam, tick, dart, square, bar, cross."""

    points: np.ndarray
    closed: bool
    layer: str
    kind: str
    width: float
    dashed: bool = False


@dataclass
class Text:
    """A text line: ``pos`` (2,) paper mm of its baseline (start or middle by ``anchor``), height ``size`` mm."""

    text: str
    pos: np.ndarray
    size: float
    kind: str
    anchor: str = "middle"
    bold: bool = False
    layer: str = LABELS


@dataclass
class DrawnPiece:
    """One piece: cut loops and seam-allowance loops (Strokes), its label lines, its marks."""

    name: str
    piece: int
    cut: list
    seam: list
    texts: list
    marks: list = field(default_factory=list)
    mark_texts: list = field(default_factory=list)
    pattern_cut: list = field(default_factory=list)  # the cut loops in pattern mm (k,2)


@dataclass
class Drawing:
    """The whole drawing: ``width`` x ``height`` mm; ``content`` (x0, y0, x1, y1) the pieces' box;
    ``square`` (x, y) the test square's top-left corner; ``frame`` {"ox", "oy"} paper = (u + ox, oy - v)."""

    width: float
    height: float
    pieces: list
    strokes: list
    texts: list
    content: tuple
    square: tuple
    frame: dict
    title: str = ""
    label: str = ""
    seam_allowance_mm: float = 0.0

    def paper(self, P) -> np.ndarray:
        P = np.asarray(P, dtype=np.float64).reshape(-1, 2)
        return np.stack([P[:, 0] + self.frame["ox"], self.frame["oy"] - P[:, 1]], axis=1)


def _length(value, name: str) -> float:
    """A length >= 0 mm, else BolusError naming it."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise BolusError(f"the {name} must be a length >= 0 mm, got {value!r}") from None
    if not np.isfinite(v) or v < 0:
        raise BolusError(f"the {name} must be a length >= 0 mm, got {value}")
    return v


def _metrics_text(EL, EA) -> str | None:
    parts = [f"{key} {100 * float(v):.2f} %" for key, v in (("EL", EL), ("EA", EA)) if v is not None]
    return " · ".join(parts) or None


def piece_name(isl: dict, i: int) -> str:
    """"patch p piece i/k" when the piece says which of its patch's pieces it is, else its "label" (or i)."""
    if all(isl.get(k) is not None for k in ("patch", "piece_in_patch", "pieces_in_patch")):
        return f"patch {int(isl['patch'])} piece {int(isl['piece_in_patch'])}/{int(isl['pieces_in_patch'])}"
    return str(isl.get("label", i))


def _text_w(text: str, size: float, bold: bool = False) -> float:
    return (CHAR_W_BOLD if bold else CHAR_W_REGULAR) * size * len(text)


def _piece(i: int, isl: dict, d: float, label: str):
    """(UV, F, cut loops, seam loops, label lines [(text, size, bold, kind)], piece id) of one piece."""
    try:
        UV, F = as_pattern_arrays(isl["UV"], isl["F"])
    except KeyError as exc:
        raise BolusError(f"pattern piece {i} has no {exc.args[0]!r} array") from None
    except TypeError:
        raise BolusError(f"pattern piece {i} is not a dict with 'UV' and 'F' arrays") from None
    loops = outline_loops(UV, F)
    seams = _seam_loops(loops, d) if d > 0 else []
    lines = [(piece_name(isl, i), FONT_LABEL_MM, True, "label")]
    if label:
        lines.append((label, FONT_METRICS_MM, True, "user-label"))
    metrics = _metrics_text(isl.get("EL"), isl.get("EA"))
    if metrics:
        lines.append((metrics, FONT_METRICS_MM, False, "metrics"))
    lines.append((SKIN_MARK, FONT_SKIN_MM, False, "skin-side"))
    pid = isl.get("piece", i)
    return UV, F, loops, seams, lines, int(pid) if pid is not None else i


def _label_block(P: "Drawing", UV, F, loops, lines, keep_out=()) -> list:
    """Texts of the label lines as one block centred where it fits best inside the piece,
    away from the points ``keep_out`` [(2,)] (pattern mm: the marks' numbers)."""
    sizes = np.array([s for _, s, _, _ in lines])
    text_w = max(_text_w(t, s, b) for t, s, b, _ in lines)
    text_h = float((1.3 * sizes).sum())
    r = KEEP_OUT_MM
    square_cw = np.array([[-r, -r], [-r, r], [r, r], [r, -r]])
    c, k = label_place(UV, F, loops, text_w, text_h, [p + square_cw for p in keep_out])
    c = P.paper(c)[0]
    out, y = [], c[1] - k * text_h / 2
    for t, s, b, kind in lines:
        y += k * 1.3 * s
        out.append(Text(t, np.array([c[0], y - 0.3 * k * s]), s * k, kind, "middle", b))
    return out


def _seam_marks(P: "Drawing", mid, normal, number: int):
    """A tick across the outline at ``mid`` (pattern mm) along the inward ``normal``, the number inside."""
    m, n = P.paper(mid)[0], np.array([normal[0], -normal[1]])
    tick = Stroke(np.array([m - TICK_MM * n, m + TICK_MM * n]), False, MARKS, "tick", MARK_STROKE_MM)
    c = m + NUMBER_INSET_MM * n
    return tick, Text(str(number), np.array([c[0], c[1] + 0.35 * FONT_MARK_MM]), FONT_MARK_MM, "seam-number",
                      "middle", True, MARKS)


def _dart_marks(P: "Drawing", UV, dart):
    """The dart's two legs as dashed lines from the outline to the apex, `DART_INSET_MM` inside
    the V's opening (on the cut line they would hide under it), "dart" inside the V."""
    apex = UV[dart.apex]
    a, b = UV[dart.leg_a[0]], UV[dart.leg_b[0]]
    ua, ub = a - apex, b - apex
    la, lb = float(np.linalg.norm(ua)), float(np.linalg.norm(ub))
    ends, tip = [a, b], apex
    if la > 0 and lb > 0:
        ua, ub = ua / la, ub / lb
        bis = ua + ub
        sin_half = 0.5 * float(np.linalg.norm(ua - ub))
        if np.linalg.norm(bis) > 1e-9 and sin_half > 0 and DART_INSET_MM / sin_half < 0.5 * min(la, lb):
            bis /= np.linalg.norm(bis)
            tip = apex + bis * DART_INSET_MM / sin_half  # on the bisector, DART_INSET_MM from both legs
            ends = [e + (tip - apex) for e in (a, b)]
    legs = [Stroke(P.paper(np.array([e, tip])), False, MARKS, "dart", MARK_STROKE_MM, True) for e in ends]
    c = P.paper((a + b + apex) / 3)[0]
    return legs, Text("dart", np.array([c[0], c[1] + 0.35 * FONT_MARK_MM]), FONT_MARK_MM, "dart-label",
                      "middle", False, MARKS)


def _one_line(text) -> str:
    """The text on one line: control characters (newlines, tabs) become spaces, ends stripped."""
    return "".join(" " if ord(ch) < 32 or ord(ch) == 127 else ch for ch in str(text or "")).strip()


def _marks_uv(marks) -> np.ndarray:
    """(n,2) finite positions the marks index; BolusError when missing or too short for their ids."""
    if marks.UV is None:
        raise BolusError("the pattern marks carry no positions (PatternMarks.UV): make them with pattern_marks")
    UVm = np.asarray(marks.UV, dtype=np.float64)
    ids = [np.asarray(c) for s in marks.seams for c in (s.chain_a, s.chain_b)]
    ids += [np.asarray(c) for dm in marks.darts for c in (dm.leg_a, dm.leg_b)]
    top = max(int(c.max()) for c in ids)
    if UVm.ndim != 2 or UVm.shape[1] != 2 or top >= len(UVm) or min(int(c.min()) for c in ids) < 0:
        raise BolusError(f"the pattern marks index vertex {top} of {len(UVm)} positions: they belong to "
                         "another pattern")
    if not np.isfinite(UVm).all():
        raise BolusError("the pattern marks' positions are not finite (NaN or infinite)")
    return UVm


def _content_box(raw, marks, has_marks: bool):
    """(lo (2,), hi (2,), UVm) of the pattern mm box around every piece's loops and the marks'
    chains (plus room for the ticks); UVm the marks' positions (`_marks_uv`) or None."""
    allpts = np.concatenate([np.concatenate(r[2] + r[3]) for r in raw])
    UVm = None
    if has_marks:
        UVm = _marks_uv(marks)
        ids = [s.chain_a for s in marks.seams] + [s.chain_b for s in marks.seams]
        ids += [np.r_[dm.leg_a, dm.leg_b] for dm in marks.darts]
        allpts = np.concatenate([allpts, UVm[np.concatenate(ids)]])
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    if has_marks:
        lo, hi = lo - TICK_MM, hi + TICK_MM  # room for the ticks
    return lo, hi, UVm


def _footer_notes(has_marks: bool, title: str, label: str) -> list:
    """The footer's text lines [(text, size mm, kind)]: print, skin side, marks, title, label."""
    notes = [(PRINT_NOTE, FONT_NOTE_MM, "print-note"), (SKIN_NOTE, FONT_NOTE_MM, "skin-note")]
    if has_marks:
        notes.append((MARKS_NOTE, FONT_NOTE_MM, "marks-note"))
    if title:
        notes.append((title, FONT_TITLE_MM, "pattern-title"))
    if label:
        notes.append((label, FONT_TITLE_MM, "pattern-label"))
    return notes


def _draw_pieces(P: Drawing, raw, marks) -> dict:
    """Every piece's cut and seam-allowance strokes and its label block (kept off the seam
    numbers) into ``P.pieces``; returns {piece id: its first `DrawnPiece`}."""
    keep_out: dict[int, list] = {}
    if marks is not None:
        for s in marks.seams:
            for pid, mid, nrm in ((s.piece_a, s.mid_a, s.normal_a), (s.piece_b, s.mid_b, s.normal_b)):
                keep_out.setdefault(int(pid), []).append(np.asarray(mid) + NUMBER_INSET_MM * np.asarray(nrm))
    by_id = {}
    for UV, F, loops, seams, lines, pid in raw:
        dp = DrawnPiece(lines[0][0], pid,
                        [Stroke(P.paper(L), True, CUT, "cut", CUT_STROKE_MM) for L in loops],
                        [Stroke(P.paper(S), True, SEAM_ALLOWANCE, "seam", SEAM_STROKE_MM, True) for S in seams],
                        _label_block(P, UV, F, loops, lines, keep_out.get(pid, [])), pattern_cut=loops)
        P.pieces.append(dp)
        by_id.setdefault(pid, dp)
    return by_id


def _draw_marks(P: Drawing, marks, UVm, by_id: dict) -> None:
    """Seam ticks with their numbers and dart legs onto their pieces (a mark of a piece not
    drawn goes onto the page itself)."""
    for s in marks.seams:
        for pid, mid, nrm in ((s.piece_a, s.mid_a, s.normal_a), (s.piece_b, s.mid_b, s.normal_b)):
            tick, num = _seam_marks(P, mid, nrm, s.number)
            dp = by_id.get(int(pid))
            (dp.marks if dp else P.strokes).append(tick)
            (dp.mark_texts if dp else P.texts).append(num)
    for dm in marks.darts:
        legs, txt = _dart_marks(P, UVm, dm)
        dp = by_id.get(int(dm.piece))
        (dp.marks if dp else P.strokes).extend(legs)
        (dp.mark_texts if dp else P.texts).append(txt)


def pattern_drawing(pieces, marks=None, *, label: str = "", title: str = "", seam_allowance_mm: float = 0.0,
                    margin_mm: float = 10.0, decimals: int = 3) -> Drawing:
    """Lay the pattern out once, in paper mm.

    Parameters
    ----------
    pieces : [{"UV": (n,2) mm, "F": (m,3), "label", "EL", "EA", "piece", "patch", "piece_in_patch",
        "pieces_in_patch"}] already laid out (pattern coordinates); a piece is named
        "patch p piece i/k" when it has the last three, else by its "label"
    marks : `pattern_marks.PatternMarks` of the same pattern (its UV in the same coordinates),
        or None; a mark goes to the piece whose "piece" matches (else it is drawn on its own)
    label : the user's label (e.g. a patient ID), printed on every piece and in the footer
    seam_allowance_mm, margin_mm : lengths >= 0 (BolusError otherwise)
    decimals : the page frame is rounded to this many decimals

    Returns
    -------
    Drawing: the page is ``margin_mm`` around the pattern plus a footer with the test
    square and the notes.
    """
    if pieces is None or not len(pieces):
        raise BolusError("there is no pattern piece to export")
    d = _length(seam_allowance_mm, "seam allowance")
    m = _length(margin_mm, "margin")
    label, title = _one_line(label), _one_line(title)
    raw = [_piece(i, isl, d, label) for i, isl in enumerate(pieces)]
    has_marks = marks is not None and bool(marks.seams or marks.darts)
    lo, hi, UVm = _content_box(raw, marks, has_marks)
    content_w, content_h = hi - lo
    ox, oy = round(m - lo[0], decimals), round(m + hi[1], decimals)
    y_sq = m + content_h + 8.0
    notes = _footer_notes(has_marks, title, label)
    x_notes = m + TEST_SQUARE_MM + 8.0
    notes_w = max(_text_w(t, s) for t, s, _ in notes)
    W = max(content_w + 2 * m, x_notes + notes_w + m)
    H = max(y_sq + TEST_SQUARE_MM, y_sq + 7.0 * len(notes)) + m
    P = Drawing(W, H, [], [], [], (m, m, m + content_w, m + content_h), (m, y_sq), {"ox": ox, "oy": oy},
                title, label, d)
    by_id = _draw_pieces(P, raw, marks)
    if has_marks:
        _draw_marks(P, marks, UVm, by_id)
    # footer: the test square (its bottom side is the scale bar), its label, the notes
    square, square_label = test_square_strokes(m, y_sq)
    P.strokes.append(square)
    P.strokes.append(Stroke(square.points[[3, 2]], False, MARKS, "bar", MARK_STROKE_MM))
    P.texts.append(square_label)
    y = y_sq + 4.0
    for t, size, kind in notes:
        P.texts.append(Text(t, np.array([x_notes, y]), size, kind, "start"))
        y += 7.0
    return P


def test_square_strokes(x: float, y: float, size: float = TEST_SQUARE_MM) -> tuple[Stroke, Text]:
    """A test square with its top-left corner at paper (x, y) and its "50 mm" label (for page footers)."""
    sq = np.array([[x, y], [x + size, y], [x + size, y + size], [x, y + size]])
    return (Stroke(sq, True, MARKS, "square", MARK_STROKE_MM),
            Text(f"{size:g} mm", np.array([x + size / 2, y + size / 2 + 0.35 * FONT_METRICS_MM]), FONT_METRICS_MM,
                 "square-label"))


test_square_strokes.__test__ = False  # not a pytest test
