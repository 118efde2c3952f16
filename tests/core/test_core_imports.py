"""The core must stay bpy-free: numpy, scipy, scikit-learn and the standard library only."""
import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CORE = ROOT / "bolus_addon" / "core"
FORBIDDEN = {"bpy", "bmesh", "mathutils", "gpu", "bl_math", "bpy_extras"}
ALLOWED_THIRD_PARTY = {"numpy", "scipy", "sklearn", "manifold3d", "igl", "ezdxf", "fpdf", "threadpoolctl", "joblib", "pydicom"}  # manifold3d: the volume library; igl (libigl): the compiled marching cubes; ezdxf, fpdf (fpdf2): the DXF and PDF writers; threadpoolctl, joblib (scikit-learn dependencies, bundled): one BLAS thread for L-BFGS-B, the retrieval library built in threads; pydicom: the planning CT and RTSTRUCT


def imported_top_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    mods = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            mods |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            mods.add(node.module.split(".")[0])
    return mods


def test_core_imports_no_blender_module():
    files = sorted(CORE.rglob("*.py"))
    assert len(files) >= 5
    stdlib = set(sys.stdlib_module_names)
    for f in files:
        mods = imported_top_modules(f)
        assert not (mods & FORBIDDEN), f"{f.name} imports {mods & FORBIDDEN}"
        unknown = mods - stdlib - ALLOWED_THIRD_PARTY - {"__future__"}
        assert not unknown, f"{f.name} imports {unknown}: the core may use numpy, scipy, scikit-learn and the bundled libraries only"


def test_core_runs_with_blender_modules_blocked():
    """Import the core and run an analysis in a fresh interpreter where bpy cannot be imported."""
    code = (
        "import sys\n"
        "for m in ('bpy','bmesh','mathutils','gpu'): sys.modules[m] = None\n"
        f"sys.path.insert(0, {str(ROOT)!r}); sys.path.insert(0, {str(ROOT / 'tests')!r})\n"
        "from meshgen import icosphere\n"
        "from bolus_addon.core.analysis.saliency import analyse\n"
        "from bolus_addon.core.analysis.spectral import segment\n"
        "V, F = icosphere(2, 50.0)\n"
        "print(round(analyse(V, F).sum_varpi, 6), segment(V, F, 2).patch_count)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    total, patches = out.stdout.split()
    assert float(total) > 0 and int(patches) == 2
