"""Cutter-ready pattern export: one drawing, written as SVG, DXF and PDF."""
import os
from pathlib import Path
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from meshgen import degenerate_variants, grid
from test_core_pattern_marks import cone_pattern, explode
from test_core_pattern_svg import perimeter, three_islands

from bolus_addon.core import files
from bolus_addon.core.pattern import drawing as pdraw
from bolus_addon.core.errors import BolusError
from bolus_addon.core.pattern.drawing import TEST_SQUARE_MM, pattern_drawing
from bolus_addon.core.pattern.export import write_pattern
from bolus_addon.core.pattern.marks import pattern_marks
from bolus_addon.core.pattern.export.pdf import FOOTER_MM, PAGE_MARGIN_MM, TILE_OVERLAP_MM
from bolus_addon.core.pattern.export.svg import signed_area, svg_outline_paths

ezdxf = pytest.importorskip("ezdxf")
pdfium = pytest.importorskip("pypdfium2")
NS = {"svg": "http://www.w3.org/2000/svg"}
DPI = 300.0
PX_MM = DPI / 25.4
LABEL = "ID 4711-B"


def marked_pattern():
    """Pieces and marks: a strip cut in two (one seam), a cone sector with its dart."""
    V, F = grid(4, 2, 60.0)
    V2 = V[:, :2] * [1.0, 0.5]
    UV, Fp, piece, sv = explode(V2, F, (V2[F].mean(axis=1)[:, 0] > 30).astype(int))
    UVc, Fc, pc, svc, _ = cone_pattern()
    UV = np.r_[UV, UVc + [140.0, 20.0]]
    Fall = np.r_[Fp, Fc + len(UV) - len(UVc)]
    piece = np.r_[piece, pc + 2]
    marks = pattern_marks(UV, Fall, piece, np.r_[sv, svc + sv.max() + 1])
    pieces = []
    for p in range(3):
        tri = np.flatnonzero(piece == p)
        verts, local = np.unique(Fall[tri], return_inverse=True)
        pieces.append({"UV": UV[verts], "F": local.reshape(-1, 3), "piece": p, "patch": 0 if p < 2 else 1,
                       "piece_in_patch": p + 1 if p < 2 else 1, "pieces_in_patch": 2 if p < 2 else 1,
                       "EL": 0.01, "EA": 0.02})
    return pieces, marks


def dxf_doc(path):
    return ezdxf.readfile(str(path))


def render(path):
    """Every page of the PDF as a (h, w) bool array of dark pixels at DPI, and its size in mm."""
    doc = pdfium.PdfDocument(str(path))
    out = []
    for page in doc:
        w_pt, h_pt = page.get_size()
        img = page.render(scale=DPI / 72.0).to_numpy()
        dark = img[..., :3].mean(axis=2) < 128
        out.append((dark, (w_pt / 72 * 25.4, h_pt / 72 * 25.4), page.get_textpage().get_text_range()))
    return out


def render_pdftoppm(path, tmp_path):
    """Every page rendered by poppler's pdftoppm (when installed) as dark-pixel arrays at DPI."""
    subprocess.run(["pdftoppm", "-gray", "-r", str(int(DPI)), str(path), str(tmp_path / "pg")], check=True)
    out = []
    for f in sorted(tmp_path.glob("pg*.pgm")):
        data = f.read_bytes()
        magic, w, h, maxval, rest = data.split(maxsplit=4)
        assert magic == b"P5" and int(maxval) == 255
        img = np.frombuffer(rest[: int(w) * int(h)], dtype=np.uint8).reshape(int(h), int(w))
        out.append(img < 128)
    return out


def measure_square(dark, x0_mm, y0_mm, size_mm=70.0):
    """Side lengths (mm, centre to centre of the strokes) of the square in the window (x0, y0, size)."""
    a, b = int(x0_mm * PX_MM), int(y0_mm * PX_MM)
    win = dark[max(b, 0):b + int(size_mm * PX_MM), max(a, 0):a + int(size_mm * PX_MM)]
    long_ = 40.0 * PX_MM  # a side of the square: a dark run of more than 40 mm; no text is that long

    def sides(counts):
        idx = np.flatnonzero(counts > long_)
        assert len(idx), "no square side found"
        groups = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
        assert len(groups) == 2, f"expected two parallel sides, found {len(groups)}"
        return (groups[1].mean() - groups[0].mean()) / PX_MM

    return sides(win.sum(axis=0)), sides(win.sum(axis=1))


# ------------------------------------------------------------------ DXF
def test_dxf_is_in_mm_with_one_closed_polyline_per_outline_and_svg_perimeters(tmp_path):
    islands = three_islands()
    info = write_pattern(tmp_path / "p.dxf", islands, label=LABEL, seam_allowance_mm=3.0, title="face")
    assert info["format"] == "dxf" and info["pieces"] == 4
    doc = dxf_doc(tmp_path / "p.dxf")
    assert doc.header["$INSUNITS"] == 4 and doc.header["$MEASUREMENT"] == 1 and doc.units == 4
    auditor = doc.audit()
    assert not auditor.has_errors, [str(e) for e in auditor.errors]
    assert {"CUT", "SEAM_ALLOWANCE", "MARKS", "LABELS"} <= {layer.dxf.name for layer in doc.layers}
    msp = doc.modelspace()
    cut = msp.query('LWPOLYLINE[layer=="CUT"]')
    seam = msp.query('LWPOLYLINE[layer=="SEAM_ALLOWANCE"]')
    assert len(cut) == len(seam) == 5 and all(p.closed for p in cut) and all(p.closed for p in seam)
    write_pattern(tmp_path / "p.svg", islands, label=LABEL, seam_allowance_mm=3.0, title="face")
    svg_loops = svg_outline_paths((tmp_path / "p.svg").read_text())
    dxf_loops = [np.array(p.get_points("xy")) for p in cut]
    assert len(svg_loops) == len(dxf_loops) == 5
    for P, Q in zip(svg_loops, dxf_loops):
        assert len(P) == len(Q)
        assert abs(perimeter(P) - perimeter(Q)) < 0.01
    # the same shapes: the DXF is the paper drawing with y up, a shift of the pattern frame
    shift = dxf_loops[0].mean(axis=0) - svg_loops[0].mean(axis=0)
    for P, Q in zip(svg_loops, dxf_loops):
        np.testing.assert_allclose(Q - shift, P, atol=1e-4)
    texts = [t.dxf.text for t in msp.query("TEXT")]
    assert all(t.dxf.layer == "LABELS" for t in msp.query("TEXT"))
    assert texts.count(LABEL) >= 4 and "50 mm" in texts and "nose tip" in texts
    sq = msp.query('LWPOLYLINE[layer=="MARKS"]')
    sides = [np.ptp(np.array(p.get_points("xy")), axis=0) for p in sq if p.closed]
    assert any(np.allclose(s, [TEST_SQUARE_MM, TEST_SQUARE_MM]) for s in sides)
    assert all(t.dxf.height > 0 for t in msp.query("TEXT"))


def test_marks_in_all_three_formats(tmp_path):
    pieces, marks = marked_pattern()
    assert len(marks.seams) == 1 and len(marks.darts) == 1
    for ext in ("svg", "dxf", "pdf"):
        info = write_pattern(tmp_path / f"m.{ext}", pieces, marks, label=LABEL)
        assert (info["seams"], info["darts"], info["pieces"]) == (1, 1, 3)
    root = ET.fromstring((tmp_path / "m.svg").read_text())
    groups = root.findall(".//svg:g[@class='patch']", NS)
    assert [g.get("id") for g in groups] == ["patch-patch_0_piece_1_2", "patch-patch_0_piece_2_2",
                                             "patch-patch_1_piece_1_1"]
    numbers = [[t.text for t in g.findall(".//svg:text[@class='seam-number']", NS)] for g in groups]
    assert numbers == [["1"], ["1"], []]  # the seam's number on both of its pieces
    assert [len(g.findall(".//svg:polyline[@class='tick']", NS)) for g in groups] == [1, 1, 0]
    legs = groups[2].findall(".//svg:polyline[@class='dart']", NS)
    assert len(legs) == 2 and all(leg.get("stroke-dasharray") for leg in legs)
    assert [t.text for t in groups[2].findall(".//svg:text[@class='dart-label']", NS)] == ["dart"]
    # every piece: its name, the user's label and the skin-side mark
    for g in groups:
        texts = [t.text for t in g.iter("{http://www.w3.org/2000/svg}text")]
        assert LABEL in texts and "outer side up" in texts
    # the seam's number is not covered by the piece's label block
    for g in groups[:2]:
        num = g.find(".//svg:text[@class='seam-number']", NS)
        nx, ny = float(num.get("x")), float(num.get("y")) - 0.35 * float(num.get("font-size"))
        for t in g.findall("svg:text", NS):
            x, y, size = float(t.get("x")), float(t.get("y")), float(t.get("font-size"))
            half_w = 0.62 * size * len(t.text) / 2 + 0.5
            assert not (abs(nx - x) < half_w and y - size - 0.5 < ny < y + 0.5), (t.text, nx, ny, x, y)
    # the dart's legs end at one point on the V's bisector, just inside the opening
    ends = [np.array(leg.get("points").replace(",", " ").split(), float).reshape(-1, 2)[-1] for leg in legs]
    np.testing.assert_allclose(ends[0], ends[1])
    msp = dxf_doc(tmp_path / "m.dxf").modelspace()
    texts = [t.dxf.text for t in msp.query("TEXT")]
    assert texts.count("1") == 2 and "dart" in texts and texts.count(LABEL) == 4
    dashed = [p for p in msp.query('LWPOLYLINE[layer=="MARKS"]') if p.dxf.get("linetype") == "DASHED"]
    assert len(dashed) == 2
    (dark, _, text), = render(tmp_path / "m.pdf")
    assert text.count(LABEL) == 4 and "dart" in text and "patch 1 piece 1/1" in text


# ------------------------------------------------------------------ PDF
def test_pdf_one_page_has_the_drawing_size_and_a_true_50_mm_square(tmp_path):
    pieces, marks = marked_pattern()
    info = write_pattern(tmp_path / "one.pdf", pieces, marks, page="NONE", label=LABEL)
    D = pattern_drawing(pieces, marks, label=LABEL)
    assert info["pages"] == 1
    (dark, size, text), = render(tmp_path / "one.pdf")
    np.testing.assert_allclose(size, (D.width, D.height), atol=0.01)
    x, y = D.square
    w, h = measure_square(dark, x - 10, y - 10)
    assert w == pytest.approx(50.0, abs=0.5) and h == pytest.approx(50.0, abs=0.5)
    assert "50 mm" in text and "print at 100 %" in text and LABEL in text


@pytest.mark.parametrize("paper", ["A4", "LETTER"])
def test_tiled_pdf_covers_the_pattern_with_a_square_on_every_page(tmp_path, paper):
    V, F = grid(30, 4, 450.0)
    UV = V[:, :2] * [1.0, 0.3]  # 450 x 135 mm: wider than A4 either way
    pieces = [{"UV": UV, "F": F, "label": "wide"}, {"UV": UV[:, ::-1] * [1, 0.3] + [0, -60], "F": F[:, ::-1],
                                                     "label": "small"}]
    info = write_pattern(tmp_path / "t.pdf", pieces, page=paper, label=LABEL)
    pages = render(tmp_path / "t.pdf")
    assert info["pages"] == len(pages) > 1 and len(info["tiles"]) == len(pages)
    D = pattern_drawing(pieces, label=LABEL)
    for (dark, (pw, ph), text), (r, c, x0, y0, cw, ch) in zip(pages, info["tiles"]):
        assert {round(pw, 1), round(ph, 1)} == {round(v, 1) for v in pdraw.PAGES[paper]}
        assert ch == pytest.approx(ph - 2 * PAGE_MARGIN_MM - FOOTER_MM)
        w, h = measure_square(dark, PAGE_MARGIN_MM - 5, ph - PAGE_MARGIN_MM - FOOTER_MM + 1)
        assert w == pytest.approx(50.0, abs=0.5) and h == pytest.approx(50.0, abs=0.5)
        assert f"row {r + 1} col {c + 1}" in text and "print at 100 %, no scaling" in text
    if shutil.which("pdftoppm"):  # the renderer the issue names, where installed
        for dark, (_, _, _), (_, _, _, _, _, ch) in zip(render_pdftoppm(tmp_path / "t.pdf", tmp_path), pages,
                                                        info["tiles"]):
            w, h = measure_square(dark, PAGE_MARGIN_MM - 5, PAGE_MARGIN_MM + ch + 1)
            assert w == pytest.approx(50.0, abs=0.5) and h == pytest.approx(50.0, abs=0.5)
    # neighbouring tiles overlap by TILE_OVERLAP_MM; every outline point is on some page
    tiles = np.array([t[2:] for t in info["tiles"]])
    xs, ys = np.unique(tiles[:, 0]), np.unique(tiles[:, 1])
    assert np.allclose(xs[:-1] + tiles[0, 2] - xs[1:], TILE_OVERLAP_MM)
    for dp in D.pieces:
        for st in dp.cut:
            P = st.points
            inside = ((P[:, None, 0] >= tiles[:, 0]) & (P[:, None, 0] <= tiles[:, 0] + tiles[:, 2])
                      & (P[:, None, 1] >= tiles[:, 1]) & (P[:, None, 1] <= tiles[:, 1] + tiles[:, 3]))
            assert inside.any(axis=1).all()
    # and it is drawn there: the wide piece's outline shows on every page of the first row
    assert all(dark.any() for dark, _, _ in pages)


def test_pdf_needs_no_pillow(tmp_path):
    """fpdf2 draws the vectors and text without Pillow (which the add-on does not bundle)."""
    code = (
        "import sys; sys.modules['PIL'] = None\n"
        "import numpy as np\n"
        "from bolus_addon.core.pattern.export import write_pattern\n"
        "UV = np.array([[0.0, 0], [40, 0], [0, 30]])\n"
        f"info = write_pattern({str(tmp_path / 'x.pdf')!r}, [{{'UV': UV, 'F': [[0, 1, 2]]}}], page='A4')\n"
        "print(info['pages'], 'PIL' in sys.modules and sys.modules['PIL'] is not None)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=str(Path(__file__).resolve().parents[3]))
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["1", "False"]
    assert (tmp_path / "x.pdf").read_bytes().startswith(b"%PDF")


def test_non_latin_text_does_not_break_the_pdf(tmp_path):
    UV = np.array([[0.0, 0], [40, 0], [0, 30]])
    write_pattern(tmp_path / "u.pdf", [{"UV": UV, "F": [[0, 1, 2]], "label": "Nase Ω"}], label="Müller 李")
    (_, _, text), = render(tmp_path / "u.pdf")
    assert "Müller" in text


# ------------------------------------------------------------------ files
def test_unknown_extension_and_unwritable_paths_write_nothing(tmp_path):
    UV = np.array([[0.0, 0], [40, 0], [0, 30]])
    pieces = [{"UV": UV, "F": [[0, 1, 2]]}]
    with pytest.raises(BolusError, match=r"\.svg, \.dxf or \.pdf"):
        write_pattern(tmp_path / "p.png", pieces)
    with pytest.raises(BolusError, match="does not exist"):
        write_pattern(tmp_path / "missing" / "p.svg", pieces)
    (tmp_path / "dir.dxf").mkdir()
    with pytest.raises(BolusError, match="is a folder"):
        write_pattern(tmp_path / "dir.dxf", pieces)
    with pytest.raises(BolusError, match="page must be"):
        write_pattern(tmp_path / "p.pdf", pieces, page="A3")
    with pytest.raises(BolusError, match="choose a file"):
        write_pattern("", pieces)
    assert sorted(os.listdir(tmp_path)) == ["dir.dxf"]


@pytest.mark.parametrize("ext", ["svg", "dxf", "pdf"])
def test_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch, ext):
    UV = np.array([[0.0, 0], [40, 0], [0, 30]])
    target = tmp_path / f"p.{ext}"
    target.write_bytes(b"old")
    with pytest.raises(BolusError, match="non-finite"):  # fails while drawing
        write_pattern(target, [{"UV": UV * [1, np.nan], "F": [[0, 1, 2]]}])

    def no_replace(a, b):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(files.os, "replace", no_replace)
    with pytest.raises(BolusError, match="could not write.*No space left"):  # fails while writing
        write_pattern(target, [{"UV": UV, "F": [[0, 1, 2]]}])
    assert target.read_bytes() == b"old" and os.listdir(tmp_path) == [target.name]
    monkeypatch.undo()
    write_pattern(target, [{"UV": UV, "F": [[0, 1, 2]]}])
    assert target.read_bytes()[:5] in (b"<?xml", b"%PDF-") or b"SECTION" in target.read_bytes()[:100]
    assert os.listdir(tmp_path) == [target.name]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder_is_refused(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(BolusError, match="could not write"):
            write_pattern(folder / "p.svg", [{"UV": [[0.0, 0], [40, 0], [0, 30]], "F": [[0, 1, 2]]}])
        assert os.listdir(folder) == []
    finally:
        folder.chmod(0o700)


# ------------------------------------------------------------------ degenerate input
@pytest.mark.parametrize("name", ["coincident", "collinear", "nan", "inf", "needle", "nonmanifold"])
@pytest.mark.parametrize("ext", ["svg", "dxf", "pdf"])
def test_degenerate_pieces(tmp_path, name, ext):
    """NaN / inf and non-manifold edges are refused by name with no file; zero-area and needle
    triangles do not change the outline: the written cut line is the clean piece's."""
    V, F = grid(4, 3, 40.0)
    Vd, Fd, says = degenerate_variants(V, F)[name]
    UVd = Vd[:, :2] + Vd[:, 2:]
    path = tmp_path / f"d.{ext}"
    if says in ("non-manifold",) or name in ("nan", "inf"):
        with pytest.raises(BolusError, match="non-finite" if name in ("nan", "inf") else "more than two faces"):
            write_pattern(path, [{"UV": UVd, "F": Fd}])
        assert not os.listdir(tmp_path)
        return
    info = write_pattern(path, [{"UV": UVd, "F": Fd}], label=LABEL)
    assert info["pieces"] == 1 and os.listdir(tmp_path) == [path.name]
    D = pattern_drawing([{"UV": UVd, "F": Fd}])
    loop = D.pieces[0].pattern_cut[0]
    assert np.isfinite(loop).all()
    assert signed_area(loop) == pytest.approx(1600.0, rel=1e-5)  # the 40 x 40 mm piece (+ the needle sliver)
    assert perimeter(loop) == pytest.approx(160.0, rel=1e-5)


def test_marks_of_another_pattern_and_bad_text_are_handled(tmp_path):
    pieces, marks = marked_pattern()
    other = pdraw_marks(marks, UV=marks.UV[:10])
    with pytest.raises(BolusError, match="belong to another pattern"):
        write_pattern(tmp_path / "a.svg", pieces, other)
    with pytest.raises(BolusError, match="carry no positions"):
        write_pattern(tmp_path / "a.svg", pieces, pdraw_marks(marks, UV=None))
    assert not os.listdir(tmp_path)
    # a label with a newline and a tab is written on one line in every format
    for ext in ("svg", "dxf", "pdf"):
        write_pattern(tmp_path / f"b.{ext}", pieces[:1], label="ID 1\nline\t2")
    texts = [t.text for t in ET.fromstring((tmp_path / "b.svg").read_text()).iter("{http://www.w3.org/2000/svg}text")]
    assert "ID 1 line 2" in texts
    assert "ID 1 line 2" in [t.dxf.text for t in dxf_doc(tmp_path / "b.dxf").modelspace().query("TEXT")]


def pdraw_marks(marks, **changes):
    from dataclasses import replace

    return replace(marks, **changes)


def test_pdf_page_too_large_for_one_page_is_refused_and_tiled_instead(tmp_path):
    V, F = grid(60, 1, 6000.0)
    pieces = [{"UV": V[:, :2] * [1.0, 0.005], "F": F}]  # 6 m x 30 mm
    with pytest.raises(BolusError, match="too large for one PDF page.*A4 or Letter"):
        write_pattern(tmp_path / "long.pdf", pieces, page="NONE")
    assert not os.listdir(tmp_path)
    info = write_pattern(tmp_path / "long.pdf", pieces, page="A4")
    assert info["pages"] == len(pdfium.PdfDocument(str(tmp_path / "long.pdf"))) > 20
