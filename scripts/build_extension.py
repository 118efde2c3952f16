"""Build installable extension zips that carry scipy and scikit-learn (`make extension-wheels`).

Blender ships numpy but not scipy or scikit-learn, which the add-on's core needs.
Blender extensions can bundle Python wheels (manifest ``wheels = [...]``), one zip per
platform.  This script

1. downloads, with the venv's pip, the cp311 wheels of scipy and scikit-learn pinned in
   requirements.txt for every platform asked, and the pure-Python packages they need
   (joblib, cloudpickle, threadpoolctl, narwhals, at the versions in the venv), into a
   cache folder;
2. stages the extension (manifest, root __init__.py, LICENSE, README.md, bolus_addon/)
   with those wheels, adding ``platforms`` and ``wheels`` to the staged manifest;
3. runs Blender's own builder (from the bpy in the venv) with ``--split-platforms``:
   one ``bolus-<version>-<platform>.zip`` per platform in the output folder.

    .venv/bin/python scripts/build_extension.py [--out dist] [--platforms linux-x64 windows-x64 ...]
"""
from __future__ import annotations

import argparse
import importlib.metadata as md
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Blender platform name -> pip --platform tag (cp311 wheels on PyPI)
PLATFORMS = {
    "linux-x64": "manylinux_2_28_x86_64",
    "macos-arm64": "macosx_12_0_arm64",
    "windows-x64": "win_amd64",
}
BINARY = ("scipy", "scikit-learn")
PURE = ("joblib", "cloudpickle", "threadpoolctl", "narwhals")


def pinned(name: str) -> str:
    for line in (ROOT / "requirements.txt").read_text().splitlines():
        if line.split("==")[0].strip().lower() == name:
            return line.strip()
    raise SystemExit(f"{name} is not pinned in requirements.txt")


def download(reqs: list[str], dest: Path, platform: str | None) -> None:
    cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check", "--no-deps",
           "--only-binary=:all:", "--python-version", "3.11", "--implementation", "cp", "-d", str(dest)]
    if platform:
        cmd += ["--platform", platform]
    if subprocess.call(cmd + reqs) != 0:
        raise SystemExit(f"could not download {' '.join(reqs)} for {platform or 'any platform'} (no network?)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "dist"))
    ap.add_argument("--cache", default=str(ROOT / "build" / "wheels"))
    ap.add_argument("--platforms", nargs="+", default=list(PLATFORMS), choices=list(PLATFORMS))
    args = ap.parse_args()
    cache, out = Path(args.cache), Path(args.out)
    cache.mkdir(parents=True, exist_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    folders = []
    for plat in args.platforms:
        folders.append(cache / plat)
        folders[-1].mkdir(exist_ok=True)
        download([pinned(n) for n in BINARY], folders[-1], PLATFORMS[plat])
    folders.append(cache / "any")
    folders[-1].mkdir(exist_ok=True)
    download([f"{n}=={md.version(n)}" for n in PURE], folders[-1], None)

    stage = ROOT / "build" / "stage"
    shutil.rmtree(stage, ignore_errors=True)
    (stage / "wheels").mkdir(parents=True)
    for name in ("__init__.py", "LICENSE", "README.md"):
        shutil.copy2(ROOT / name, stage / name)
    shutil.copytree(ROOT / "bolus_addon", stage / "bolus_addon", ignore=shutil.ignore_patterns("__pycache__"))
    found = sorted({w for d in folders for w in d.glob("*.whl")}, key=lambda w: w.name)
    wheels = [w.name for w in found]
    for w in found:
        shutil.copy2(w, stage / "wheels" / w.name)
    manifest = (ROOT / "blender_manifest.toml").read_text()
    extra = "platforms = [" + ", ".join(f'"{p}"' for p in args.platforms) + "]\n"
    extra += "wheels = [\n" + "".join(f'  "./wheels/{w}",\n' for w in wheels) + "]\n"
    head, sep, tail = manifest.partition("\n[")  # top-level keys must come before the first table
    (stage / "blender_manifest.toml").write_text(head + "\n" + extra + sep + tail)

    import bpy  # the builder ships with Blender (and with the bpy module)

    cli = Path(bpy.utils.system_resource("SCRIPTS")) / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    rc = subprocess.call([sys.executable, str(cli), "build", "--source-dir", str(stage), "--output-dir", str(out),
                          "--split-platforms"])
    if rc == 0:
        print(f"extension zips in {out}: " + ", ".join(sorted(p.name for p in out.glob("bolus-*.zip"))))
    return rc


if __name__ == "__main__":
    os.chdir(ROOT)
    sys.exit(main())
