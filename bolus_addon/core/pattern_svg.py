"""The flat pattern as an SVG at true scale (1 mm on the pattern = 1 mm on paper).

* `outline_loops` / `outline_loop_indices` - the closed boundary loops of a flat
  triangle mesh (`cutting.boundary_loops`, the one walker), oriented for cutting:
  outer loops counter-clockwise, holes clockwise, largest first.
* `pattern_svg` - the document: width and height in mm with a viewBox in mm, the
  pattern seen from above (+y up on paper), one ``<g id="patch-<label>">`` per island
  with its cut lines, optional dashed seam allowance (`polygon_offset.offset_polygon`)
  and a label, a 50 mm scale bar.
* `svg_outline_paths` - the cut lines read back into pattern millimetres.

`offset_polygon` and `signed_area` live in `polygon_offset` and are re-exported here.
"""
from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np
from scipy.spatial import cKDTree

from .cutting import boundary_loops
from .errors import BolusError
from .overlap import as_pattern_arrays
from .polygon_offset import offset_polygon, signed_area, winding_numbers

__all__ = [
    "outline_loops",
    "outline_loop_indices",
    "offset_polygon",
    "signed_area",
    "pattern_svg",
    "svg_outline_paths",
    "SCALE_BAR_MM",
]

SVG_NS = "http://www.w3.org/2000/svg"
#: the length of the scale bar the user checks the print with
SCALE_BAR_MM = 50.0
#: cut lines: thin enough to cut along precisely, thick enough to print on any printer
CUT_STROKE_MM = 0.3
#: the seam allowance is dashed and a little thinner, so it is not taken for a cut line
SEAM_STROKE_MM = 0.2
PRINT_NOTE = "print at 100 % (no fit-to-page)"
#: font sizes (mm): the patch label, its EL / EA line, the print note, the title
FONT_LABEL_MM, FONT_METRICS_MM, FONT_NOTE_MM, FONT_TITLE_MM = 5.0, 3.5, 3.0, 4.0
#: a label never shrinks below this share of its size to fit a small piece
LABEL_MIN_SCALE = 0.4
#: label candidates: a LABEL_GRID x LABEL_GRID grid over the piece, and at most this many centroids
LABEL_GRID, LABEL_CENTROIDS = 40, 2000
#: the outline is sampled this finely (a share of its length) to measure the room around a label
OUTLINE_SAMPLES = 5000
#: label candidates kept: this many farthest from the outline and as many near the centre and roomy
LABEL_KEEP = 60
#: a label fills at most this share of the free room around it
LABEL_FILL = 0.9
#: text width per character, in font sizes (bold label, regular metrics line; sans-serif)
CHAR_W_BOLD, CHAR_W_REGULAR = 0.62, 0.55


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


# --------------------------------------------------------------------------- labels
def _centroid(P: np.ndarray) -> np.ndarray:
    """Area centroid (2,) of the closed polygon P (k,2) (its mean for a polygon without area)."""
    X = P - P.mean(axis=0)
    cr = X[:, 0] * np.roll(X[:, 1], -1) - np.roll(X[:, 0], -1) * X[:, 1]
    a = cr.sum() / 2
    if abs(a) <= 1e-12:
        return P.mean(axis=0)
    return P.mean(axis=0) + ((X + np.roll(X, -1, axis=0)) * cr[:, None]).sum(0) / (6 * a)


def _label_candidates(UV, F, A, B, centre):
    """Points (c,2) inside the piece where a label may go (grid points and triangle centroids,
    the most roomy and the nearest the centre kept), with their distances to the centre (c,)."""
    lo, hi = A.min(axis=0), A.max(axis=0)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], LABEL_GRID + 2)[1:-1],
                         np.linspace(lo[1], hi[1], LABEL_GRID + 2)[1:-1])
    grid_pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    grid_pts = grid_pts[winding_numbers(grid_pts, A, B) == 1]
    cand = np.concatenate([UV[F].mean(axis=1)[:: max(1, len(F) // LABEL_CENTROIDS)], grid_pts])
    length = np.linalg.norm(B - A, axis=1)
    step = max(length.sum() / OUTLINE_SAMPLES, 1e-6)
    k = np.maximum(1, np.ceil(length / step).astype(np.int64))
    seg = np.repeat(np.arange(len(A)), k)
    t = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) / np.repeat(k, k)
    dist = cKDTree(A[seg] + t[:, None] * (B - A)[seg]).query(cand)[0]
    off = np.linalg.norm(cand - centre, axis=1)
    pick = np.unique(np.concatenate([np.argsort(-dist)[:LABEL_KEEP], np.argsort(off - 3 * dist)[:LABEL_KEEP]]))
    return cand[pick], off[pick]


def _free_room(cand, A, B, axis: int) -> np.ndarray:
    """(c,) free length through each candidate (c,2) along ``axis``, centred on it, inside the outline A -> B."""
    o = 1 - axis
    lo_, hi_ = np.minimum(A[:, o], B[:, o]), np.maximum(A[:, o], B[:, o])
    q = cand[:, None, :]
    hit = (lo_ <= q[..., o]) & (hi_ > q[..., o])
    with np.errstate(divide="ignore", invalid="ignore"):
        x = A[:, axis] + (q[..., o] - A[:, o]) / (B[:, o] - A[:, o]) * (B[:, axis] - A[:, axis])
    rel = np.where(hit, x - q[..., axis], np.nan)
    before = np.nanmin(np.where(rel < 0, -rel, np.inf), axis=1)
    after = np.nanmin(np.where(rel > 0, rel, np.inf), axis=1)
    return 2 * np.minimum(before, after)


def _label_place(UV: np.ndarray, F: np.ndarray, loops: list[np.ndarray], text_w: float, text_h: float):
    """Where to put a text block of text_w x text_h mm on the island: ``(point (2,), scale)``.

    Among the candidates where the text fits best (scale 1 if it fits, else shrunk to
    the room left and right, above and below the point, never below `LABEL_MIN_SCALE`)
    the one nearest the outer loop's centroid is taken.
    """
    A = np.concatenate(loops)
    B = np.concatenate([np.roll(L, -1, axis=0) for L in loops])
    cand, off = _label_candidates(UV, F, A, B, _centroid(loops[0]))
    fit = np.minimum(1.0, np.minimum(LABEL_FILL * _free_room(cand, A, B, 0) / max(text_w, 1e-9),
                                     LABEL_FILL * _free_room(cand, A, B, 1) / max(text_h, 1e-9)))
    best = np.flatnonzero(fit >= fit.max() * (1 - 1e-9))
    i = best[np.argmin(off[best])]
    return cand[i], float(np.clip(fit[i], LABEL_MIN_SCALE, 1.0))


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


def _metrics_text(EL, EA) -> str | None:
    parts = [f"{key} {100 * float(v):.2f} %" for key, v in (("EL", EL), ("EA", EA)) if v is not None]
    return " · ".join(parts) or None


def _length(value, name: str) -> float:
    """A length >= 0 mm, else BolusError naming it."""
    v = float(value)
    if not np.isfinite(v) or v < 0:
        raise BolusError(f"the {name} must be a length >= 0 mm, got {value}")
    return v


def _pieces(islands, d: float) -> list[tuple]:
    """Every island as (UV, F, cut loops, seam loops, label, metrics text)."""
    pieces = []
    for i, isl in enumerate(islands):
        try:
            UV, F = as_pattern_arrays(isl["UV"], isl["F"])
        except KeyError as exc:
            raise BolusError(f"pattern piece {i} has no {exc.args[0]!r} array") from None
        loops = outline_loops(UV, F)
        seams = _seam_loops(loops, d) if d > 0 else []
        pieces.append((UV, F, loops, seams, str(isl.get("label", i)), _metrics_text(isl.get("EL"), isl.get("EA"))))
    return pieces


class _Page:
    """The page: pattern (x, y) mm -> paper (x + ox, oy - y), its size W x H mm, the footer rows."""

    def __init__(self, pieces, m: float, title: str, decimals: int):
        allpts = np.concatenate([np.concatenate(p[2] + p[3]) for p in pieces])
        lo, hi = allpts.min(axis=0), allpts.max(axis=0)
        self.m = m
        self.ox, self.oy = round(m - lo[0], decimals), round(m + hi[1], decimals)
        content_w, content_h = hi - lo
        self.y_bar = m + content_h + 10.0
        self.y_note = self.y_bar + 7.0
        self.y_title = self.y_note + 6.0
        footer_w = max(SCALE_BAR_MM + 15.0, 0.6 * FONT_NOTE_MM * len(PRINT_NOTE), 0.6 * FONT_TITLE_MM * len(title))
        self.W = max(content_w + 2 * m, footer_w + 2 * m)
        self.H = (self.y_title if title else self.y_note) + m

    def paper(self, P) -> np.ndarray:
        P = np.asarray(P, dtype=np.float64)
        return np.stack([P[:, 0] + self.ox, self.oy - P[:, 1]], axis=1)


def _write_piece(g_all, piece, page: _Page, f, path_decimals: int, taken: set) -> None:
    """One ``<g class="patch">``: cut paths, dashed seam paths, the label and its metrics line."""
    UV, F, loops, seams, label, metrics = piece
    g = ET.SubElement(g_all, "g", {"id": _safe_id(label, taken), "class": "patch"})
    for L in loops:
        ET.SubElement(g, "path", {
            "class": "cut", "d": _path_d(page.paper(L), path_decimals), "fill": "none", "stroke": "#000000",
            "stroke-width": f(CUT_STROKE_MM), "stroke-linejoin": "round"})
    for S in seams:
        ET.SubElement(g, "path", {
            "class": "seam", "d": _path_d(page.paper(S), path_decimals), "fill": "none", "stroke": "#000000",
            "stroke-width": f(SEAM_STROKE_MM), "stroke-dasharray": "2 1"})
    text_w = max(CHAR_W_BOLD * FONT_LABEL_MM * len(label), CHAR_W_REGULAR * FONT_METRICS_MM * len(metrics or ""))
    c, k = _label_place(UV, F, loops, text_w, 10.0 if metrics else 5.0)
    c = page.paper(c[None])[0]
    common = {"text-anchor": "middle", "font-family": "sans-serif", "fill": "#000000"}
    ET.SubElement(g, "text", {"class": "label", "x": f(c[0]), "y": f(c[1] - (0.5 if metrics else -1.8) * k),
                              "font-size": f(FONT_LABEL_MM * k), "font-weight": "bold", **common}).text = label
    if metrics:
        ET.SubElement(g, "text", {"class": "metrics", "x": f(c[0]), "y": f(c[1] + 4.0 * k),
                                  "font-size": f(FONT_METRICS_MM * k), **common}).text = metrics


def _write_footer(root, page: _Page, f, title: str) -> None:
    """The 50 mm scale bar with its ticks and label, the print note and the title."""
    g = ET.SubElement(root, "g", {"id": "scale"})
    x0, x1, y = page.m, page.m + SCALE_BAR_MM, page.y_bar
    ET.SubElement(g, "line", {"id": "scale-bar", "x1": f(x0), "y1": f(y), "x2": f(x1), "y2": f(y),
                              "stroke": "#000000", "stroke-width": "0.5"})
    for x in (x0, x1):
        ET.SubElement(g, "line", {"class": "tick", "x1": f(x), "y1": f(y - 1.5), "x2": f(x),
                                  "y2": f(y + 1.5), "stroke": "#000000", "stroke-width": "0.3"})
    text = {"font-family": "sans-serif", "fill": "#000000"}
    ET.SubElement(g, "text", {"id": "scale-label", "x": f(x1 + 3.0), "y": f(y + 1.2),
                              "font-size": f(FONT_METRICS_MM), **text}).text = f"{SCALE_BAR_MM:g} mm"
    ET.SubElement(g, "text", {"id": "print-note", "x": f(x0), "y": f(page.y_note),
                              "font-size": f(FONT_NOTE_MM), **text}).text = PRINT_NOTE
    if title:
        ET.SubElement(g, "text", {"id": "pattern-title", "x": f(x0), "y": f(page.y_title),
                                  "font-size": f(FONT_TITLE_MM), **text}).text = title


def pattern_svg(islands, seam_allowance_mm: float = 0.0, title: str = "", margin_mm: float = 10.0,
                decimals: int = 3, path_decimals: int = 5) -> str:
    """SVG document (str) of laid-out islands at true scale.

    Parameters
    ----------
    islands : [{"UV": (n,2) mm, "F": (m,3), "label": str, "EL": float, "EA": float}] in
        pattern coordinates (already laid out); EL and EA are ratios (0.0123 is shown as
        "EL 1.23 %"), either may be missing
    seam_allowance_mm, margin_mm : lengths >= 0 (BolusError otherwise)
    decimals, path_decimals : decimals of numbers and of outline coordinates: rounding
        every corner of a ragged 250-corner outline to 1 um changes its perimeter by up
        to about 0.02 mm, to 0.01 um by about 1e-4 mm

    Returns
    -------
    The document: the page is ``margin_mm`` around the pattern plus a footer with the
    50 mm scale bar; width and height in mm, viewBox in mm, +y of the pattern up on paper.
    """
    if not len(islands):
        raise BolusError("there is no pattern piece to export")
    d = _length(seam_allowance_mm, "seam allowance")
    pieces = _pieces(islands, d)
    page = _Page(pieces, _length(margin_mm, "margin"), title, decimals)
    f = lambda v: _fmt(v, decimals)  # noqa: E731
    root = ET.Element("svg", {
        "xmlns": SVG_NS, "version": "1.1",
        "width": f"{f(page.W)}mm", "height": f"{f(page.H)}mm", "viewBox": f"0 0 {f(page.W)} {f(page.H)}",
    })
    ET.SubElement(root, "title").text = title or "Bolus pattern"
    ET.SubElement(root, "desc").text = (
        "Bolus pattern at true scale: 1 user unit = 1 mm. Solid lines are cut lines, dashed lines the "
        f"seam allowance. {PRINT_NOTE[0].upper() + PRINT_NOTE[1:]}.")
    ET.SubElement(root, "metadata", {"id": "bolus-frame"}).text = json.dumps(
        {"units": "mm", "paper_x": "x + ox", "paper_y": "oy - y", "ox": page.ox, "oy": page.oy,
         "seam_allowance_mm": d})
    g_all = ET.SubElement(root, "g", {"id": "patches"})
    taken: set = set()
    for piece in pieces:
        _write_piece(g_all, piece, page, f, path_decimals, taken)
    _write_footer(root, page, f, title)
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


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
