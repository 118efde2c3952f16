"""Bolus from the command line: a planning system's STL in, every output in a folder.

    .venv/bin/python scripts/bolus_cli.py skin.stl --point 0 -95 20 --out case42
    blender --background --python scripts/bolus_cli.py -- skin.stl --point 0 -95 20 --out case42
    .venv/bin/python scripts/bolus_cli.py --ct CT_FOLDER --point 0 -95 20 --steps shell,print --out case42

Imports the mesh (STL, OBJ or PLY; --units says the file's unit) into a scene where 1 unit = 1 mm,
picks the treatment area (--point X Y Z with --radius: bolus.select_area with the 3D cursor there;
--sphere X Y Z R: the faces whose centroid lies in the sphere; neither: the whole mesh; coordinates in
mm in the file's frame) and runs the --steps in this order:

  preview  bolus.saliency_preview (--smoothing-mm)
  segment  bolus.segment (--patches, --eta, --seed, --smoothing-mm)
  cuts     bolus.smooth_cuts                                   (needs segment: added)
  improve  bolus.improve_flattenability (--max-gap-mm, --seed): <name>_improved; unfold then
           unfolds the improved surface
  unfold   bolus.unfold (--max-el %, --sheet-thickness-mm)
  export   bolus.export_pattern (--page, --label, --seam-allowance-mm): pattern.svg, pattern.dxf,
           pattern_<page>.pdf (pattern.pdf with --page NONE)    (needs unfold: added)
  shell    bolus.make_shell (--thickness-mm, --resolution-mm, --label): <name>_bolus
  print    bolus.print_segment (--parts, --seed, --print-method), bolus.orient_parts, bolus.export_parts on the
           bolus: parts/*.stl (binary, mm, closed)              (needs shell: added)
  rtstruct bolus.export_rtstruct on the planning CT: RS_bolus.dcm (or --rtstruct-out) (needs shell: added;
           added itself with --ct)

With --ct DIR instead of a mesh file the skin is bolus.import_dicom of the planning CT's folder
(patient coordinates LPS, mm: --point and --sphere are in them); report.json's input then records
the folder, patient ID, study, CT series and frame of reference.

and writes report.json, result.blend and, with --png, surface.png (the skin alone, seen along
the treatment area's mean normal, coloured by patch), pattern.png, parts.png.  report.json holds: input
(path, units, sha256, unchanged), area, steps / steps_added / steps_done, results (per step: the
tables and figures the operators leave as custom properties, JSON decoded), reports (every INFO /
WARNING / ERROR line with its step and operator), warnings, seconds (per operator), step_seconds,
outputs and error (null, or the step and message).
Exit code 0 on success; 2 when an operator refuses or the area selects nothing (the message on
stderr, report.json written with what finished and "error") or an argument is wrong (argparse);
1 on an unexpected error (traceback on stderr, report.json written).  The input file is only read.
"""
from __future__ import annotations

import argparse
import ctypes
import hashlib
import json
import os
import sys
import tempfile
import threading
import time
import traceback
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

STEPS = ("preview", "segment", "cuts", "improve", "unfold", "export", "shell", "print", "rtstruct")
DEFAULT_STEPS = "preview,segment,cuts,unfold,export"
#: a step and the earlier step it cannot do without (added when missing)
NEEDS = {"cuts": "segment", "export": "unfold", "print": "shell", "rtstruct": "shell"}
UNITS_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
FORMATS = (".stl", ".obj", ".ply")
#: exit code of a refusal (an operator's, or a treatment area that selects nothing) and of argparse
EXIT_REFUSED = 2


class StepRefused(Exception):
    """A step could not be done; the message says why (an operator's ERROR report or our own check)."""


def parse_args(argv=None) -> argparse.Namespace:
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    ap = argparse.ArgumentParser(prog="bolus_cli.py", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("stl", type=Path, nargs="?", help="the skin surface: .stl (binary or ASCII), .obj or .ply; "
                                                      "only read (or --ct)")
    ap.add_argument("--ct", type=Path, help="a planning CT's DICOM folder: the skin from it (instead of a mesh file)")
    ap.add_argument("--rtstruct-out", type=Path, help="the RTSTRUCT to write (default OUT/RS_bolus.dcm; with --ct)")
    ap.add_argument("--units", choices=sorted(UNITS_MM), default="mm", help="the file's length unit (default mm)")
    area = ap.add_mutually_exclusive_group()
    area.add_argument("--point", type=float, nargs=3, metavar=("X", "Y", "Z"),
                      help="treatment area centre in mm (file frame): bolus.select_area with the 3D cursor there")
    area.add_argument("--sphere", type=float, nargs=4, metavar=("X", "Y", "Z", "R"),
                      help="treatment area: the faces whose centroid lies within this sphere (mm, file frame)")
    ap.add_argument("--radius", type=float, default=45.0,
                    help="with --point: the area's radius in mm measured along the skin (default 45)")
    ap.add_argument("--steps", default=DEFAULT_STEPS,
                    help=f"comma list from {','.join(STEPS)} (default {DEFAULT_STEPS}); run in that order, "
                         "a missing prerequisite (cuts<-segment, export<-unfold, print<-shell) is added")
    ap.add_argument("--out", type=Path, default=Path("bolus_out"), help="output folder (created; default bolus_out)")
    ap.add_argument("--png", action="store_true", help="also write pictures: surface.png, pattern.png, parts.png")
    ap.add_argument("--png-height", type=int, default=900, help="picture height in pixels (default 900)")
    g = ap.add_argument_group("step parameters (default: the operator's)")
    g.add_argument("--smoothing-mm", type=float, help="preview/segment: analysis smoothing scale in mm")
    g.add_argument("--patches", type=int, help="segment: number of patches")
    g.add_argument("--eta", type=float, help="segment: eta, the weight of flattenability in the features")
    g.add_argument("--seed", type=int, help="segment/improve/print: random seed")
    g.add_argument("--max-gap-mm", type=float, help="improve: largest air gap in mm")
    g.add_argument("--max-el", type=float, help="unfold: EL target in %% (darts and splits above it; 0 = off)")
    g.add_argument("--sheet-thickness-mm", type=float,
                   help="unfold: sheet thickness in mm (pattern of the mid-surface; 0 = the skin)")
    g.add_argument("--page", type=str.upper, choices=("NONE", "A4", "LETTER"), default="A4",
                   help="export: PDF tiled on this page size (default A4)")
    g.add_argument("--label", help="export/shell: label printed on the pieces and engraved on the bolus")
    g.add_argument("--seam-allowance-mm", type=float, help="export: seam allowance around each piece in mm")
    g.add_argument("--thickness-mm", type=float, help="shell: bolus thickness in mm")
    g.add_argument("--resolution-mm", type=float, help="shell: voxel resolution in mm (coarser is faster)")
    g.add_argument("--parts", type=int, help="print: number of print parts")
    g.add_argument("--print-method", choices=("ABCUT", "RATIOCUT", "LEARNED"),
                   help="print: how to split (LEARNED finds the number of parts itself)")
    g.add_argument("--time-limit-s", type=float, default=60.0,
                   help="a step estimated to take longer is refused with what to do instead (default 60; 0 = no limit)")
    args = ap.parse_args(argv)
    if (args.stl is None) == (args.ct is None):
        ap.error("give the skin as a mesh file or as --ct FOLDER (one of the two)")
    if args.ct is not None:
        if not args.ct.is_dir():
            ap.error(f"--ct {args.ct}: no such folder")
        if "rtstruct" not in args.steps.split(","):
            args.steps += ",rtstruct"
    elif not args.stl.is_file():
        ap.error(f"{args.stl}: no such file")
    elif args.stl.suffix.lower() not in FORMATS:
        ap.error(f"{args.stl}: a {'/'.join(FORMATS)} file is needed, got '{args.stl.suffix}'")
    if args.radius <= 0:
        ap.error(f"--radius must be positive, got {args.radius:g}")
    if not args.time_limit_s >= 0:
        ap.error(f"--time-limit-s must be 0 (no limit) or positive, got {args.time_limit_s:g}")
    if args.sphere is not None and args.sphere[3] <= 0:
        ap.error(f"--sphere radius must be positive, got {args.sphere[3]:g}")
    try:
        args.plan, args.added = plan_steps(args.steps)
    except ValueError as exc:
        ap.error(str(exc))
    return args


def plan_steps(text: str) -> tuple[list[str], list[str]]:
    """'export,print' -> (['unfold', 'export', 'shell', 'print'], ['unfold', 'shell']): the steps in
    the canonical order with every missing prerequisite added, and those added."""
    asked = [s.strip().lower() for s in text.split(",") if s.strip()]
    bad = [s for s in asked if s not in STEPS]
    if bad or not asked:
        raise ValueError(f"--steps: unknown step(s) {', '.join(bad) or '(none given)'}; choose from {', '.join(STEPS)}")
    todo = set(asked)
    added = []
    for s in STEPS[::-1]:  # a prerequisite comes earlier in STEPS
        if s in todo and NEEDS.get(s) and NEEDS[s] not in todo:
            todo.add(NEEDS[s])
            added.append(NEEDS[s])
    return [s for s in STEPS if s in todo], [s for s in STEPS if s in added]


# ---------------------------------------------------------------------------------------------
# the operators' INFO / WARNING lines: Blender prints them on the process's stdout (C level)


@contextmanager
def captured_stdout():
    """Capture fd 1 (Python's prints and Blender's C-level report lines) into a list of lines, echoed on
    the real stdout as they come (a thread tails the capture file, so long steps still show progress)."""
    lines: list[str] = []
    libc = _libc()
    sys.stdout.flush()
    libc.fflush(None)
    saved = os.dup(1)
    fd, path = tempfile.mkstemp(prefix="bolus_cli_", suffix=".log")
    reader = open(path, "rb")
    chunks: list[bytes] = []
    stop = threading.Event()

    def echo():
        data = reader.read()
        if data:
            chunks.append(data)
            os.write(saved, data)

    def tail():
        while not stop.wait(0.25):
            echo()

    os.dup2(fd, 1)
    thread = threading.Thread(target=tail, daemon=True)
    thread.start()
    try:
        yield lines
    finally:
        sys.stdout.flush()
        libc.fflush(None)
        stop.set()
        thread.join()
        os.dup2(saved, 1)
        echo()
        for close in (lambda: os.close(saved), lambda: os.close(fd), reader.close, lambda: os.unlink(path)):
            try:
                close()
            except OSError:
                pass
        lines.extend(b"".join(chunks).decode("utf-8", "replace").splitlines())


def _libc():
    """The C library whose stdout buffer Blender writes its report lines to (fflush(NULL) empties it);
    a stand-in where it cannot be loaded (the lines then may reach the console uncollected)."""
    for name in (None, "ucrtbase", "msvcrt"):
        try:
            return ctypes.CDLL(name)
        except (OSError, TypeError):  # TypeError: CDLL(None) on Windows
            continue

    class _NoLibc:
        @staticmethod
        def fflush(_):
            return 0

    return _NoLibc()


REPORT_PREFIXES = {"Info: ": "INFO", "Warning: ": "WARNING", "Error: ": "ERROR"}


def report_lines(lines: list[str]) -> list[dict]:
    """[{'type': 'INFO'|'WARNING'|'ERROR', 'message': ...}] from captured output (progress lines and
    Blender's timers left out; a line without a prefix continues the report before it)."""
    out: list[dict] = []
    for line in lines:
        kind = next((k for k in REPORT_PREFIXES if line.startswith(k)), None)
        if kind is not None:
            out.append({"type": REPORT_PREFIXES[kind], "message": line[len(kind):].strip()})
        elif out and line.strip() and not line.startswith(("bolus.", "Timer ", "Read ", "Info ", "Saved ")):
            out[-1]["message"] += "\n" + line.rstrip()
    return out


# ---------------------------------------------------------------------------------------------


class Run:
    """One CLI run: the scene, the objects made so far, and report.json's content."""

    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.out: Path = args.out
        source = {"ct": str(args.ct.resolve())} if args.ct is not None else \
            {"path": str(args.stl.resolve()), "units": args.units, "sha256": sha256(args.stl)}
        self.report: dict = {
            "input": source,
            "steps": args.plan, "steps_added": args.added, "steps_done": [],
            "area": None, "results": {}, "reports": [], "warnings": [], "seconds": {}, "step_seconds": {},
            "outputs": [],
            "error": None,
        }
        self.skin = None  # the imported mesh (its treatment area is the region)
        self.area = None  # (p,) bool: the treatment area's polygons, None = the whole mesh
        self.surface = None  # the object unfold works on (the skin, or <skin>_improved)

    # -- running an operator ----------------------------------------------------------------
    def op(self, step: str, op, **kw) -> float:
        """op(**kw) with its reports collected; a refusal raises StepRefused(message)."""
        kw = {k: v for k, v in kw.items() if v is not None}
        name = op.idname_py()
        t = time.perf_counter()
        error = None
        with captured_stdout() as lines:
            try:
                result = op(**kw)
            except RuntimeError as exc:
                error = str(exc).strip()
                result = {"CANCELLED"}
        seconds = time.perf_counter() - t
        for r in report_lines(lines):
            self.report["reports"].append({"step": step, "operator": name, **r})
            if r["type"] == "WARNING":
                self.report["warnings"].append(f"{name}: {r['message']}")
        key = name.replace("bolus.", "")
        self.report["seconds"][key] = round(self.report["seconds"].get(key, 0.0) + seconds, 3)
        if error is not None or result != {"FINISHED"}:
            msg = error or f"{name} returned {sorted(result)}"
            raise StepRefused(msg[len("Error: "):] if msg.startswith("Error: ") else msg)
        return seconds

    def activate(self, obj, region: bool) -> None:
        """obj active and alone selected, in Object Mode; with region=True and a treatment area, in
        Edit Mode with the area's faces selected (the region of the next operator)."""
        if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        for ob in bpy.context.view_layer.objects:
            ob.select_set(ob is obj)
        bpy.context.view_layer.objects.active = obj
        mask = self.region_mask(obj) if region else None
        if mask is not None:
            me = obj.data
            me.polygons.foreach_set("select", mask)
            me.update()
            bpy.ops.object.mode_set(mode="EDIT")
            bpy.ops.mesh.select_mode(type="FACE")

    def region_mask(self, obj):
        """The treatment area on obj: its patches when segmented (they follow smooth_cuts' re-cut),
        else the area as selected; None for the whole mesh."""
        if self.area is None:
            return None
        from bolus_addon.blender.mesh_io import read_face_labels

        if "bolus_patch" in obj.data.attributes:
            return read_face_labels(obj.data, "bolus_patch") >= 0
        if len(obj.data.polygons) == len(self.area):  # the skin, or its improved copy
            return self.area
        raise StepRefused(f"internal: the treatment area is lost on '{obj.name}'")

    def done(self, step: str, **results) -> None:
        self.report["results"][step] = results
        self.report["steps_done"].append(step)

    def output(self, path: Path) -> None:
        self.report["outputs"].append(str(path.relative_to(self.out)))

    # -- the steps ------------------------------------------------------------------------------
    def load(self) -> None:
        a = self.args
        from demo import mm_scene

        mm_scene()
        bpy.context.scene.bolus.time_limit_s = a.time_limit_s
        if a.ct is not None:
            return self.load_ct()
        scale = UNITS_MM[a.units]
        path = str(a.stl.resolve())
        ext = a.stl.suffix.lower()
        before = set(bpy.data.objects)
        with captured_stdout():
            try:
                if ext == ".stl":
                    bpy.ops.wm.stl_import(filepath=path, global_scale=scale, use_scene_unit=False)
                elif ext == ".obj":  # the file's own axes (no Y-up conversion), so --point is in its frame
                    bpy.ops.wm.obj_import(filepath=path, global_scale=scale, forward_axis="Y", up_axis="Z")
                else:
                    bpy.ops.wm.ply_import(filepath=path, global_scale=scale, forward_axis="Y", up_axis="Z")
            except RuntimeError as exc:
                raise StepRefused(f"{a.stl.name} could not be read: {str(exc).strip()}") from None
        new = [ob for ob in bpy.data.objects if ob not in before and ob.type == "MESH"]
        if len(new) != 1:
            raise StepRefused(f"{a.stl.name}: expected one mesh, the importer made {len(new)}")
        obj = new[0]
        if len(obj.data.polygons) == 0:
            raise StepRefused(f"{a.stl.name}: no faces read ({len(obj.data.vertices)} vertices): "
                              "the bolus tools need a surface mesh")
        self.activate(obj, region=False)
        bpy.ops.object.transform_apply(location=False, rotation=True, scale=True)  # vertices in mm
        self.skin = self.surface = obj
        self.report["input"].update(object=obj.name, vertices=len(obj.data.vertices), faces=len(obj.data.polygons))

    def load_ct(self) -> None:
        """The skin from the planning CT (bolus.import_dicom): patient coordinates, mm."""
        self.op("load", bpy.ops.bolus.import_dicom, directory=str(self.args.ct.resolve()))
        obj = bpy.context.active_object
        self.skin = self.surface = obj
        ids = {k.removeprefix("bolus_dicom_"): obj[k] for k in obj.keys() if k.startswith("bolus_dicom_")}
        self.report["input"].update(object=obj.name, vertices=len(obj.data.vertices), faces=len(obj.data.polygons),
                                    patient_id=ids.get("patient_id"), study=ids.get("study_uid"),
                                    series=ids.get("ct_series_uid"), frame=ids.get("frame_uid"))

    def select_area(self) -> None:
        a, obj = self.args, self.skin
        if a.point is not None:
            bpy.context.scene.cursor.location = tuple(a.point)
            self.activate(obj, region=False)
            self.op("area", bpy.ops.bolus.select_area, radius_mm=a.radius)
            bpy.ops.object.mode_set(mode="OBJECT")
            sel = np.zeros(len(obj.data.polygons), dtype=bool)
            obj.data.polygons.foreach_get("select", sel)
            self.report["area"] = {"point_mm": a.point, "radius_mm": a.radius}
        elif a.sphere is not None:
            me = obj.data
            c = np.zeros(len(me.polygons) * 3)
            me.polygons.foreach_get("center", c)  # mm: the transform was applied on import
            c = c.reshape(-1, 3)
            centre, r = np.array(a.sphere[:3]), a.sphere[3]
            sel = np.linalg.norm(c - centre, axis=1) <= r
            if not sel.any():
                d = float(np.linalg.norm(c - centre, axis=1).min())
                raise StepRefused(f"no face centroid lies within the sphere of {r:g} mm around "
                                  f"({', '.join(f'{x:g}' for x in centre)}) mm: the nearest is {d:.1f} mm away; "
                                  "give the centre on the skin in the file's frame (mm, after --units)")
            self.report["area"] = {"sphere_mm": a.sphere}
        else:
            self.report["area"] = {"whole_mesh": True}
            return
        self.area = sel
        self.report["area"].update(faces=int(sel.sum()), of_faces=len(sel))

    def step_preview(self) -> None:
        self.activate(self.skin, region=True)
        self.op("preview", bpy.ops.bolus.saliency_preview, smoothing_mm=self.args.smoothing_mm)
        self.done("preview", **props(self.skin, "bolus_sum_varpi", "bolus_flv"))

    def step_segment(self) -> None:
        a = self.args
        self.activate(self.skin, region=True)
        self.op("segment", bpy.ops.bolus.segment, patches=a.patches, eta=a.eta, seed=a.seed,
                smoothing_mm=a.smoothing_mm)
        self.done("segment", **props(self.skin, "bolus_patch_table", "bolus_sum_varpi", "bolus_flv"))

    def step_cuts(self) -> None:
        self.activate(self.skin, region=False)  # smooth_cuts works on the patches
        self.op("cuts", bpy.ops.bolus.smooth_cuts)
        self.done("cuts", **props(self.skin, "bolus_cut_table", "bolus_patch_table"))

    def step_improve(self) -> None:
        a = self.args
        self.activate(self.skin, region=True)
        self.op("improve", bpy.ops.bolus.improve_flattenability, max_gap_mm=a.max_gap_mm, seed=a.seed)
        self.surface = bpy.data.objects[self.skin.name + "_improved"]
        self.done("improve", object=self.surface.name, **props(self.surface))

    def step_unfold(self) -> None:
        a = self.args
        self.activate(self.surface, region=True)
        self.op("unfold", bpy.ops.bolus.unfold, max_el=a.max_el, sheet_thickness_mm=a.sheet_thickness_mm)
        pattern = bpy.data.objects[self.surface.name + "_pattern"]
        self.pattern = pattern
        self.done("unfold", object=pattern.name, source=self.surface.name, **props(pattern))

    def step_export(self) -> None:
        a = self.args
        pdf = "pattern.pdf" if a.page == "NONE" else f"pattern_{a.page.lower()}.pdf"
        files = []
        for name in ("pattern.svg", "pattern.dxf", pdf):
            path = (self.out / name).resolve()
            self.activate(self.pattern, region=False)  # the active pattern is the one exported
            self.op("export", bpy.ops.bolus.export_pattern, filepath=str(path), label=a.label,
                    seam_allowance_mm=a.seam_allowance_mm, **({"page": a.page} if name == pdf else {}))
            if not path.is_file():
                raise StepRefused(f"bolus.export_pattern finished but wrote no {name}")
            self.output(self.out / name)
            files.append(name)
        self.done("export", files=files)

    def step_shell(self) -> None:
        a = self.args
        self.activate(self.skin, region=True)
        self.op("shell", bpy.ops.bolus.make_shell, thickness_mm=a.thickness_mm, resolution_mm=a.resolution_mm,
                label=a.label)
        self.bolus = bpy.data.objects[self.skin.name + "_bolus"]
        self.done("shell", object=self.bolus.name, **props(self.bolus))

    def step_print(self) -> None:
        from bolus_addon.operators.printing import part_objects

        a = self.args
        self.activate(self.bolus, region=False)
        self.op("print", bpy.ops.bolus.print_segment, parts=a.parts, seed=a.seed, method=a.print_method)
        self.op("print", bpy.ops.bolus.orient_parts)
        parts_dir = self.out / "parts"
        parts_dir.mkdir(exist_ok=True)
        before = set(parts_dir.glob("*.stl"))
        self.activate(self.bolus, region=False)
        self.op("print", bpy.ops.bolus.export_parts, directory=str(parts_dir.resolve()))
        stl = sorted(set(parts_dir.glob("*.stl")) - before) or sorted(parts_dir.glob("*.stl"))
        for p in stl:
            self.output(p)
        parts = part_objects(self.bolus.name)
        self.done("print", parts=[p.name for p in parts], stl=[p.name for p in stl],
                  **props(self.bolus, "bolus_print_table", "bolus_orient_table", "bolus_connectors"),
                  part_figures=[{"object": p.name, **props(p)} for p in parts])

    def step_rtstruct(self) -> None:
        a = self.args
        path = (a.rtstruct_out or self.out / "RS_bolus.dcm").resolve()
        self.activate(self.bolus, region=False)
        self.op("rtstruct", bpy.ops.bolus.export_rtstruct, filepath=str(path))
        if path.is_relative_to(self.out.resolve()):
            self.output(self.out / path.relative_to(self.out.resolve()))
        self.done("rtstruct", file=str(path), frame=self.bolus.get("bolus_dicom_frame_uid"))

    def pictures(self) -> None:
        """surface.png (the skin alone, seen along the treatment area's mean normal, coloured by patch
        or flattenability), pattern.png (area distortion), parts.png (overhangs): demo.py's renderers."""
        import demo

        demo.setup_render(self.skin, self.args.png_height)
        with captured_stdout():
            colours = self.skin.data.color_attributes
            colour = next((c for c in ("bolus_patch_color", "bolus_saliency_color") if c in colours), None)
            if colour is not None:
                self.render_surface(colour, self.out / "surface.png")
                self.output(self.out / "surface.png")
            pattern = getattr(self, "pattern", None)
            if pattern is not None and "bolus_area_distortion" in pattern.data.color_attributes:
                demo.render_pattern(pattern, self.out / "pattern.png")
                self.output(self.out / "pattern.png")
            bolus = getattr(self, "bolus", None)
            if "print" in self.report["steps_done"]:
                from bolus_addon.operators.printing import part_objects

                hide = [ob for ob in bpy.context.scene.objects if ob.type == "MESH"
                        and ob not in part_objects(bolus.name)]
                demo.render_parts(hide, part_objects(bolus.name), self.out / "parts.png")
                self.output(self.out / "parts.png")

    def render_surface(self, colour: str, path: Path) -> None:
        """The skin alone (other objects hidden), the camera looking at the treatment area (or the whole
        mesh) against its area-weighted mean normal, framing it."""
        import demo
        from mathutils import Matrix

        scene, obj = bpy.context.scene, self.skin
        me = obj.data
        n = len(me.polygons)
        centre, normal, area = (np.zeros(n * 3), np.zeros(n * 3), np.zeros(n))
        me.polygons.foreach_get("center", centre)
        me.polygons.foreach_get("normal", normal)
        me.polygons.foreach_get("area", area)
        mask = self.region_mask(obj)
        mask = np.ones(n, dtype=bool) if mask is None else mask
        centre, normal, area = centre.reshape(-1, 3)[mask], normal.reshape(-1, 3)[mask], area[mask]
        view = (normal * area[:, None]).sum(axis=0)
        view = view / np.linalg.norm(view) if np.linalg.norm(view) > 1e-9 else np.array([0.0, -1.0, 0.0])
        up = np.array([0.0, 0.0, 1.0]) if abs(view[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
        right = np.cross(up, view)
        right /= np.linalg.norm(right)
        up = np.cross(view, right)
        lo, hi = centre.min(axis=0), centre.max(axis=0)
        mid = (lo + hi) / 2
        rel = centre - mid
        w, h = np.ptp(rel @ right), np.ptp(rel @ up)
        rx, ry = scene.render.resolution_x, scene.render.resolution_y
        cam = scene.camera
        cam.rotation_mode = "QUATERNION"
        cam.rotation_quaternion = Matrix(np.c_[right, up, view].tolist()).to_quaternion()  # looks along -view
        # the ortho scale spans the longer side of the image (sensor fit AUTO)
        cam.data.ortho_scale = float((max(w, h * rx / ry) if rx >= ry else max(h, w * ry / rx)) * 1.15) or 1.0
        size = float(np.linalg.norm(np.ptp(np.array([v.co for v in me.vertices]), axis=0)))
        cam.location = tuple(float(x) for x in mid + view * 2.0 * size)
        cam.data.clip_end = 5.0 * size
        others = [ob for ob in scene.objects if ob is not obj and ob.type == "MESH" and not ob.hide_render]
        for ob in others:
            ob.hide_render = True
        demo.render(obj, colour, path)
        for ob in others:
            ob.hide_render = False

    def execute(self) -> int:
        code = 0
        step = "load"
        try:
            self.load()
            step = "area"
            self.select_area()
            for step in self.args.plan:
                t = time.perf_counter()
                getattr(self, f"step_{step}")()
                self.report["step_seconds"][step] = round(time.perf_counter() - t, 3)
            if self.args.png:
                step = "png"
                self.pictures()
        except StepRefused as exc:
            self.report["error"] = {"step": step, "message": str(exc)}
            print(f"bolus_cli: {step} refused: {exc}", file=sys.stderr)
            code = EXIT_REFUSED
        except Exception as exc:  # a bug of ours: said, and the report still written
            traceback.print_exc()
            self.report["error"] = {"step": step, "message": f"{type(exc).__name__}: {exc}"}
            print(f"bolus_cli: {step} failed: {type(exc).__name__}: {exc}", file=sys.stderr)
            code = 1
        self.finish()
        return code

    def finish(self) -> None:
        try:
            if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
                bpy.ops.object.mode_set(mode="OBJECT")
            if self.skin is not None:
                blend = (self.out / "result.blend").resolve()
                with captured_stdout():
                    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
                self.output(self.out / "result.blend")
        except Exception as exc:
            self.report["warnings"].append(f"result.blend not written: {exc}")
        if self.args.stl is not None:
            self.report["input"]["unchanged"] = sha256(self.args.stl) == self.report["input"]["sha256"]
        self.report["outputs"].append("report.json")
        (self.out / "report.json").write_text(json.dumps(self.report, indent=2, default=_json_default))
        print(f"bolus_cli: wrote {', '.join(self.report['outputs'])} into {self.out}")


def props(obj, *keys) -> dict:
    """obj's custom properties named keys (default: every bolus_*), JSON strings decoded."""
    out = {}
    for k in keys or [k for k in obj.keys() if k.startswith("bolus_")]:
        if k not in obj:
            continue
        v = obj[k]
        if hasattr(v, "to_list"):
            v = v.to_list()
        elif hasattr(v, "to_dict"):
            v = v.to_dict()
        elif isinstance(v, str) and v[:1] in "[{":
            try:
                v = json.loads(v)
            except ValueError:
                pass
        out[k] = v
    return out


def _json_default(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def main(argv=None) -> int:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.added:
        print(f"bolus_cli: step '{name}' added (a later step needs it)")
    return Run(args).execute()


def run_with_addon(fn) -> int:
    """fn(), then unregister the add-on: plain bpy 4.2 segfaults and 4.5 hangs at exit while an
    add-on stays registered."""
    try:
        return fn()
    finally:
        if hasattr(bpy.types.Scene, "bolus"):
            import bolus_addon

            bolus_addon.unregister()


if __name__ == "__main__":
    sys.exit(run_with_addon(main))
