"""Build installable extension zips that carry scipy, scikit-learn, manifold3d, libigl, ezdxf and fpdf2 (`make extension-wheels`).

Blender ships numpy but not scipy, scikit-learn, manifold3d (the volume and boolean library of the
printed bolus) or libigl (its compiled marching cubes), nor ezdxf and fpdf2 (the DXF and PDF
pattern export), which the add-on's core needs.  libigl's cp313 wheel is a cp312-abi3 one.
Blender extensions can bundle Python wheels (manifest ``wheels = [...]``), one zip per
platform.  Blender 4.2-5.0 run Python 3.11 and Blender 5.1+ Python 3.13, so every zip
carries the wheels for both (cp311 and cp313); Blender installs the ones for its Python.
This script

1. downloads, with the venv's pip, the scipy, scikit-learn, manifold3d and libigl wheels of every platform
   asked (linux-x64, macos-arm64, macos-x64, windows-x64) for both Pythons -- cp311 at the
   versions pinned in requirements.txt, cp313 at those in requirements-bpy52.txt -- and
   the pure-Python packages they need (joblib, cloudpickle, threadpoolctl, narwhals, at
   the versions in the venv), and the pattern export's pure-Python wheels (py3-none-any:
   ezdxf, fpdf2, fonttools, defusedxml, pyparsing, typing_extensions, and pydicom for the DICOM
   import and export, at the versions in requirements.txt; no Pillow), into a cache folder;
2. stages the extension (the files the manifest's paths_exclude_pattern keeps: root __init__.py,
   LICENSE, README.md, bolus_addon/, assets/print_sae.npz)
   with those wheels, adding ``platforms`` and ``wheels`` to the staged manifest;
3. runs Blender's own builder (from the bpy in the venv) with ``--split-platforms``:
   one ``bolus-<version>-<platform>.zip`` per platform in the output folder, and checks
   that each zip holds both Pythons' wheels.

Blender 4.2.0 does not yet skip wheels made for another Python: of two wheels of one
package it installs the higher version, on a tie the later file name (cp313).  So each
cp311 pin must be a higher version than the cp313 pin of the same package
(`check_pins`), and Blender 4.2.0 then installs the cp311 wheels.

    .venv/bin/python scripts/build_extension.py [--out dist] [--platforms linux-x64 windows-x64 ...]
"""
from __future__ import annotations

import argparse
import importlib.metadata as md
import json
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Blender platform name -> pip --platform tag (the oldest OS each Blender release supports)
PLATFORMS = {
    "linux-x64": "manylinux_2_28_x86_64",
    "macos-arm64": "macosx_12_0_arm64",
    "macos-x64": "macosx_11_0_x86_64",
    "windows-x64": "win_amd64",
}
#: wheel Python tag -> (pip --python-version, requirements file with its pins, Blenders)
PYTHONS = {
    "cp311": ("3.11", "requirements.txt", "4.2-5.0"),
    "cp313": ("3.13", "requirements-bpy52.txt", "5.1+"),
}
BINARY = ("scipy", "scikit-learn", "manifold3d", "libigl")
PURE = ("joblib", "cloudpickle", "threadpoolctl", "narwhals")
#: the pattern export's libraries: DXF with ezdxf, PDF with fpdf2, and what they need, as
#: py3-none-any wheels at the versions pinned in requirements.txt (ezdxf and fonttools also publish
#: compiled wheels; their pure ones run the same, only slower on huge drawings).  Not Pillow: fpdf2
#: draws vectors and text without it (tests/test_core_pattern_export.py checks that).
#: pydicom: the planning CT and the RTSTRUCT (core.dicom), pure Python too.
PURE_ANY = ("ezdxf", "fpdf2", "fonttools", "defusedxml", "pyparsing", "typing_extensions", "pydicom")


def pinned(name: str, requirements: str = "requirements.txt") -> str:
    """The ``name==version`` line for ``name`` in the requirements file (under ROOT)."""
    for line in (ROOT / requirements).read_text().splitlines():
        if line.split("==")[0].strip().lower() == name:
            return line.strip()
    raise SystemExit(f"{name} is not pinned in {requirements}")


def _version_key(v: str) -> tuple[int, ...]:
    return tuple(int(x) for x in re.findall(r"\d+", v)[:3])


def check_pins() -> dict[str, dict[str, str]]:
    """{package: {python tag: version}} of the bundled binary packages; raises SystemExit
    unless every cp311 version is above the cp313 one (what Blender 4.2.0 needs, see above)."""
    pins = {n: {tag: pinned(n, req).split("==")[1] for tag, (_, req, _) in PYTHONS.items()} for n in BINARY}
    for name, v in pins.items():
        if not _version_key(v["cp311"]) > _version_key(v["cp313"]):
            raise SystemExit(f"{name}: the cp311 pin ({v['cp311']}, requirements.txt) must be a higher version "
                             f"than the cp313 pin ({v['cp313']}, requirements-bpy52.txt): Blender 4.2.0 installs "
                             "the higher of the two whatever its Python")
    return pins


def download(reqs: list[str], dest: Path, platform: str | None, python: str = "3.11") -> None:
    """Download the wheels ``reqs`` for ``platform`` (None: this machine's; "any": only pure
    py3-none-any wheels, even of packages that also publish compiled ones)."""
    cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check", "--no-deps",
           "--only-binary=:all:", "--python-version", python, "-d", str(dest)]
    if platform == "any":
        cmd += ["--platform", "any", "--implementation", "py", "--abi", "none"]
    else:
        cmd += ["--implementation", "cp"] + (["--platform", platform] if platform else [])
    if subprocess.call(cmd + reqs) != 0:
        raise SystemExit(f"could not download {' '.join(reqs)} for Python {python} on {platform or 'any platform'} "
                         "(no network?)")


def staged_manifest(manifest: str, platforms: list[str], wheels: list[str]) -> str:
    """The manifest text with ``platforms`` and ``wheels = ["./wheels/<name>", ...]`` added."""
    extra = "platforms = [" + ", ".join(f'"{p}"' for p in platforms) + "]\n"
    extra += "wheels = [\n" + "".join(f'  "./wheels/{w}",\n' for w in wheels) + "]\n"
    head, sep, tail = manifest.partition("\n[")  # top-level keys must come before the first table
    return head + "\n" + extra + sep + tail


def builder_cli() -> Path:
    """Blender's extension builder (blender_ext.py), shipped with Blender and with the bpy module."""
    import bpy

    return Path(bpy.utils.system_resource("SCRIPTS")) / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"


def shipped_files() -> list[str]:
    """The repository's files (relative POSIX paths) that the manifest's ``paths_exclude_pattern``
    lets into the extension, as Blender's own builder matches them (so the platform zips hold
    what ``make extension`` holds: the package, the manifest, and assets/print_sae.npz)."""
    import importlib.util
    import tomllib

    spec = importlib.util.spec_from_file_location("blender_ext_cli", builder_cli())
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    match = mod.PathPatternMatch(manifest["build"]["paths_exclude_pattern"])
    try:
        listed = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
        files = [f for f in listed.splitlines() if (ROOT / f).is_file()]
    except (OSError, subprocess.CalledProcessError):
        files = [p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*") if p.is_file()]
    return sorted(f for f in files if f != "blender_manifest.toml"
                  and not any(match.test_path("/".join(f.split("/")[:i]) + "/") for i in range(1, f.count("/") + 1))
                  and not match.test_path(f))


def zip_wheel_tags(path: Path) -> dict[str, set[str]]:
    """{package: {the Python tags it runs on, of PYTHONS}} of the wheels inside an extension zip:
    a cp3xx wheel runs on that Python, a cp3xx-abi3 wheel on that one and every later one."""
    out: dict[str, set[str]] = {}
    for name in zipfile.ZipFile(path).namelist():
        if name.startswith("wheels/") and name.endswith(".whl"):
            parts = Path(name).name[:-4].split("-")
            py, abi = parts[-3], parts[-2]
            runs = {t for t in PYTHONS if t == py or (abi == "abi3" and py.startswith("cp")
                                                          and int(py[2:]) <= int(t[2:]))}
            out.setdefault(parts[0].lower().replace("_", "-"), set()).update(runs or {py})
    return out


# Runs in the other Blender: install the zip, enable it, segment and unfold a bent sheet
# (a piece of a cylinder of radius 0.2 m, 100 mm wide, in a 1 m-unit scene) through the
# installed add-on, and print what a user would check.
INSTALL_AND_RUN = r"""
import json, sys
import bpy
import numpy as np

ZIP, USER = sys.argv[1], sys.argv[2]
out = {"bpy": bpy.app.version_string, "python": "%d.%d" % sys.version_info[:2], "numpy": np.__version__}
r = bpy.ops.extensions.package_install_files(filepath=ZIP, repo="user_default", enable_on_install=True)
out["install"] = sorted(r)
out["enabled"] = "bl_ext.user_default.bolus" in bpy.context.preferences.addons
out["scene_prop"] = hasattr(bpy.types.Scene, "bolus")
mod = sys.modules.get("bl_ext.user_default.bolus.bolus_addon.blender.operator_base")
out["module_file"] = getattr(mod, "__file__", "")

n = 11
x, y = np.meshgrid(np.linspace(-0.05, 0.05, n), np.linspace(-0.05, 0.05, n))
R = 0.2
V = np.stack([R * np.sin(x.ravel() / R), y.ravel(), R * (1 - np.cos(x.ravel() / R))], 1)
ids = np.arange(n * n).reshape(n, n)
Q = np.stack([ids[:-1, :-1], ids[:-1, 1:], ids[1:, 1:], ids[1:, :-1]], -1).reshape(-1, 4)
me = bpy.data.meshes.new("sheet")
me.from_pydata(V.tolist(), [], Q.tolist())
me.update()
ob = bpy.data.objects.new("sheet", me)
bpy.context.scene.collection.objects.link(ob)
bpy.context.view_layer.objects.active = ob
ob.select_set(True)

out["segment"] = sorted(bpy.ops.bolus.segment(patches=2))
a = ob.data.attributes["bolus_patch"]
lab = np.zeros(len(ob.data.polygons), dtype=np.int32)
a.data.foreach_get("value", lab)
out["patch_labels"] = sorted(set(lab.tolist()))

out["unfold"] = sorted(bpy.ops.bolus.unfold())
bpy.context.view_layer.objects.active = ob
try:  # the learned print split needs the shipped auto-encoder weights (assets/print_sae.npz in the zip)
    out["learned"] = sorted(bpy.ops.bolus.print_segment(method="LEARNED"))
except RuntimeError as exc:
    out["learned"] = [str(exc)]
pat = bpy.data.objects.get("sheet_pattern")
out["pattern"] = pat is not None
if pat is not None:
    pm = pat.data
    P = np.zeros(len(pm.vertices) * 3)
    pm.vertices.foreach_get("co", P)
    P = P.reshape(-1, 3)
    src = np.zeros(len(pm.polygons), dtype=np.int32)
    pm.attributes["bolus_source_face"].data.foreach_get("value", src)
    out["pattern_max_abs_z"] = float(np.abs(P[:, 2]).max())
    out["pattern_faces_cover_source"] = sorted(src.tolist()) == list(range(len(me.polygons)))
    # edge-length error EL (SPEC) of the pattern against the sheet
    L = L0 = 0.0
    for k, poly in enumerate(pm.polygons):
        pv = list(poly.vertices)
        sv = list(me.polygons[int(src[k])].vertices)
        for i in range(len(pv)):
            l1 = np.linalg.norm(P[pv[i]] - P[pv[(i + 1) % len(pv)]])
            l0 = np.linalg.norm(V[sv[i]] - V[sv[(i + 1) % len(sv)]])
            L += abs(l1 - l0)
            L0 += l0
    out["EL"] = L / L0
import manifold3d  # the volume library of the printed bolus (core.solid)
import importlib, os
drawing = importlib.import_module("bl_ext.user_default.bolus.bolus_addon.core.pattern.export")
tri = [{"UV": np.array([[0.0, 0], [40, 0], [0, 30]]), "F": [[0, 1, 2]], "label": "check"}]
out["export"] = {ext: drawing.write_pattern(os.path.join(USER, "check." + ext), tri, page="A4")["pages"]
                 for ext in ("svg", "dxf", "pdf")}
marching = importlib.import_module("bl_ext.user_default.bolus.bolus_addon.core.solid.marching")
ax = np.arange(-6.0, 6.5, 0.5)
X, Y, Z = np.meshgrid(ax, ax, ax, indexing="ij")
ball = marching.marching_manifold(4.0 - np.sqrt(X ** 2 + Y ** 2 + Z ** 2), [-6.0] * 3, [0.5] * 3)
out["marched_ball"] = [ball.genus(), round(ball.volume() / (4 / 3 * np.pi * 64), 3)]
rtw = importlib.import_module("bl_ext.user_default.bolus.bolus_addon.core.dicom.rtstruct_write")
out["dicom_uid"] = rtw.new_uid()[:5]  # the DICOM code imports pydicom from the zip's wheel
import pydicom  # noqa: F401
out["modules"] = {m: getattr(sys.modules.get(m), "__file__", None)
                  for m in ("scipy", "sklearn", "manifold3d", "igl", "ezdxf", "fpdf", "pydicom")}
print("RESULT " + json.dumps(out))
"""



#: what the extension's wheels bring; hidden from the Blender under test by `--check`
BUNDLED_MODULES = ("scipy", "sklearn", "scikit_learn", "manifold3d", "igl", "libigl", "joblib", "threadpoolctl", "narwhals", "cloudpickle",
                   "ezdxf", "fpdf", "fonttools", "defusedxml", "pyparsing", "typing_extensions", "pydicom")


def _site_without_bundled(python: str, dest: Path) -> Path:
    """A folder of links to ``python``'s site-packages minus the packages the wheels bring."""
    site = subprocess.check_output([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                   text=True).strip()
    dest.mkdir(parents=True, exist_ok=True)
    for entry in Path(site).iterdir():
        if not entry.name.lower().startswith(BUNDLED_MODULES):
            (dest / entry.name).symlink_to(entry)
    return dest


def install_and_run(python: str, zip_path: Path, user: Path, hide_bundled: bool = False) -> tuple[dict | None, str]:
    """Install ``zip_path`` into the Blender (bpy) of ``python`` with a throw-away user folder
    ``user``, enable it, segment and unfold a bent sheet through the installed add-on.

    ``hide_bundled``: run without the interpreter's own scipy / scikit-learn (``-S`` and a
    copy of its site-packages without them), so that only the zip's wheels can provide them.
    Returns (the RESULT dict or None, the output for a failure message).
    """
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user))
    env.pop("PYTHONPATH", None)
    cmd = [python, "-c", INSTALL_AND_RUN, str(Path(zip_path).resolve()), str(user)]
    if hide_bundled:
        env["PYTHONPATH"] = str(_site_without_bundled(python, user / "_site"))
        cmd.insert(1, "-S")
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env, cwd=str(user))
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
    if p.returncode != 0 or not lines:
        return None, p.stdout[-3000:] + p.stderr[-3000:]
    return json.loads(lines[-1][len("RESULT "):]), p.stdout[-3000:]


def installed_run_problems(res: dict, user: Path) -> list[str]:
    """What is wrong with an `install_and_run` result (empty: installed, enabled, segment and unfold worked)."""
    bad = []
    if not (res["install"] == ["FINISHED"] and res["enabled"] and res["scene_prop"]):
        bad.append("install/enable failed")
    if not Path(res["module_file"] or "/").resolve().is_relative_to(Path(user).resolve()):
        bad.append(f"operators not from the installed copy: {res['module_file']}")
    if res["segment"] != ["FINISHED"] or res["patch_labels"] != [0, 1]:
        bad.append(f"segment: {res['segment']}, bolus_patch values {res['patch_labels']}")
    if res.get("learned") != ["FINISHED"]:
        bad.append(f"print_segment(method='LEARNED') (the shipped auto-encoder): {res.get('learned')}")
    if res.get("export") != {"svg": 1, "dxf": 1, "pdf": 1}:
        bad.append(f"pattern export (SVG, DXF, PDF): {res.get('export')}")
    genus, vol = (res.get("marched_ball") or [None, 0.0])
    if genus != 0 or not 0.97 < vol <= 1.0:
        bad.append(f"marching cubes (libigl) on a ball: genus {genus}, volume {vol} of the ball's")
    if res["unfold"] != ["FINISHED"] or not res["pattern"]:
        bad.append(f"unfold: {res['unfold']}, pattern object {res['pattern']}")
    elif not (res["pattern_max_abs_z"] <= 1e-6 and res["pattern_faces_cover_source"] and res["EL"] < 0.02):
        bad.append(f"pattern: |z| <= {res['pattern_max_abs_z']:.2g}, faces cover the source "
                   f"{res['pattern_faces_cover_source']}, EL {res['EL']:.4f} (a cylinder piece: < 0.02)")
    return bad


def check_zip(zip_path: Path, pythons: list[str]) -> int:
    """Install ``zip_path`` into each bpy ``python`` without its own scipy / scikit-learn; 0 if all work."""
    import tempfile

    failed = 0
    for python in pythons:
        with tempfile.TemporaryDirectory(prefix="bolus-check-") as tmp:
            user = Path(tmp)
            res, log = install_and_run(python, zip_path, user, hide_bundled=True)
            if res is None:
                bad = ["did not finish:\n" + log]
            else:
                bad = installed_run_problems(res, user)
                bad += [f"{m} not from the zip's wheels: {f}" for m, f in res["modules"].items()
                        if f is None or not Path(f).resolve().is_relative_to(user.resolve())]
            if bad:
                print(f"  FAILED {zip_path.name} with {python}:\n    " + "\n    ".join(bad))
            else:
                print(f"  ok {zip_path.name} in bpy {res['bpy']} (Python {res['python']}, numpy {res['numpy']}): "
                      f"segment and unfold finished, EL {res['EL']:.4f}, SVG/DXF/PDF written, scipy, scikit-learn, "
                      "manifold3d, libigl, ezdxf, fpdf2 and pydicom from the zip's wheels")
            failed += bool(bad)
    return int(failed > 0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "dist"))
    ap.add_argument("--cache", default=str(ROOT / "build" / "wheels"))
    ap.add_argument("--platforms", nargs="+", default=list(PLATFORMS), choices=list(PLATFORMS))
    ap.add_argument("--check", nargs="+", metavar="PYTHON", default=[],
                    help="after building, install this machine's zip into the bpy of each PYTHON (e.g. "
                         ".venv42/bin/python .venv52/bin/python) without its own scipy / scikit-learn, "
                         "and run segment and unfold through it")
    args = ap.parse_args()
    pins = check_pins()
    cache, out = Path(args.cache), Path(args.out)
    cache.mkdir(parents=True, exist_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    folders = []
    for plat in args.platforms:
        for tag, (python, _, _) in PYTHONS.items():
            folders.append(cache / plat / tag)
            folders[-1].mkdir(parents=True, exist_ok=True)
            download([f"{n}=={pins[n][tag]}" for n in BINARY], folders[-1], PLATFORMS[plat], python)
    folders.append(cache / "any")
    folders[-1].mkdir(exist_ok=True)
    download([f"{n}=={md.version(n)}" for n in PURE], folders[-1], None)
    download([pinned(n) for n in PURE_ANY], folders[-1], "any")

    stage = ROOT / "build" / "stage"
    shutil.rmtree(stage, ignore_errors=True)
    (stage / "wheels").mkdir(parents=True)
    for rel in shipped_files():
        (stage / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / rel, stage / rel)
    found = set(folders[-1].glob("*.whl"))  # the pure ones
    for plat in args.platforms:
        for tag in PYTHONS:  # each Python's folder: its pinned binaries (cp3xx or an older abi3 wheel)
            wanted = {f"{n.replace('-', '_')}-{pins[n][tag]}" for n in BINARY}
            found |= {w for w in (cache / plat / tag).glob("*.whl") if "-".join(w.name.split("-")[:2]) in wanted}
    found = sorted(found, key=lambda w: w.name)
    wheels = [w.name for w in found]
    for w in found:
        shutil.copy2(w, stage / "wheels" / w.name)
    manifest = (ROOT / "blender_manifest.toml").read_text()
    (stage / "blender_manifest.toml").write_text(staged_manifest(manifest, args.platforms, wheels))

    cli = builder_cli()
    for old in out.glob("bolus-*.zip"):
        old.unlink()
    rc = subprocess.call([sys.executable, str(cli), "build", "--source-dir", str(stage), "--output-dir", str(out),
                          "--split-platforms"])
    if rc != 0:
        return rc
    zips = sorted(out.glob("bolus-*.zip"))
    bad = []
    for z in zips:
        tags = zip_wheel_tags(z)
        have = {n: sorted(tags.get(n, ())) for n in BINARY}
        print(f"  {z.name}: {z.stat().st_size / 2**20:.1f} MiB, "
              + ", ".join(f"{n} {'+'.join(t) or 'MISSING'}" for n, t in have.items()))
        bad += [f"{z.name}: {n} lacks {set(PYTHONS) - set(t)}" for n, t in have.items() if set(t) != set(PYTHONS)]
    if len(zips) != len(args.platforms) or bad:
        print("extension zips incomplete:\n" + "\n".join(bad or [f"{len(zips)} zips for {args.platforms}"]))
        return 1
    print(f"extension zips in {out}: " + ", ".join(z.name for z in zips) + "  (wheels for "
          + ", ".join(f"{t}: Blender {b}" for t, (_, _, b) in PYTHONS.items()) + ")")
    if args.check:
        import sysconfig

        host = {"linux-x86_64": "linux_x64", "win-amd64": "windows_x64", "macosx-arm64": "macos_arm64"}.get(
            sysconfig.get_platform(), "macos_x64" if sysconfig.get_platform().startswith("macosx") else "?")
        mine = [z for z in zips if z.stem.endswith(host)]
        if not mine:
            print(f"--check: no zip for this machine ({sysconfig.get_platform()})")
            return 1
        return check_zip(mine[0], [str(Path(p).absolute()) for p in args.check])
    return 0


if __name__ == "__main__":
    os.chdir(ROOT)
    sys.exit(main())
