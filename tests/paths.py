"""Where the tests find the repository, its meshes and its benchmark scripts."""
from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ASSETS = ROOT / "assets"  #: the demo's meshes (shipped with the repository)
DATA = ROOT / "tests" / "data"  #: the larger meshes of the tests and benchmarks (sources in its README)


def data_mesh(name: str) -> Path:
    """A mesh of the repository by file name: assets/ first, then tests/data/."""
    for folder in (ASSETS, DATA):
        if (folder / name).exists():
            return folder / name
    raise FileNotFoundError(f"{name} is neither in {ASSETS} nor in {DATA}")


def import_bench(*names):
    """bench/<name>.py modules imported (bench scripts import bpy only inside their functions);
    one module for one name, a tuple for several."""
    bench = str(ROOT / "bench")
    sys.path.insert(0, bench)
    try:
        mods = tuple(importlib.import_module(n) for n in names)
    finally:
        sys.path.remove(bench)
    return mods[0] if len(names) == 1 else mods


def load_extension_package():
    """Import the repository root as the extension package 'bolus' (as Blender does)."""
    if "bolus" in sys.modules:
        return sys.modules["bolus"]
    spec = importlib.util.spec_from_file_location("bolus", ROOT / "__init__.py", submodule_search_locations=[str(ROOT)])
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bolus"] = mod
    spec.loader.exec_module(mod)
    return mod
