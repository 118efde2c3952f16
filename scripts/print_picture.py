"""The README's picture of oriented print parts (docs/print_parts.png).

    .venv/bin/python scripts/print_picture.py [--mesh ../shared/meshes/fish.obj] [--out docs/print_parts.png]

Imports a closed model (default: Keenan Crane's public-domain "Blub" fish from
../shared/meshes, scaled to 150 mm long), runs bolus.print_segment(parts=3) and
bolus.orient_parts, and renders, side by side, the whole model in its own best print
direction and its parts on the build plate, overhang faces (n.b < -cos 45 deg) in red.
The same operators a user runs; nothing here is measured (see bench/print_bench.py).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Matrix  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mesh", default=str(ROOT.parent / "shared" / "meshes" / "fish.obj"))
    ap.add_argument("--length-mm", type=float, default=150.0, help="scale the model to this longest side")
    ap.add_argument("--parts", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "docs" / "print_parts.png"))
    ap.add_argument("--resolution", type=int, default=420)
    args = ap.parse_args(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])

    bpy.ops.wm.read_factory_settings(use_empty=True)
    import bolus_addon

    bolus_addon.register()
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 0.001  # 1 unit = 1 mm
    bpy.ops.wm.obj_import(filepath=args.mesh)
    ob = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = ob
    co = np.array([v.co for v in ob.data.vertices])
    ob.scale = [args.length_mm / float(np.ptp(co, axis=0).max())] * 3
    bpy.ops.object.transform_apply(location=False, rotation=True, scale=True)
    assert bpy.ops.bolus.print_segment(parts=args.parts) == {"FINISHED"}
    from bolus_addon.print_ops import PART_INFIX, part_objects

    # the whole model as one part, in its own best direction (a copy without part labels)
    whole = ob.copy()
    whole.data = ob.data.copy()
    whole.name = "whole"
    scene.collection.objects.link(whole)
    whole.data.attributes.remove(whole.data.attributes["bolus_print_part"])
    bpy.context.view_layer.objects.active = whole
    assert bpy.ops.bolus.orient_parts() == {"FINISHED"}
    bpy.context.view_layer.objects.active = ob
    assert bpy.ops.bolus.orient_parts() == {"FINISHED"}
    ob.hide_render = whole.hide_render = True
    (whole_part,) = part_objects("whole")
    parts = part_objects(ob.name)
    # the whole model to the left of the parts, 30 mm apart
    pts = np.array([p.matrix_world @ v.co for p in parts for v in p.data.vertices])
    wpts = np.array([whole_part.matrix_world @ v.co for v in whole_part.data.vertices])
    shift = pts[:, 0].min() - wpts[:, 0].max() - 30.0
    whole_part.matrix_world = Matrix.Translation((shift, 0.0, 0.0)) @ whole_part.matrix_world
    from bolus_addon.mesh_io import show_colors

    allpts = []
    for p in [whole_part, *parts]:
        show_colors(p.data, "bolus_overhang")
        allpts += [p.matrix_world @ v.co for v in p.data.vertices]
    allpts = np.array(allpts)
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    pad = 10.0
    # the build plate as a thin slab under z = 0 (seen from slightly below, so that the
    # downward faces that need support are visible)
    plate = bpy.data.meshes.new("plate")
    x0, x1, y0, y1 = lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad
    plate.from_pydata([(x0, y0, -2), (x1, y0, -2), (x1, y1, -2), (x0, y1, -2), (x0, y0, 0), (x1, y0, 0), (x1, y1, 0),
                       (x0, y1, 0)], [], [(0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7), (4, 5, 6, 7), (3, 2, 1, 0)])
    scene.collection.objects.link(bpy.data.objects.new("plate", plate))
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "STUDIO"
    scene.display.shading.color_type = "VERTEX"
    scene.display.render_aa = "8"
    rx = int(args.resolution * (hi[0] - lo[0] + 2 * pad) / max(hi[2] - lo[2] + (hi[1] - lo[1]) * 0.2 + 2 * pad, 1.0))
    scene.render.resolution_x, scene.render.resolution_y = max(rx, args.resolution), args.resolution
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    cam.data.type = "ORTHO"
    tilt = -0.12  # from slightly below the plate's top
    centre = (lo + hi) / 2
    dist = 3.0 * float(np.linalg.norm(hi - lo))
    cam.rotation_euler = (np.pi / 2 - tilt, 0.0, 0.0)
    cam.location = (float(centre[0]), float(centre[1] - dist * np.cos(tilt)), float(centre[2] + dist * np.sin(tilt)))
    cam.data.clip_end = 10 * dist
    w = float(hi[0] - lo[0]) + 2 * pad
    h = float(hi[2] - lo[2]) + float(hi[1] - lo[1]) * abs(np.sin(tilt)) + 2 * pad
    rx, ry = scene.render.resolution_x, scene.render.resolution_y
    cam.data.ortho_scale = max(w, h * rx / ry) * 1.05
    scene.render.filepath = str(Path(args.out).resolve())
    bpy.ops.render.render(write_still=True)
    import json

    for name, src in (("whole", whole), (ob.name, ob)):
        t = json.loads(src["bolus_orient_table"])
        for r in t["rows"][1 if name == "whole" else 0:]:
            print(f"{name:>10} {r['part']:>7}: WQ {r['WQ']:9.1f}  WU {r['WU']:10.1f}  support {r['support_volume_mm3']:10.1f} mm3")
    print(f"wrote {args.out} ({PART_INFIX.strip('_')}s: {len(parts)})")


if __name__ == "__main__":
    main()
