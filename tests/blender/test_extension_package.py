"""The extension as Blender builds, validates and installs it (manifest, paths_exclude_pattern, wheels).

Each install runs in a separate Python (a separate Blender) with a throw-away user folder
(BLENDER_USER_RESOURCES), as a user's "Install from Disk" does, and then runs the add-on's
operators through the *installed* copy.  Besides the running Blender, the zip is installed
into bpy 5.2.3 (Python 3.13, numpy 2) from .venv52 when that venv exists.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = [pytest.mark.blender, pytest.mark.smoke]

ROOT = Path(__file__).resolve().parents[2]
PY52 = ROOT / ".venv52" / "bin" / "python"
sys.path.insert(0, str(ROOT / "scripts"))
import build_extension  # noqa: E402


def blender_ext_cli() -> Path:
    pytest.importorskip("bpy")
    cli = build_extension.builder_cli()
    if not cli.exists():
        pytest.skip(f"Blender's extension builder not found at {cli}")
    return cli


def running_bpy_version() -> str:
    bpy = pytest.importorskip("bpy")
    return ".".join(str(x) for x in bpy.app.version[:3])


@pytest.fixture(scope="module")
def built_zip(tmp_path_factory):
    cli = blender_ext_cli()
    out = tmp_path_factory.mktemp("dist")
    v = subprocess.run([sys.executable, str(cli), "validate", str(ROOT)], capture_output=True, text=True, timeout=120)
    assert v.returncode == 0 and "Success" in v.stdout, v.stdout + v.stderr
    b = subprocess.run([sys.executable, str(cli), "build", "--source-dir", str(ROOT), "--output-dir", str(out)],
                       capture_output=True, text=True, timeout=120)
    assert b.returncode == 0, b.stdout + b.stderr
    zips = list(out.glob("bolus-*.zip"))
    assert len(zips) == 1, b.stdout
    return zips[0]


def test_zip_holds_the_addon_and_no_dev_files(built_zip):
    names = set(zipfile.ZipFile(built_zip).namelist())
    for must in ("blender_manifest.toml", "__init__.py", "LICENSE", "bolus_addon/__init__.py",
                 "bolus_addon/blender/operator_base.py", "bolus_addon/operators/unfold.py",
                 "bolus_addon/blender/compat.py", "bolus_addon/core/unfold/unfold.py",
                 "bolus_addon/core/analysis/spectral.py", "bolus_addon/core/mesh/geometry2d.py"):
        assert must in names, f"{must} missing from the extension zip"
    # every module of the package is there (4.2's `paths` would have dropped folder contents)
    for py in (ROOT / "bolus_addon").rglob("*.py"):
        assert py.relative_to(ROOT).as_posix() in names
    for banned in ("tests/", "bench/", "scripts/", ".ci/", "docs/", "dist/", "build/", ".venv", "Makefile",
                   "requirements", "pyproject.toml", "__pycache__"):
        assert not any(n.startswith(banned) or f"/{banned}" in n for n in names), f"{banned} leaked into the zip"
    # of assets/ only the learned print split's trained auto-encoder ships (the meshes are for demo and tests)
    assert sorted(n for n in names if n.startswith("assets/")) == ["assets/print_sae.npz"], names


def test_platform_zips_stage_what_the_plain_zip_holds(built_zip):
    """`make extension-wheels` stages the files the manifest keeps, the same the builder packs
    into the plain zip (the trained auto-encoder included), plus the wheels."""
    names = {n for n in zipfile.ZipFile(built_zip).namelist() if not n.endswith("/")}
    assert set(build_extension.shipped_files()) | {"blender_manifest.toml"} == names


def test_manifest_keeps_every_generated_folder_out_of_the_zip():
    """What the repository ignores (venvs, out/, and dist/ and build/ of `make extension-wheels`:
    hundreds of MB of zips and wheels) is excluded by the builder's own pattern matcher."""
    import importlib.util
    import tomllib

    spec = importlib.util.spec_from_file_location("blender_ext_cli", blender_ext_cli())
    cli = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cli)
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    match = cli.PathPatternMatch(manifest["build"]["paths_exclude_pattern"])
    ignored = [ln.strip() for ln in (ROOT / ".gitignore").read_text().splitlines() if ln.strip()
               and not ln.startswith("#")]
    probes = [g.replace("*", "x") for g in ignored] + ["dist/", "build/", "out/", ".venv52/", ".venv45/"]
    kept = [p for p in probes if not match.test_path(p.lstrip("/"))]
    assert not kept, f"paths_exclude_pattern lets these into the extension zip: {kept}"
    for needed in ("bolus_addon/", "bolus_addon/core/unfold.py", "__init__.py", "LICENSE"):
        assert not match.test_path(needed), needed


def install_and_run(python: Path | str, zip_path: Path, user: Path) -> dict:
    """`build_extension.install_and_run` (install, enable, segment, unfold a bent sheet) in ``python``."""
    res, log = build_extension.install_and_run(str(python), zip_path, user)
    assert res is not None, log
    return res


def check_installed_run(res: dict, user: Path) -> None:
    problems = build_extension.installed_run_problems(res, user)
    assert not problems, (problems, res)


def blenders():
    """The Blenders the zip is installed into: the running one, and bpy 5.2.3 (Python 3.13,
    numpy 2; the Blender most people download today) unless that is the running one."""
    out = [pytest.param("running", id="running")]
    if Path(sys.prefix).resolve() != PY52.parent.parent.resolve():
        out.append(pytest.param("bpy-5.2.3", id="bpy-5.2.3"))
    return out


def blender_python(which: str) -> str:
    if which == "running":
        return sys.executable
    if not PY52.exists():
        pytest.skip(".venv52 (bpy 5.2.3) does not exist: `make .venv52/.installed` needs a Python 3.13")
    return str(PY52)


@pytest.mark.parametrize("which", blenders())
def test_blender_installs_the_zip_and_runs_segment_and_unfold(built_zip, tmp_path, which):
    """Install from Disk into a throw-away user folder, then segment and unfold through the installed copy."""
    res = install_and_run(blender_python(which), built_zip, tmp_path)
    if which == "running":
        assert res["bpy"].startswith(running_bpy_version()), res
    else:
        assert res["bpy"].startswith("5.2") and res["python"] == "3.13" and res["numpy"].startswith("2."), res
    check_installed_run(res, tmp_path)


# ---------------------------------------------------------------- wheels for two Pythons

def test_bundled_pins_are_ordered_for_blender_4_2():
    """cp311 pins above the cp313 ones (see build_extension): checked, and refused otherwise."""
    pins = build_extension.check_pins()
    assert set(pins) == {"scipy", "scikit-learn", "manifold3d", "libigl"}
    for v in pins.values():
        assert set(v) == {"cp311", "cp313"}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(build_extension, "pinned", lambda name, req="requirements.txt": f"{name}==1.9.1")
        with pytest.raises(SystemExit, match="Blender 4.2.0 installs"):
            build_extension.check_pins()


def test_staged_manifest_lists_platforms_and_wheels_before_the_tables():
    import tomllib

    text = build_extension.staged_manifest((ROOT / "blender_manifest.toml").read_text(), ["linux-x64", "macos-x64"],
                                           ["a-1.0-cp311-cp311-any.whl", "a-1.0-cp313-cp313-any.whl"])
    m = tomllib.loads(text)
    assert m["platforms"] == ["linux-x64", "macos-x64"]
    assert m["wheels"] == ["./wheels/a-1.0-cp311-cp311-any.whl", "./wheels/a-1.0-cp313-cp313-any.whl"]
    assert m["id"] == "bolus" and "permissions" in m and "build" in m
    assert set(build_extension.PLATFORMS) == {"linux-x64", "macos-arm64", "macos-x64", "windows-x64"}


def probe_wheel(folder: Path, dist: str, version: str, tag: str) -> str:
    """A minimal wheel ``<dist>-<version>-<tag>-<tag>-any.whl`` whose module says its tag."""
    name = f"{dist}-{version}-{tag}-{tag}-any.whl"
    info = f"{dist}-{version}.dist-info"
    files = {f"{dist}/__init__.py": f"TAG = {tag!r}\nVERSION = {version!r}\n",
             f"{info}/METADATA": f"Metadata-Version: 2.1\nName: {dist}\nVersion: {version}\n",
             f"{info}/WHEEL": "Wheel-Version: 1.0\nGenerator: bolus-test\nRoot-Is-Purelib: false\n"
                              f"Tag: {tag}-{tag}-any\n"}
    record = "".join(f"{k},,\n" for k in files) + f"{info}/RECORD,,\n"
    with zipfile.ZipFile(folder / name, "w") as z:
        for k, text in files.items():
            z.writestr(k, text)
        z.writestr(f"{info}/RECORD", record)
    return name


PROBE = r"""
import importlib, json, sys
import bpy
r = bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=True)
out = {"install": sorted(r), "python": "cp3%d" % sys.version_info[1]}
for dist in sys.argv[2:]:
    m = importlib.import_module(dist)
    out[dist] = [m.TAG, m.VERSION]
print("RESULT " + json.dumps(out))
"""


@pytest.mark.parametrize("which", blenders())
def test_blender_installs_the_wheels_of_its_own_python(tmp_path, which):
    """An extension carrying cp311 and cp313 wheels versioned like our scipy / scikit-learn pins:
    the Blender (4.2.0 too, which does not look at the Python tag) installs its own."""
    exe = blender_python(which)
    pins = build_extension.check_pins()
    src = tmp_path / "src"
    (src / "wheels").mkdir(parents=True)
    wheels, dists = [], []
    for name, versions in pins.items():
        dist = "bolus_probe_" + name.replace("-", "_")
        dists.append(dist)
        wheels += [probe_wheel(src / "wheels", dist, v, tag) for tag, v in versions.items()]
    manifest = (ROOT / "blender_manifest.toml").read_text().replace('id = "bolus"', 'id = "bolus_wheel_probe"')
    manifest = manifest.split("\n[build]")[0]
    (src / "blender_manifest.toml").write_text(build_extension.staged_manifest(manifest, ["linux-x64", "macos-arm64",
                                                                                          "macos-x64", "windows-x64"],
                                                                             wheels))
    (src / "__init__.py").write_text("def register():\n    pass\n\n\ndef unregister():\n    pass\n")
    zpath = tmp_path / "probe.zip"
    with zipfile.ZipFile(zpath, "w") as z:
        for f in src.rglob("*"):
            if f.is_file():
                z.write(f, f.relative_to(src).as_posix())
    user = tmp_path / "user"
    user.mkdir()
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user))
    env.pop("PYTHONPATH", None)
    p = subprocess.run([exe, "-c", PROBE, str(zpath), *dists], capture_output=True, text=True, timeout=300,
                       env=env, cwd=str(user))
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
    assert p.returncode == 0 and lines, p.stdout[-3000:] + p.stderr[-3000:]
    res = json.loads(lines[-1][len("RESULT "):])
    assert res["install"] == ["FINISHED"], res
    for name, dist in zip(pins, dists):
        assert res[dist] == [res["python"], pins[name][res["python"]]], (name, res)
