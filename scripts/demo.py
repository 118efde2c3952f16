"""The main job, headless, on the built-in example (`make demo`).

    .venv/bin/python scripts/demo.py --out out
    blender --background --python scripts/demo.py -- --out out     (a Blender install with the extension)

Loads assets/ict_face_narrow.obj (an MIT-licensed face; the file is in cm) at true size
in a scene where 1 unit = 1 mm, puts the 3D cursor on the nose tip and runs the add-on's
operators as a modeler does:

0. bolus.select_area       the treatment area: within --radius mm of the cursor along the skin,
                           its border cut along a smooth curve, the nostrils left out
1. bolus.saliency_preview  -> out/saliency.png
2. bolus.segment           -> out/patches.png (jagged borders along mesh edges)
3. bolus.smooth_cuts       -> out/cuts.png (the borders replaced by smooth cut lines;
                              close-ups before and after: cuts_before.png, cuts_after.png)
4. bolus.unfold            -> out/pattern.png (the flat pattern of the mid-surface of a
                              --sheet-thickness mm (5) sheet, coloured by area distortion): a
                              patch above --max-el % (2) gets darts and splits; every piece gets
                              its bending strain and the sheet-or-print advice; pieces not fit to
                              cut are warned with their figures
   bolus.improve_flattenability (optional step) -> the object face_improved: the area moved
                              outward by at most --max-gap mm (1) where that makes it flatter,
                              out/air_gap.png (its air-gap map), and the pattern unfolded again
                              from it: EL / EA before and after in report.txt
5. bolus.export_pattern    -> out/pattern.svg, out/pattern.dxf (mm, for a cutter) and
                              out/pattern_a4.pdf (tiled on A4): true scale, pieces labelled with
                              --label, numbered matching marks, dart marks, a 50 mm test square
6. bolus.make_shell        -> the object face_bolus: a closed --thickness mm (10) solid on the
                              area, --label engraved; out/section.png (a cross-section through
                              the nose tip: the bolus filled, the skin a line, 10 mm bar)
7. bolus.print_segment (on face_bolus), bolus.orient_parts, bolus.export_parts
                           -> --parts (3) closed solid parts with pegs and holes,
                              out/parts/*.stl (binary, mm, closed), out/parts.png (the parts
                              on the build plate, overhangs in red)

and writes out/demo.blend and the per-patch tables (out/report.json, out/report.txt).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

EXAMPLE = ROOT / "assets" / "ict_face_narrow.obj"
CM_TO_MM = 10.0


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "out"), help="output folder (created)")
    ap.add_argument("--radius", type=float, default=45.0, help="treatment area: faces within this many mm of the nose tip")
    ap.add_argument("--patches", type=int, default=4)
    ap.add_argument("--parts", type=int, default=3, help="print parts")
    ap.add_argument("--max-el", type=float, default=2.0, help="unfold's EL target in %% (darts and splits); 0 = off")
    ap.add_argument("--sheet-thickness", type=float, default=5.0,
                    help="sheet thickness in mm: the pattern of the mid-surface, bending advice; 0 = the skin")
    ap.add_argument("--max-gap", type=float, default=1.0,
                    help="improve_flattenability's largest air gap in mm; 0 = skip that step")
    ap.add_argument("--thickness", type=float, default=10.0, help="bolus thickness in mm")
    ap.add_argument("--shell-resolution", type=float, default=0.5, help="make_shell's resolution in mm")
    ap.add_argument("--label", default="DEMO", help="engraved on each part with its number")
    ap.add_argument("--smoothing", type=float, default=None, help="analysis smoothing in mm (default: the add-on's)")
    ap.add_argument("--resolution", type=int, default=900, help="PNG height in pixels")
    return ap.parse_args(argv)


def ensure_addon():
    if not hasattr(bpy.ops, "bolus") or not hasattr(bpy.types.Scene, "bolus"):
        import bolus_addon

        bolus_addon.register()


def mm_scene() -> bpy.types.Scene:
    """An empty scene in which 1 unit = 1 mm, the add-on registered (demo and scripts/bolus_cli.py)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_addon()
    scene = bpy.context.scene
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 0.001  # 1 unit = 1 mm
    scene.unit_settings.length_unit = "MILLIMETERS"
    return scene


def load_example() -> bpy.types.Object:
    mm_scene()
    bpy.ops.wm.obj_import(filepath=str(EXAMPLE), global_scale=CM_TO_MM)
    obj = bpy.context.selected_objects[0]
    obj.name = "face"
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.transform_apply(location=False, rotation=True, scale=True)  # vertices in mm
    return obj


def nose_tip(obj: bpy.types.Object) -> np.ndarray:
    """World position of the nose tip (the face looks towards -Y after the OBJ importer's Y-up conversion)."""
    co = np.array([obj.matrix_world @ v.co for v in obj.data.vertices])
    return co[np.argmin(co[:, 1])]


def select_treatment_area(obj: bpy.types.Object, radius_mm: float) -> np.ndarray:
    """The treatment area around the nose tip, as a modeler makes it: the 3D cursor on the tip, then
    Select Treatment Area (`bolus.select_area`: within radius_mm along the surface, the border cut
    along a smooth curve, the nostrils left out).  Leaves Object Mode; returns the polygons' selection."""
    bpy.context.scene.cursor.location = tuple(float(x) for x in nose_tip(obj))
    bpy.context.view_layer.objects.active = obj
    run_op(bpy.ops.bolus.select_area, radius_mm=radius_mm, exclude_cavities=True)
    bpy.ops.object.mode_set(mode="OBJECT")
    sel = np.zeros(len(obj.data.polygons), dtype=bool)
    obj.data.polygons.foreach_get("select", sel)
    return sel


def setup_render(obj: bpy.types.Object, height_px: int) -> None:
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    shading = scene.display.shading
    shading.light = "STUDIO"
    shading.color_type = "VERTEX"
    shading.show_cavity = False
    scene.display.render_aa = "8"
    scene.render.film_transparent = False
    scene.render.resolution_y = height_px
    scene.render.resolution_x = int(height_px * 0.8)
    scene.render.resolution_percentage = 100
    world = bpy.data.worlds.new("demo") if scene.world is None else scene.world
    scene.world = world
    # orthographic camera in front of the face (-Y), framing the whole object
    bb = np.array([obj.matrix_world @ v.co for v in obj.data.vertices])
    lo, hi = bb.min(axis=0), bb.max(axis=0)
    centre = (lo + hi) / 2
    cam_data = bpy.data.cameras.new("demo_camera")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = float(max(hi[0] - lo[0], (hi[2] - lo[2]) / 0.8) * 1.05)
    cam_data.clip_start = 1.0
    cam_data.clip_end = 10.0 * float(np.linalg.norm(hi - lo))
    cam = bpy.data.objects.new("demo_camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = (float(centre[0]), float(lo[1] - 3 * (hi[1] - lo[1]) - 100), float(centre[2]))
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    scene.camera = cam


def render(obj: bpy.types.Object, color_attribute: str, path: Path) -> None:
    from bolus_addon.blender.mesh_io import show_colors

    show_colors(obj.data, color_attribute)
    bpy.context.scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)


def render_closeup(obj: bpy.types.Object, color_attribute: str, path: Path) -> None:
    """Front view framing the patches only (faces with bolus_patch >= 0)."""
    from bolus_addon.blender.mesh_io import read_face_labels

    scene = bpy.context.scene
    labels = read_face_labels(obj.data, "bolus_patch")
    verts = {v for p, lab in zip(obj.data.polygons, labels) if lab >= 0 for v in p.vertices}
    co = np.array([obj.matrix_world @ obj.data.vertices[i].co for i in verts])
    lo, hi = co.min(axis=0), co.max(axis=0)
    cam = scene.camera
    old = (tuple(cam.location), cam.data.ortho_scale)
    cam.location = (float((lo[0] + hi[0]) / 2), cam.location[1], float((lo[2] + hi[2]) / 2))
    cam.data.ortho_scale = float(max(hi[0] - lo[0], (hi[2] - lo[2]) / 0.8) * 1.15)
    render(obj, color_attribute, path)
    cam.location, cam.data.ortho_scale = old


def render_pattern(pattern: bpy.types.Object, path: Path) -> None:
    """Top view of the pattern alone, coloured by area distortion (blue shrunk, red stretched)."""
    from bolus_addon.blender.mesh_io import show_colors

    scene = bpy.context.scene
    others = [ob for ob in scene.objects if ob is not pattern and ob.type == "MESH" and not ob.hide_render]
    for ob in others:  # the face, and the print parts that also lie on z = 0
        ob.hide_render = True
    show_colors(pattern.data, "bolus_area_distortion")
    co = np.array([v.co for v in pattern.data.vertices])
    lo, hi = co.min(axis=0), co.max(axis=0)
    cam = scene.camera
    old = (tuple(cam.location), tuple(cam.rotation_euler), cam.data.ortho_scale)
    cam.location = (float((lo[0] + hi[0]) / 2), float((lo[1] + hi[1]) / 2), 500.0)
    cam.rotation_euler = (0.0, 0.0, 0.0)
    rx, ry = scene.render.resolution_x, scene.render.resolution_y
    w, h = float(hi[0] - lo[0]), float(hi[1] - lo[1])
    # the ortho scale spans the longer side of the image (sensor fit AUTO)
    cam.data.ortho_scale = (max(w, h * rx / ry) if rx >= ry else max(h, w * ry / rx)) * 1.1
    scene.display.shading.light = "FLAT"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    scene.display.shading.light = "STUDIO"
    cam.location, cam.rotation_euler, cam.data.ortho_scale = old
    for ob in others:
        ob.hide_render = False


def render_parts(hide: list, parts: list, path: Path) -> None:
    """Front view of the oriented print parts on the plate (z = 0), overhang faces in red."""
    from bolus_addon.blender.mesh_io import show_colors

    scene = bpy.context.scene
    for ob in hide:
        ob.hide_render = True
    pts = []
    for ob in parts:
        show_colors(ob.data, "bolus_overhang")
        pts += [ob.matrix_world @ v.co for v in ob.data.vertices]
    pts = np.array(pts)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    # the build plate under the parts, for the picture only
    pad = 0.1 * float(max(hi[0] - lo[0], hi[1] - lo[1]))
    plate_me = bpy.data.meshes.new("build_plate")
    x0, x1, y0, y1 = lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad
    plate_me.from_pydata([(x0, y0, 0), (x1, y0, 0), (x1, y1, 0), (x0, y1, 0)], [], [(0, 1, 2, 3)])
    plate = bpy.data.objects.new("build_plate", plate_me)
    scene.collection.objects.link(plate)
    cam = scene.camera
    old = (tuple(cam.location), tuple(cam.rotation_euler), cam.data.ortho_scale)
    tilt = 0.5  # look down onto the plate
    centre = (lo + hi) / 2
    dist = 5.0 * float(np.linalg.norm(hi - lo))
    cam.rotation_euler = (np.pi / 2 - tilt, 0.0, 0.0)
    cam.location = (float(centre[0]), float(centre[1] - dist * np.cos(tilt)), float(centre[2] + dist * np.sin(tilt)))
    rx, ry = scene.render.resolution_x, scene.render.resolution_y
    w, h = float(hi[0] - lo[0]), float(hi[2] - lo[2] + (hi[1] - lo[1]) * np.sin(tilt))
    cam.data.ortho_scale = (max(w, h * rx / ry) if rx >= ry else max(h, w * ry / rx)) * 1.15
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    cam.location, cam.rotation_euler, cam.data.ortho_scale = old
    bpy.data.objects.remove(plate, do_unlink=True)
    bpy.data.meshes.remove(plate_me)
    for ob in hide:
        ob.hide_render = False


def render_section(face: bpy.types.Object, bolus: bpy.types.Object, path: Path, size_px=None) -> dict:
    """The bolus on the face cut through the nose tip by a sagittal plane (x = const), drawn exactly
    (scripts/pictures2d.section_png): the bolus's section filled, the skin's a black line."""
    from pictures2d import section_png

    def world_tris(ob):
        me = ob.data
        me.calc_loop_triangles()
        V = np.array([ob.matrix_world @ v.co for v in me.vertices])
        F = np.array([t.vertices[:] for t in me.loop_triangles], dtype=np.int64)
        return V, F

    return section_png(path, world_tris(face), world_tris(bolus), nose_tip(face), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0),
                       size_px=size_px)


def improve_and_unfold(obj: bpy.types.Object, args, out: Path) -> dict:
    """The optional step: Improve Flattenability on the patches (outward only, at most --max-gap mm),
    the air-gap map rendered, and the improved surface unfolded with the same settings as the skin."""
    from bolus_addon.blender.mesh_io import read_face_labels

    bpy.context.view_layer.objects.active = obj
    obj.data.polygons.foreach_set("select", read_face_labels(obj.data, "bolus_patch") >= 0)
    bpy.ops.object.mode_set(mode="EDIT")
    seconds = run_op(bpy.ops.bolus.improve_flattenability, max_gap_mm=args.max_gap, method="GRADIENT", seed=0)
    bpy.ops.object.mode_set(mode="OBJECT")
    improved = bpy.data.objects[obj.name + "_improved"]
    table = json.loads(improved["bolus_improve_table"])
    obj.hide_render = True
    render_closeup(improved, "bolus_air_gap_color", out / "air_gap.png")
    obj.hide_render = False
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob is improved)
    bpy.context.view_layer.objects.active = improved
    t_unf = run_op(bpy.ops.bolus.unfold, max_el=args.max_el, sheet_thickness_mm=args.sheet_thickness)
    pattern = bpy.data.objects[improved.name + "_pattern"]
    improved.hide_render = pattern.hide_render = True  # the later pictures show the skin's bolus and parts
    bpy.context.view_layer.objects.active = obj
    return {"table": table, "pattern": json.loads(pattern["bolus_pattern_table"]), "seconds": seconds,
            "unfold_seconds": t_unf}


def improve_lines(improve: dict, pattern_table: dict) -> list[str]:
    """report.txt's lines of the optional step: Table 4-4 before -> after, and the pattern's EL / EA."""
    t = improve["table"]
    b, a = t["whole"]["before"], t["whole"]["after"]
    lines = [f"Improve flattenability (max gap {t['max_gap_mm']:g} mm, {t['method']}, {improve['seconds']:.1f} s; "
             f"Table 4-4, at smoothing {t['smoothing_mm']:g} mm): FLV {b['flv']:.4g} -> {a['flv']:.4g}, sum varpi "
             f"{b['sum_varpi']:.3f} -> {a['sum_varpi']:.3f} rad (raw {b['raw_sum_varpi']:.2f} -> "
             f"{a['raw_sum_varpi']:.2f}), area {b['area_mm2']:.0f} -> {a['area_mm2']:.0f} mm2, air gap max "
             f"{a['max_gap_mm']:.2f} / mean {a['mean_gap_mm']:.2f} mm (air_gap.png)"]
    for r in t["patches"]:
        lines.append(f"  patch {r['patch']}: {r['status']}, sum varpi {r['before']['sum_varpi']:.3f} -> "
                     f"{r['after']['sum_varpi']:.3f}, largest varpi {r['before']['max_varpi']:.3f} -> "
                     f"{r['after']['max_varpi']:.3f}, largest gap {r['after']['max_gap_mm']:.2f} mm")
    p = improve["pattern"]
    lines.append(f"Pattern of the improved surface: EL {pattern_table['EL'] * 100:.2f} -> {p['EL'] * 100:.2f} %, "
                 f"EA {pattern_table['EA'] * 100:.2f} -> {p['EA'] * 100:.2f} %, {pattern_table['pieces']} -> "
                 f"{p['pieces']} pieces, {pattern_table['darts']} -> {p['darts']} darts (the skin's pattern is the "
                 "one exported)")
    return lines


def run_op(op, **kw) -> float:
    t = time.perf_counter()
    result = op(**kw)
    if result != {"FINISHED"}:
        raise SystemExit(f"{op.idname_py()} returned {result}")
    return time.perf_counter() - t


def main():
    args = parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    obj = load_example()
    sel = select_treatment_area(obj, args.radius)
    smoothing = args.smoothing if args.smoothing is not None else bpy.context.scene.bolus.smoothing_mm
    setup_render(obj, args.resolution)
    bpy.ops.object.mode_set(mode="EDIT")
    t_sal = run_op(bpy.ops.bolus.saliency_preview, smoothing_mm=smoothing)
    t_seg = run_op(bpy.ops.bolus.segment, patches=args.patches, eta=5.0, seed=0, smoothing_mm=smoothing)
    bpy.ops.object.mode_set(mode="OBJECT")
    render(obj, "bolus_saliency_color", out / "saliency.png")
    render(obj, "bolus_patch_color", out / "patches.png")
    render_closeup(obj, "bolus_patch_color", out / "cuts_before.png")
    jagged_table = json.loads(obj["bolus_patch_table"])
    t_cut = run_op(bpy.ops.bolus.smooth_cuts)
    cuts = json.loads(obj["bolus_cut_table"])
    render(obj, "bolus_patch_color", out / "cuts.png")
    render_closeup(obj, "bolus_patch_color", out / "cuts_after.png")
    t_unf = run_op(bpy.ops.bolus.unfold, max_el=args.max_el, sheet_thickness_mm=args.sheet_thickness)
    t_svg = run_op(bpy.ops.bolus.export_pattern, filepath=str((out / "pattern.svg").resolve()), seam_allowance_mm=5.0,
                   label=args.label)
    run_op(bpy.ops.bolus.export_pattern, filepath=str((out / "pattern.dxf").resolve()), seam_allowance_mm=5.0,
           label=args.label)
    run_op(bpy.ops.bolus.export_pattern, filepath=str((out / "pattern_a4.pdf").resolve()), seam_allowance_mm=5.0,
           label=args.label, page="A4")
    pattern = bpy.data.objects[obj.name + "_pattern"]
    pattern_table = json.loads(pattern["bolus_pattern_table"])
    improve = improve_and_unfold(obj, args, out) if args.max_gap > 0 else None

    # 3D printing: the bolus itself, a closed solid of --thickness mm on the treatment area (after the
    # cuts), split into parts with pegs and holes, each turned to its best print direction, one STL each
    from bolus_addon.blender.mesh_io import read_face_labels
    from bolus_addon.operators.printing import part_objects

    bpy.context.view_layer.objects.active = obj
    obj.data.polygons.foreach_set("select", read_face_labels(obj.data, "bolus_patch") >= 0)
    bpy.ops.object.mode_set(mode="EDIT")
    t_shell = run_op(bpy.ops.bolus.make_shell, thickness_mm=args.thickness, resolution_mm=args.shell_resolution,
                     label=args.label)
    bpy.ops.object.mode_set(mode="OBJECT")
    bolus = bpy.data.objects[obj.name + "_bolus"]
    shell = {k: bolus[k] for k in ("bolus_thickness_mm", "bolus_volume_cm3", "bolus_thickness_min_mm",
                                   "bolus_thickness_mean_mm", "bolus_thickness_max_mm", "bolus_mass_g",
                                   "bolus_resolution_mm") if k in bolus}
    section = render_section(obj, bolus, out / "section.png")
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob is bolus)
    bpy.context.view_layer.objects.active = bolus
    t_prs = run_op(bpy.ops.bolus.print_segment, parts=args.parts, method="ABCUT", seed=0)
    t_ori = run_op(bpy.ops.bolus.orient_parts)
    (out / "parts").mkdir(exist_ok=True)
    t_stl = run_op(bpy.ops.bolus.export_parts, directory=str((out / "parts").resolve()))
    orient_table = json.loads(bolus["bolus_orient_table"])
    joints = json.loads(bolus.get("bolus_connectors", "[]"))
    connectors = [c for j in joints for c in j["connectors"]]
    parts = part_objects(bolus.name)

    table = json.loads(obj["bolus_patch_table"])
    report = {
        "mesh": EXAMPLE.name,
        "treatment_area": {"radius_mm": args.radius, "faces": int(sel.sum()), "of_faces": len(sel)},
        "smoothing_mm": smoothing,
        "sum_varpi": obj["bolus_sum_varpi"],
        "flv": obj["bolus_flv"],
        "segment": jagged_table,
        "smooth_cuts": {"borders": cuts, "patches": table["patches"]},
        "pattern": pattern_table,
        "improve": improve,
        "bolus": {**shell, "section_png": section},
        "print": {"segment": json.loads(bolus["bolus_print_table"]), "orient": orient_table,
                  "joints": joints, "stl": sorted(p.name for p in (out / "parts").glob("*.stl"))},
        "seconds": {"saliency_preview": round(t_sal, 3), "segment": round(t_seg, 3), "smooth_cuts": round(t_cut, 3),
                    "unfold": round(t_unf, 3),
                    "improve_flattenability": round(improve["seconds"], 3) if improve else None,
                    "make_shell": round(t_shell, 3), "print_segment": round(t_prs, 3), "orient_parts": round(t_ori, 3),
                    "export_parts": round(t_stl, 3),
                    "export_pattern": round(t_svg, 3)},
    }
    (out / "report.json").write_text(json.dumps(report, indent=2))
    lines = [
        f"Bolus demo: {EXAMPLE.name}, treatment area = {int(sel.sum())} faces within {args.radius:g} mm of the nose tip",
        f"Analysis smoothing {smoothing:g} mm: sum varpi = {report['sum_varpi']:.4f} rad, FLV = {report['flv']:.4g}",
    ]
    for title, rows in (
        (f"Segmentation: {len(jagged_table['patches'])} patches (asked {args.patches}, eta 5, seed 0) (Table 4-1)", jagged_table["patches"]),
        ("With smooth cut lines (Table 4-2)", table["patches"]),
    ):
        lines.append(title)
        lines.append(f"{'patch':>5} {'vertices':>9} {'edges':>7} {'triangles':>10} {'area cm2':>9} {'sum varpi':>10} {'FLV':>10}")
        for r in rows:
            lines.append(
                f"{r['patch']:>5} {r['vertices']:>9} {r['edges']:>7} {r['faces']:>10} {r['area_mm2'] / 100:>9.1f} "
                f"{r['sum_varpi']:>10.4f} {r['flv']:>10.4g}"
            )
    lines.append(f"{'border':>6} {'cut':<24} {'turning rad/mm':>16} {'moved mm':>9}")
    for b in cuts:
        lines.append(
            f"{b['a']:>3}|{b['b']:<2} {b['method']:<24} {b['turning_before']:>7.3f} -> {b['turning_after']:<6.3f} "
            f"{b['max_shift_mm']:>9.2f}"
        )
    lines.append(
        f"Pattern '{pattern.name}': EL {pattern_table['EL'] * 100:.2f} %, EA {pattern_table['EA'] * 100:.2f} %, "
        f"{pattern_table['flipped']} flipped faces (SPEC measures)"
    )
    warn_pct = pattern_table.get("warn_pct", 3.0)
    lines.append(f"Sheet {pattern_table.get('sheet_thickness_mm', 0):g} mm, Max EL {pattern_table.get('max_el', 0) * 100:g} %: "
                 f"{pattern_table.get('pieces', len(pattern_table['islands']))} pieces, {pattern_table.get('darts', 0)} darts, "
                 f"{pattern_table.get('splits', 0)} splits")
    lines.append(f"{'piece':>18} {'triangles':>10} {'EL %':>7} {'EA %':>7} {'area':>6} {'flipped':>8} {'darts':>6} "
                 f"{'R mm':>6} {'strain %':>8}  use   fit to cut (EL, EA <= {warn_pct:g} %, no flips/overlaps)")
    for r in pattern_table["islands"]:
        R = r.get("R_min_mm")
        lines.append(f"{r.get('name', r['patch']):>18} {r['faces']:>10} {r['EL'] * 100:>7.3f} {r['EA'] * 100:>7.3f} "
                     f"{r.get('area_ratio', float('nan')):>6.3f} {r['flipped']:>8} {r.get('darts', 0):>6} "
                     f"{'flat' if R is None else f'{R:.0f}':>6} {r.get('strain', 0) * 100:>8.0f}  {r.get('sheet', '-'):<5} "
                     f"{'NO: ' + r['short_advice'] if r.get('warn') else 'yes'}" + (f"  ({r['cut']})" if r["cut"] else ""))
    for u in pattern_table.get("unmet", []):
        lines.append(f"  patch {u['patch']} misses Max EL: {u['reason']}")
    bad = [r for r in pattern_table["islands"] if r.get("warn")]
    if bad:
        lines.append(f"{len(bad)} of {len(pattern_table['islands'])} pieces are not fit to cut as they are "
                     "(the unfold operator's warnings):")
        lines += [f"  {r['name']}: {r['advice']}" for r in bad]
    else:
        lines.append(f"Every piece is fit to cut (EL and EA at most {warn_pct:g} %).")
    lines += [f"  {r['name']}: {r['sheet_reason']}" for r in pattern_table["islands"] if r.get("sheet") == "print"]
    if improve:
        lines += improve_lines(improve, pattern_table)
    lines.append(f"Bolus '{bolus.name}': {shell['bolus_thickness_mm']:g} mm asked, wall "
                 f"{shell['bolus_thickness_min_mm']:.2f} / {shell['bolus_thickness_mean_mm']:.2f} / "
                 f"{shell['bolus_thickness_max_mm']:.2f} mm (min / mean / max, ray casts from the inner face), "
                 f"{shell['bolus_volume_cm3']:.1f} cm3, {shell['bolus_mass_g']:.1f} g; cross-section in section.png")
    lines.append(f"{len(joints)} joints, {len(connectors)} connectors (peg / hole radius, mm): "
                 + ", ".join(f"parts {c['parts'][0]}|{c['parts'][1]} {c['peg_radius']:.2f} / {c['hole_radius']:.2f}"
                             for c in connectors))
    lines += [f"  joint {j['parts'][0]}|{j['parts'][1]} left plain: {j['note']}" for j in joints if j["note"]]
    lines.append(f"3D print: {len(parts)} solid parts (ABcut on the skin side, SVM planes), layer {orient_table['layer_mm']:g} mm, overhang beyond 45 degrees "
                 "(Tables 6-1, 6-2; mm3)")
    lines.append(f"{'':>8} {'triangles':>10} {'area cm2':>9} {'WQ':>9} {'WU':>9} {'support':>9}  build direction")
    for r in orient_table["rows"]:
        d = r["direction"]
        lines.append(f"{r['part']:>8} {r['faces']:>10} {r['area_mm2'] / 100:>9.1f} {r['WQ']:>9.1f} {r['WU']:>9.1f} "
                     f"{r['support_volume_mm3']:>9.1f}  ({d[0]:+.2f}, {d[1]:+.2f}, {d[2]:+.2f})")
    if orient_table.get("support_ratio") is not None:
        lines.append(f"support of the parts = {orient_table['support_ratio'] * 100:.0f} % of the whole model's")
    (out / "report.txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    render_pattern(pattern, out / "pattern.png")
    render_parts([obj, pattern, bolus], parts, out / "parts.png")
    bpy.ops.wm.save_as_mainfile(filepath=str((out / "demo.blend").resolve()))
    print(f"wrote {out}/demo.blend, saliency.png, section.png, patches.png, cuts.png, cuts_before.png, cuts_after.png, pattern.png, air_gap.png, parts.png, pattern.svg, pattern.dxf, pattern_a4.pdf, parts/*.stl, report.json, report.txt")


def run_with_addon(fn) -> None:
    """fn(), then unregister the add-on: plain bpy 4.2 segfaults and 4.5 hangs at exit
    while an add-on stays registered."""
    try:
        fn()
    finally:
        if hasattr(bpy.types.Scene, "bolus"):
            import bolus_addon

            bolus_addon.unregister()


if __name__ == "__main__":
    run_with_addon(main)
