"""The extension as Blender builds, validates and installs it (manifest, paths_exclude_pattern)."""
from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = [pytest.mark.blender, pytest.mark.smoke]

ROOT = Path(__file__).resolve().parents[1]


def blender_ext_cli() -> Path:
    bpy = pytest.importorskip("bpy")
    cli = Path(bpy.utils.system_resource("SCRIPTS")) / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    if not cli.exists():
        pytest.skip(f"Blender's extension builder not found at {cli}")
    return cli


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
                 "bolus_addon/operators.py", "bolus_addon/pattern_ops.py", "bolus_addon/core/unfold.py",
                 "bolus_addon/core/spectral.py"):
        assert must in names, f"{must} missing from the extension zip"
    # every module of the package is there (4.2's `paths` would have dropped folder contents)
    for py in (ROOT / "bolus_addon").rglob("*.py"):
        assert py.relative_to(ROOT).as_posix() in names
    for banned in ("tests/", "bench/", "scripts/", "assets/", ".ci/", "docs/", ".venv", "Makefile",
                   "requirements.txt", "pyproject.toml", "__pycache__"):
        assert not any(n.startswith(banned) or f"/{banned}" in n for n in names), f"{banned} leaked into the zip"


def test_blender_installs_and_enables_the_zip(built_zip, tmp_path):
    """Install from Disk, as a user does, into a throw-away user folder (a separate Blender)."""
    code = (
        "import bpy, sys\n"
        f"r = bpy.ops.extensions.package_install_files(filepath={str(built_zip)!r}, repo='user_default', "
        "enable_on_install=True)\n"
        "print('RESULT', r, hasattr(bpy.types.Scene, 'bolus'), 'bl_ext.user_default.bolus' in bpy.context.preferences.addons)\n"
        "bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3)\n"
        "print('SEGMENT', bpy.ops.bolus.segment(patches=2))\n"
    )
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert "RESULT {'FINISHED'} True True" in out.stdout, out.stdout + out.stderr
    assert "SEGMENT {'FINISHED'}" in out.stdout, out.stdout + out.stderr
