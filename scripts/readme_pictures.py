"""The README's step-by-step pictures (`make pictures`), rendered headless.

    .venv/bin/python scripts/readme_pictures.py [--out docs/img]

Runs the demo's job (scripts/demo.py: the MIT-licensed ICT face, assets/ict_face_narrow.obj,
at true size in a scene where 1 unit = 1 mm, the treatment area = the forward-facing faces
within 45 mm of the nose tip) step by step with the same operators a modeler presses in the
sidebar, and renders each step's RESULT with Blender's Workbench engine (bpy cannot
screenshot its own UI in background mode, so there is no picture of the panel itself):

    1_area_flattenability.png  the treatment area selected in Edit Mode (orange)
                               | Flattenability Preview (viridis: dark lies flat, yellow cannot)
    2_patches_cuts.png         Segment into Patches (jagged borders along mesh edges)
                               | Smooth Cut Lines (close-ups of the treatment area)
    3_pattern.png              Unfold Patches: the pattern object, coloured by area distortion
                               (blue shrunk, white exact, red stretched, +-10 %)
    4_pattern_svg.png          Export Pattern (SVG): the file's paths, lines and texts drawn
                               in Blender (solid cut lines, dashed 5 mm seam allowance, 50 mm bar)
    5_bolus_section.png        Make Bolus: the 10 mm bolus on the face (close-up) | a cross-section
                               through the nose tip (scripts/pictures2d.py: bolus filled, skin a line)
    6_print_parts.png          Split into Print Parts on the bolus, Orient Print Parts: the solid
                               parts with pegs and holes on the build plate (spread in a row for
                               the picture), faces that need support in red

Every picture is 800 px wide, RGB, rendered without dithering and with the Standard view
transform (the colours are the colour maps' own), written by a small PNG writer (64 levels
per channel, zlib level 9) so the files stay small. The figures of the run are printed (and are the demo's).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import demo  # noqa: E402  (scripts/demo.py: loading, the treatment area, the renders)
from pictures2d import write_png  # noqa: E402  (the small PNG writer)

#: every picture's width in pixels (GitHub shows README images up to about 880 px)
WIDTH_PX = 800
#: height of the two-panel pictures (each panel 400 x 500, the demo's 0.8 aspect)
PANEL_HEIGHT_PX = 500
#: Blender's selected-face orange (sRGB) and a light grey for the rest, for picture 1
SELECTED_SRGB = (1.0, 0.55, 0.1)
UNSELECTED_SRGB = (0.8, 0.8, 0.8)
#: thinnest line drawn for the SVG picture, in pixels (a 0.2 mm stroke is under 1 px at 800 px)
MIN_LINE_PX = 1.3
SVG_NS = "{http://www.w3.org/2000/svg}"


def read_png(path: Path) -> np.ndarray:
    """(h, w, 3) uint8, top row first, of a PNG Blender wrote (loaded through bpy.data.images)."""
    im = bpy.data.images.load(str(path))
    w, h = im.size
    px = np.empty(w * h * 4, np.float32)
    im.pixels.foreach_get(px)
    bpy.data.images.remove(im)
    return (np.clip(px.reshape(h, w, 4)[::-1, :, :3], 0, 1) * 255 + 0.5).astype(np.uint8)


def side_by_side(paths: list[Path], out: Path) -> None:
    """The renders at `paths` (same height) in one row, separated by a 4 px white gap."""
    imgs = [read_png(p) for p in paths]
    gap = np.full((imgs[0].shape[0], 4, 3), 255, np.uint8)
    row = [imgs[0]]
    for im in imgs[1:]:
        row += [gap, im]
    write_png(out, np.concatenate(row, axis=1))


def render_to(path: Path) -> Path:
    bpy.context.scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    return path


def set_resolution(w: int, h: int) -> None:
    r = bpy.context.scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, 100


def show_selection(obj: bpy.types.Object, sel: np.ndarray) -> None:
    """A picture-only colour attribute: the selected faces orange, the rest grey (removed after use)."""
    from bolus_addon.core.colormap import srgb_to_linear
    from bolus_addon.blender.mesh_io import write_face_colors

    rgb = np.where(sel[:, None], SELECTED_SRGB, UNSELECTED_SRGB)
    write_face_colors(obj.data, "readme_selection", np.c_[srgb_to_linear(rgb), np.ones(len(sel))])


def svg_polylines(root: ET.Element) -> list[tuple[np.ndarray, float, list[float]]]:
    """Every <path> (M/L/Z only, as core.pattern_svg writes them), <line>, <polyline> and <polygon> of the SVG as
    (points (k, 2) in SVG user units (mm), stroke width, dash pattern or [])."""
    out = []
    for el in root.iter():
        tag = el.tag.removeprefix(SVG_NS)
        width = float(el.get("stroke-width", "0.3"))
        dash = [float(x) for x in el.get("stroke-dasharray", "").replace(",", " ").split()]
        if tag == "line":
            pts = np.array([[float(el.get("x1")), float(el.get("y1"))], [float(el.get("x2")), float(el.get("y2"))]])
            out.append((pts, width, dash))
        elif tag in ("polyline", "polygon"):  # marks and the test square (core.pattern_svg)
            pts = np.array(el.get("points").replace(",", " ").split(), dtype=float).reshape(-1, 2)
            out.append((np.r_[pts, pts[:1]] if tag == "polygon" else pts, width, dash))
        elif tag == "path":
            tokens = el.get("d").replace(",", " ").split()
            pts, i = [], 0
            while i < len(tokens):
                t = tokens[i]
                if t in ("M", "L"):
                    if t == "M" and pts:
                        out.append((np.array(pts), width, dash))
                        pts = []
                    pts.append((float(tokens[i + 1]), float(tokens[i + 2])))
                    i += 3
                elif t == "Z":
                    pts.append(pts[0])
                    i += 1
                else:
                    raise SystemExit(f"path command {t!r}: this drawing knows M, L and Z only")
            if pts:
                out.append((np.array(pts), width, dash))
    return out


def dashes(pts: np.ndarray, pattern: list[float]) -> list[np.ndarray]:
    """The polyline cut into the on-pieces of a dash pattern (on, off, on, off, ...)."""
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    period = sum(pattern)
    starts = np.arange(0.0, s[-1], period)
    pieces = []
    for a in starts:
        b = min(a + pattern[0], s[-1])
        inner = pts[1:-1][(s[1:-1] > a) & (s[1:-1] < b)]
        ends = [np.array([np.interp(t, s, pts[:, 0]), np.interp(t, s, pts[:, 1])]) for t in (a, b)]
        pieces.append(np.vstack([ends[0], *inner, ends[1]]))
    return pieces


def draw_svg(svg_path: Path, px_per_mm: float) -> tuple[list, float, float]:
    """The SVG's lines as black tubes and its texts as Blender text objects in z = 0 (SVG y
    flipped); returns (objects, page width, page height) in mm."""
    root = ET.parse(svg_path).getroot()
    _, _, w, h = (float(x) for x in root.get("viewBox").split())
    black = bpy.data.materials.new("svg_black")
    objs = []
    for pts, width, dash in svg_polylines(root):
        cu = bpy.data.curves.new("svg_line", "CURVE")
        cu.dimensions = "3D"
        cu.bevel_depth = max(width, MIN_LINE_PX / px_per_mm) / 2
        for piece in dashes(pts, dash) if dash else [pts]:
            sp = cu.splines.new("POLY")
            sp.points.add(len(piece) - 1)
            xyzw = np.c_[piece[:, 0], h - piece[:, 1], np.zeros(len(piece)), np.ones(len(piece))]
            sp.points.foreach_set("co", xyzw.ravel())
        objs.append(bpy.data.objects.new("svg_line", cu))
    for el in root.iter(SVG_NS + "text"):
        cu = bpy.data.curves.new("svg_text", "FONT")
        cu.body = el.text or ""
        cu.size = float(el.get("font-size", "3"))
        cu.align_x = {"middle": "CENTER", "end": "RIGHT"}.get(el.get("text-anchor"), "LEFT")
        ob = bpy.data.objects.new("svg_text", cu)
        ob.location = (float(el.get("x")), h - float(el.get("y")), 0.0)
        objs.append(ob)
    for ob in objs:
        ob.data.materials.append(black)
        ob.color = (0.0, 0.0, 0.0, 1.0)
        bpy.context.scene.collection.objects.link(ob)
    return objs, w, h


def render_svg(svg_path: Path, out: Path) -> None:
    """Top view of the SVG page (white) drawn by draw_svg, WIDTH_PX wide, with every other object hidden."""
    scene = bpy.context.scene
    hidden = [ob for ob in scene.objects if ob.type == "MESH" and not ob.hide_render]
    for ob in hidden:
        ob.hide_render = True
    page_w = float(ET.parse(svg_path).getroot().get("viewBox").split()[2])
    objs, w, h = draw_svg(svg_path, WIDTH_PX / page_w)
    shading, world = scene.display.shading, scene.world
    old = (shading.light, shading.color_type, tuple(world.color))
    shading.light, shading.color_type = "FLAT", "OBJECT"
    world.color = (1.0, 1.0, 1.0)
    set_resolution(WIDTH_PX, int(round(WIDTH_PX * h / w)))
    cam = scene.camera
    old_cam = (tuple(cam.location), tuple(cam.rotation_euler), cam.data.ortho_scale)
    # an orthographic camera's scale spans the longer side of the image: a page taller than wide needs h
    cam.location, cam.rotation_euler, cam.data.ortho_scale = (w / 2, h / 2, 100.0), (0.0, 0.0, 0.0), max(w, h)
    tmp = render_to(out.with_suffix(".render.png"))
    write_png(out, read_png(tmp))
    tmp.unlink()
    cam.location, cam.rotation_euler, cam.data.ortho_scale = old_cam
    shading.light, shading.color_type, world.color = old
    for ob in objs:
        bpy.data.objects.remove(ob, do_unlink=True)
    for ob in hidden:
        ob.hide_render = False


def spread_along_x(parts: list, gap_mm: float = 10.0) -> None:
    """Shift the placed parts (on z = 0, turned as orient_parts left them) into one row
    along x, `gap_mm` apart, so that the front view shows each of them (orient_parts packs
    the footprints on the plate, which may put one behind the other); picture only."""
    from mathutils import Matrix

    x = 0.0
    for ob in parts:
        co = np.array([ob.matrix_world @ v.co for v in ob.data.vertices])
        lo, hi = co.min(axis=0), co.max(axis=0)
        shift = (x - lo[0], -(lo[1] + hi[1]) / 2, 0.0)
        ob.matrix_world = Matrix.Translation(shift) @ ob.matrix_world
        x += hi[0] - lo[0] + gap_mm


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "docs" / "img"), help="folder for the PNGs (created)")
    ap.add_argument("--radius", type=float, default=45.0, help="treatment area: faces within this many mm of the nose tip")
    args = ap.parse_args(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="bolus_readme_"))
    half = (WIDTH_PX - 4) // 2

    obj = demo.load_example()
    sel = demo.select_treatment_area(obj, args.radius)
    demo.setup_render(obj, PANEL_HEIGHT_PX)
    scene = bpy.context.scene
    set_resolution(half, PANEL_HEIGHT_PX)
    scene.render.image_settings.color_mode = "RGB"
    scene.render.dither_intensity = 0.0  # noise that costs bytes and shows nothing
    scene.view_settings.view_transform = "Standard"  # attribute colours as the colour maps define them
    # 1. the treatment area, selected in Edit Mode, and the flattenability preview
    show_selection(obj, sel)
    area = render_to(tmp / "area.png")
    obj.data.color_attributes.remove(obj.data.color_attributes["readme_selection"])
    bpy.ops.object.mode_set(mode="EDIT")
    demo.run_op(bpy.ops.bolus.saliency_preview)
    demo.run_op(bpy.ops.bolus.segment, patches=4, eta=5.0, seed=0)
    bpy.ops.object.mode_set(mode="OBJECT")
    demo.render(obj, "bolus_saliency_color", tmp / "flat.png")
    side_by_side([area, tmp / "flat.png"], out / "1_area_flattenability.png")
    # 2. the patches, before and after the smooth cut lines (close-ups)
    demo.render_closeup(obj, "bolus_patch_color", tmp / "patches.png")
    demo.run_op(bpy.ops.bolus.smooth_cuts)
    demo.render_closeup(obj, "bolus_patch_color", tmp / "cuts.png")
    side_by_side([tmp / "patches.png", tmp / "cuts.png"], out / "2_patches_cuts.png")
    # 3. the pattern object; 4. the SVG as exported
    demo.run_op(bpy.ops.bolus.unfold)
    svg = tmp / "pattern.svg"
    demo.run_op(bpy.ops.bolus.export_pattern, filepath=str(svg), seam_allowance_mm=5.0)
    pattern = bpy.data.objects[obj.name + "_pattern"]
    set_resolution(WIDTH_PX, PANEL_HEIGHT_PX)
    demo.render_pattern(pattern, tmp / "pattern.png")
    write_png(out / "3_pattern.png", read_png(tmp / "pattern.png"))
    render_svg(svg, out / "4_pattern_svg.png")
    # 5. the printed bolus on the face, and a cross-section through the nose tip
    from bolus_addon.blender.mesh_io import read_face_labels
    from bolus_addon.operators.printing import part_objects

    bpy.context.view_layer.objects.active = obj
    obj.data.polygons.foreach_set("select", read_face_labels(obj.data, "bolus_patch") >= 0)
    bpy.ops.object.mode_set(mode="EDIT")
    demo.run_op(bpy.ops.bolus.make_shell, thickness_mm=10.0, label="DEMO")
    bpy.ops.object.mode_set(mode="OBJECT")
    bolus = bpy.data.objects[obj.name + "_bolus"]
    set_resolution(half, PANEL_HEIGHT_PX)
    pattern.hide_render = True  # it lies on z = 0, in front of the face's close-up
    shading = scene.display.shading
    shading.color_type = "OBJECT"  # the face grey, the bolus blue as in the cross-section
    obj.color, bolus.color = (0.8, 0.8, 0.8, 1.0), (0.27, 0.51, 0.86, 1.0)
    demo.render_closeup(obj, "bolus_patch_color", tmp / "bolus.png")
    shading.color_type = "VERTEX"
    demo.render_section(obj, bolus, tmp / "section.png", size_px=(half, PANEL_HEIGHT_PX))
    side_by_side([tmp / "bolus.png", tmp / "section.png"], out / "5_bolus_section.png")
    # 6. the bolus split into solid parts with pegs and holes, each in its best direction on the plate
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob is bolus)
    bpy.context.view_layer.objects.active = bolus
    demo.run_op(bpy.ops.bolus.print_segment, parts=3, method="ABCUT", seed=0)
    demo.run_op(bpy.ops.bolus.orient_parts)
    parts = part_objects(bolus.name)
    spread_along_x(parts)
    set_resolution(WIDTH_PX, PANEL_HEIGHT_PX)
    demo.render_parts([obj, pattern, bolus], parts, tmp / "parts.png")
    write_png(out / "6_print_parts.png", read_png(tmp / "parts.png"))

    table = json.loads(pattern["bolus_pattern_table"])
    orient = json.loads(bolus["bolus_orient_table"])
    print(f"treatment area {int(sel.sum())} faces; sum varpi {obj['bolus_sum_varpi']:.2f} rad; "
          f"{len(json.loads(obj['bolus_patch_table'])['patches'])} patches; pattern EL {table['EL'] * 100:.2f} %, "
          f"EA {table['EA'] * 100:.2f} %; pieces " + ", ".join(
              f"{r['name']} EL {r['EL'] * 100:.1f} % EA {r['EA'] * 100:.1f} %{' (warned)' if r.get('warn') else ''}"
              for r in table["islands"]) + f"; {len(orient['rows']) - 1} print parts")
    for p in sorted(out.glob("*.png")):
        print(f"wrote {p} ({p.stat().st_size // 1024} KB)")


if __name__ == "__main__":
    demo.run_with_addon(main)
