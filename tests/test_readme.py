"""README.md checked against the code: what it names exists, what it shows runs.

The plain checks read files only; the two Blender checks compare the operator table's
defaults with the registered operators and run the scripting recipe as written on an STL
in millimetres.
"""
from __future__ import annotations

import ast
import re
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: the developers' page the README links to: venvs, tests, benchmarks, the module layout
DEVELOPMENT = ROOT / "docs" / "development.md"
#: the README stays short enough to read in one sitting (about 15 KB)
MAX_README_BYTES = 16_000


@pytest.fixture(scope="module")
def text() -> str:
    return README.read_text(encoding="utf-8")


def registered_operators() -> set[str]:
    """'saliency_preview', ... : every bl_idname = "bolus.X" in the Blender layer."""
    names = set()
    for path in (ROOT / "bolus_addon").rglob("*.py"):
        names |= set(re.findall(r'bl_idname\s*=\s*"bolus\.(\w+)"', path.read_text(encoding="utf-8")))
    return names


def operator_table(text: str) -> dict[str, str]:
    """{operator: its argument list} from the rows of the README's table of operators."""
    return dict(re.findall(r"^\| `(\w+)\(([^)]*)\)` \|", text, flags=re.M))


def test_make_demo_and_make_test_in_the_first_40_lines(text):
    head = "\n".join(text.splitlines()[:40])
    assert "make demo" in head and "make test" in head


def test_readme_is_short(text):
    assert len(text.encode("utf-8")) < MAX_README_BYTES


def test_every_local_link_and_picture_exists(text):
    targets = [t for t in re.findall(r"\]\(([^)\s]+)\)", text) if not t.startswith(("http", "#"))]
    assert targets, "the README shows pictures of the steps"
    missing = [t for t in targets if not (ROOT / t).exists()]
    assert not missing


def test_pictures_are_small(text):
    for t in re.findall(r"!\[[^\]]*\]\(([^)\s]+\.png)\)", text):
        data = (ROOT / t).read_bytes()
        width = struct.unpack(">I", data[16:20])[0]
        assert width <= 900 and len(data) < 150_000, t


def test_every_picture_caption_names_its_mesh(text):
    for caption in re.findall(r"!\[([^\]]*)\]\(", text):
        assert re.search(r"ICT face|fish|Nefertiti|makehuman", caption), caption


def test_operators_named_are_the_registered_ones(text):
    ops = registered_operators()
    named = set(re.findall(r"bpy\.ops\.bolus\.(\w+)\(", text)) | set(operator_table(text))
    assert named <= ops, f"not operators: {sorted(named - ops)}"
    assert set(operator_table(text)) == ops, "the operator table lists every operator once"


#: Blender's own menus and fields the steps name (not ours to check)
BLENDER_UI = {"File ‣ Import ‣ STL", "Scale", "Scene Unit", "Scene Properties ‣ Units ‣ Unit Scale"}


def test_sidebar_names_are_the_panels(text):
    """Every button is named as the sidebar labels it, and every *name* in the steps is a
    label of the panel, a property, a button, or one of Blender's own (BLENDER_UI)."""
    ui = set()  # every string constant of the Blender layer (labels, names, table heads)
    for path in (ROOT / "bolus_addon").rglob("*.py"):
        ui |= {n.value for n in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
               if isinstance(n, ast.Constant) and isinstance(n.value, str)}
    flat = " ".join(text.split())
    labels = set()
    for path in (ROOT / "bolus_addon").rglob("*.py"):
        labels |= set(re.findall(r'bl_label\s*=\s*"([^"]+)"', path.read_text(encoding="utf-8")))
    assert labels and all(label in flat for label in labels), sorted(lab for lab in labels if lab not in flat)
    steps = flat[flat.index("## Step by step"):flat.index("## Scripting")]
    named = {n.split(": ")[0] for n in re.findall(r"(?<![*\w])\*([^*]+)\*(?![*\w])", steps)}
    assert named and not named - ui - BLENDER_UI, sorted(named - ui - BLENDER_UI)


def test_every_documented_operator_is_registered_and_what_is_not_there_yet_is_not_there(text):
    """Every operator of docs/operators.md's table is registered and every registered one is there;
    a "Not there yet" paragraph (if any) names no registered operator."""
    ref = (ROOT / "docs" / "operators.md").read_text(encoding="utf-8")
    table = ref[ref.index("| operator | leaves behind |"):]
    table = table[:table.index("\n\n")]
    documented = set(re.findall(r"^\| `(\w+)` \|", table, flags=re.M))
    assert documented == registered_operators(), sorted(documented ^ registered_operators())
    if "**Not there yet:**" in text:
        para = text[text.index("**Not there yet:**"):]
        para = para[:para.index("\n\n")]
        planned = set(re.findall(r"`(\w+)`", para))
        assert planned and not planned & registered_operators(), "implemented now: move it out of 'Not there yet'"


def test_table_arguments_are_the_operators_properties(text):
    """Every keyword of the table is declared on that operator (bpy-free: the class's annotations)."""
    declared: dict[str, set[str]] = {}
    for path in (ROOT / "bolus_addon").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ClassDef):
                continue
            idname = [n.value.value for n in node.body if isinstance(n, ast.Assign)
                      and getattr(n.targets[0], "id", "") == "bl_idname" and isinstance(n.value, ast.Constant)]
            if idname and idname[0].startswith("bolus."):
                declared[idname[0][6:]] = {n.target.id for n in node.body if isinstance(n, ast.AnnAssign)}
    for op, args in operator_table(text).items():
        names = {a.split("=")[0].strip() for a in args.split(",") if a.strip()}
        assert names <= declared[op], f"{op}: {sorted(names - declared[op])}"


def test_attribute_and_property_names_exist_in_the_code(text):
    source = "\n".join(p.read_text(encoding="utf-8") for p in (ROOT / "bolus_addon").rglob("*.py"))
    scripts = {p.stem for p in (ROOT / "scripts").glob("*.py")}  # e.g. bolus_cli: a file, not a name
    names = set(re.findall(r"\bbolus_[A-Za-z0-9_]+", text)) - {"bolus_addon"} - scripts
    assert names
    missing = sorted(n for n in names if f'"{n}"' not in source)
    assert not missing


def test_make_targets_exist(text):
    makefile = (ROOT / "Makefile").read_text()
    targets = set(re.findall(r"^([\w-]+):", makefile, flags=re.M))
    named = set(re.findall(r"`make ([\w-]+)", text)) | set(re.findall(r"^\s+make ([\w-]+)", text, flags=re.M))
    assert named and named <= targets, sorted(named - targets)


@pytest.mark.parametrize("page", [README, DEVELOPMENT], ids=lambda p: p.name)
def test_repository_paths_exist(page):
    text = page.read_text(encoding="utf-8")
    paths = set(re.findall(r"`((?:scripts|bench|tests|docs|bolus_addon|assets)/[\w./*-]*)`", text))
    assert paths
    missing = sorted(p for p in paths if not list(ROOT.glob(p)))
    assert not missing


def tracked_modules() -> list[Path]:
    """The add-on's .py files git tracks in a checkout (a module still being written is not part
    of the project yet), else every one there."""
    try:
        out = subprocess.run(["git", "ls-files", "--", "bolus_addon/*.py"], cwd=ROOT, capture_output=True,
                             text=True, check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        out = []
    return [ROOT / f for f in out] or sorted((ROOT / "bolus_addon").rglob("*.py"))


def test_layout_lists_every_package_and_module():
    """The package tree (docs/development.md) names every package and module of the add-on and
    nothing that is gone."""
    text = DEVELOPMENT.read_text(encoding="utf-8")
    block = text[text.index("**Layout.**"):]
    listed = set(re.findall(r"\b(\w+)\.py\b", block))
    files = tracked_modules()
    missing = sorted({f.stem for f in files if f.name != "__init__.py"} - listed)
    assert not missing, f"not in the layout: {missing}"
    packages = {f.parent.relative_to(ROOT / "bolus_addon").as_posix() for f in files if f.name == "__init__.py"}
    unnamed = sorted(p for p in packages - {"."} if f"{p.rsplit('/', 1)[-1]}/" not in block)
    assert not unnamed, f"packages not in the layout: {unnamed}"
    every = {p.stem for folder in ("bolus_addon", "scripts", "bench", "tests") for p in (ROOT / folder).rglob("*.py")}
    assert listed <= every, sorted(listed - every)


def _write_stl_mm(path: Path) -> None:
    """A binary STL of a 70 x 50 mm patch of skin with a 15 mm high bump (a nose-sized dome), in mm."""
    x, y = np.meshgrid(np.linspace(-35, 35, 36), np.linspace(-25, 25, 26))
    z = 15.0 * np.exp(-(x ** 2 + y ** 2) / (2 * 12.0 ** 2))
    V = np.c_[x.ravel(), y.ravel(), z.ravel()]
    nx = x.shape[1]
    quads = [(r * nx + c, r * nx + c + 1, (r + 1) * nx + c + 1, (r + 1) * nx + c)
             for r in range(x.shape[0] - 1) for c in range(nx - 1)]
    F = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    out = bytearray(b"\0" * 80 + struct.pack("<I", len(F)))
    for f in F:
        p = V[f]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        out += struct.pack("<12fH", *(n / np.linalg.norm(n)), *p.ravel(), 0)
    path.write_bytes(bytes(out))


@pytest.mark.blender
def test_operator_table_defaults_are_the_operators(text, bpy_addon):
    bpy = bpy_addon
    for op, args in operator_table(text).items():
        props = getattr(bpy.ops.bolus, op).get_rna_type().properties
        for arg in (a for a in args.split(",") if "=" in a):
            name, value = (s.strip() for s in arg.split("="))
            assert props[name].default == pytest.approx(ast.literal_eval(value)), f"{op}.{name}"


@pytest.mark.blender
@pytest.mark.smoke
def test_scripting_recipe_runs_as_written(text, tmp_path):
    """The README's python block, with this repository and an STL in mm put in, runs in a
    fresh Python, writes a true-scale SVG (no unit warning: the unit line is right) and
    exits cleanly (bpy 4.2 crashed, 4.5 hung at exit while the add-on stayed registered)."""
    pytest.importorskip("bpy")
    code = re.search(r"```python\n(.*?)```", text, flags=re.S).group(1)
    assert '"/path/to/this/repository"' in code and '"skin.stl"' in code
    _write_stl_mm(tmp_path / "skin.stl")
    code = code.replace('"/path/to/this/repository"', repr(str(ROOT)))
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "units are probably wrong" not in run.stdout + run.stderr
    svg = (tmp_path / "pattern.svg").read_text()
    w = float(re.search(r'width="([\d.]+)mm"', svg).group(1))
    assert 70.0 < w < 400.0  # a 70 x 50 mm surface (plus the dome), laid out at true size in mm


@pytest.mark.blender
@pytest.mark.smoke
def test_stl_import_units_as_the_readme_says(bpy_addon, scene, tmp_path):
    """Step 0: in a scene of Unit Scale 0.001 an STL in mm comes in at true size (70 mm
    wide), and with the importer's 'Scene Unit' option 1000x off (too large on 5.x, too
    small on 4.2)."""
    bpy = bpy_addon
    _write_stl_mm(tmp_path / "skin.stl")
    scene.unit_settings.scale_length = 0.001
    widths = []
    for use_scene_unit in (False, True):
        bpy.ops.wm.stl_import(filepath=str(tmp_path / "skin.stl"), use_scene_unit=use_scene_unit)
        ob = bpy.context.selected_objects[0]
        co = np.array([ob.matrix_world @ v.co for v in ob.data.vertices])
        widths.append(float(np.ptp(co[:, 0])))
        bpy.data.objects.remove(ob)
    assert widths[0] == pytest.approx(70.0, rel=1e-4)
    assert abs(np.log10(widths[1] / 70.0)) == pytest.approx(3.0, abs=1e-4)
