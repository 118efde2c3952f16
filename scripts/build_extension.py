"""Build installable extension zips that carry scipy and scikit-learn (`make extension-wheels`).

Blender ships numpy but not scipy or scikit-learn, which the add-on's core needs.
Blender extensions can bundle Python wheels (manifest ``wheels = [...]``), one zip per
platform.  Blender 4.2-5.0 run Python 3.11 and Blender 5.1+ Python 3.13, so every zip
carries the wheels for both (cp311 and cp313); Blender installs the ones for its Python.
This script

1. downloads, with the venv's pip, the scipy and scikit-learn wheels of every platform
   asked (linux-x64, macos-arm64, macos-x64, windows-x64) for both Pythons -- cp311 at the
   versions pinned in requirements.txt, cp313 at those in requirements-bpy52.txt -- and
   the pure-Python packages they need (joblib, cloudpickle, threadpoolctl, narwhals, at
   the versions in the venv), into a cache folder;
2. stages the extension (manifest, root __init__.py, LICENSE, README.md, bolus_addon/)
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
BINARY = ("scipy", "scikit-learn")
PURE = ("joblib", "cloudpickle", "threadpoolctl", "narwhals")


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
    cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check", "--no-deps",
           "--only-binary=:all:", "--python-version", python, "--implementation", "cp", "-d", str(dest)]
    if platform:
        cmd += ["--platform", platform]
    if subprocess.call(cmd + reqs) != 0:
        raise SystemExit(f"could not download {' '.join(reqs)} for Python {python} on {platform or 'any platform'} "
                         "(no network?)")


def staged_manifest(manifest: str, platforms: list[str], wheels: list[str]) -> str:
    """The manifest text with ``platforms`` and ``wheels = ["./wheels/<name>", ...]`` added."""
    extra = "platforms = [" + ", ".join(f'"{p}"' for p in platforms) + "]\n"
    extra += "wheels = [\n" + "".join(f'  "./wheels/{w}",\n' for w in wheels) + "]\n"
    head, sep, tail = manifest.partition("\n[")  # top-level keys must come before the first table
    return head + "\n" + extra + sep + tail


def zip_wheel_tags(path: Path) -> dict[str, set[str]]:
    """{package: {python tags}} of the wheels inside an extension zip."""
    out: dict[str, set[str]] = {}
    for name in zipfile.ZipFile(path).namelist():
        if name.startswith("wheels/") and name.endswith(".whl"):
            parts = Path(name).name[:-4].split("-")
            out.setdefault(parts[0].lower().replace("_", "-"), set()).add(parts[-3])
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "dist"))
    ap.add_argument("--cache", default=str(ROOT / "build" / "wheels"))
    ap.add_argument("--platforms", nargs="+", default=list(PLATFORMS), choices=list(PLATFORMS))
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

    stage = ROOT / "build" / "stage"
    shutil.rmtree(stage, ignore_errors=True)
    (stage / "wheels").mkdir(parents=True)
    for name in ("__init__.py", "LICENSE", "README.md"):
        shutil.copy2(ROOT / name, stage / name)
    shutil.copytree(ROOT / "bolus_addon", stage / "bolus_addon", ignore=shutil.ignore_patterns("__pycache__"))
    wanted = {f"{n.replace('-', '_')}-{pins[n][tag]}-{tag}" for n in BINARY for tag in PYTHONS}
    found = sorted({w for d in folders for w in d.glob("*.whl")
                    if d.name == "any" or "-".join(w.name.split("-")[:3]) in wanted}, key=lambda w: w.name)
    wheels = [w.name for w in found]
    for w in found:
        shutil.copy2(w, stage / "wheels" / w.name)
    manifest = (ROOT / "blender_manifest.toml").read_text()
    (stage / "blender_manifest.toml").write_text(staged_manifest(manifest, args.platforms, wheels))

    import bpy  # the builder ships with Blender (and with the bpy module)

    cli = Path(bpy.utils.system_resource("SCRIPTS")) / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
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
    return 0


if __name__ == "__main__":
    os.chdir(ROOT)
    sys.exit(main())
