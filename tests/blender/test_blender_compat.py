"""bolus_addon.blender.compat: the Blender-version differences, on every Blender `make test` runs (smoke)."""
from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np
import pytest
from bpy_helpers import make_object

pytestmark = [pytest.mark.blender, pytest.mark.smoke]

ROOT = Path(__file__).resolve().parents[2]


def test_version_and_at_least(bpy_addon):
    from bolus_addon.blender import compat

    bpy = bpy_addon
    v = compat.version()
    assert v == tuple(bpy.app.version[:3]) and v >= (4, 2, 0)
    assert compat.at_least(*v) and compat.at_least(4, 2) and not compat.at_least(v[0] + 1)
    assert compat.at_least(v[0], v[1] + 1) is False


def test_uv_unwrap_methods_are_the_ones_that_run(bpy_addon, scene):
    """MINIMUM_STRETCH (SLIM) exists from Blender 4.3; every listed method unwraps, others are refused."""
    from bolus_addon.blender import compat

    bpy = bpy_addon
    methods = compat.uv_unwrap_methods()
    assert {"ANGLE_BASED", "CONFORMAL"} <= set(methods)
    assert ("MINIMUM_STRETCH" in methods) == (compat.version() >= (4, 3, 0))
    assert compat.has_uv_unwrap_method("CONFORMAL") and not compat.has_uv_unwrap_method("NO_SUCH_METHOD")
    x, y = np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 5))
    V = np.stack([x.ravel(), y.ravel(), 0.2 * x.ravel() ** 2], 1)
    ids = np.arange(25).reshape(5, 5)
    F = np.concatenate([np.stack([ids[:-1, :-1], ids[:-1, 1:], ids[1:, 1:]], -1).reshape(-1, 3),
                        np.stack([ids[:-1, :-1], ids[1:, 1:], ids[1:, :-1]], -1).reshape(-1, 3)])
    ob = make_object(bpy, V, F, name="sheet")
    ob.data.uv_layers.new(name="UVMap")
    bpy.ops.object.mode_set(mode="EDIT")
    try:
        bpy.ops.mesh.select_all(action="SELECT")
        for m in methods:
            assert bpy.ops.uv.unwrap(method=m, margin=0.0) == {"FINISHED"}, m
        with pytest.raises(TypeError):
            bpy.ops.uv.unwrap(method="NO_SUCH_METHOD")
        if "MINIMUM_STRETCH" not in methods:
            with pytest.raises(TypeError):
                bpy.ops.uv.unwrap(method="MINIMUM_STRETCH")
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")


def test_stl_export_writes_binary_mm_in_world_space(bpy_addon, scene, tmp_path):
    from bolus_addon.blender import compat

    bpy = bpy_addon
    bpy.ops.mesh.primitive_cube_add(size=0.01, location=(0.1, 0.0, 0.0))  # a 10 mm cube, 100 mm along x
    cube = bpy.context.active_object
    for o in bpy.context.view_layer.objects:
        o.select_set(o is cube)
    path = tmp_path / "cube.stl"
    compat.stl_export(str(path), 1000.0)  # 1 unit = 1 m = 1000 mm
    data = path.read_bytes()
    (n,) = struct.unpack("<I", data[80:84])
    assert n == 12 and len(data) == 84 + 50 * n  # binary STL, 12 triangles
    rec = np.frombuffer(data[84:], dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    P = rec["v"].reshape(-1, 3)
    assert np.allclose(P.min(axis=0), [95, -5, -5], atol=1e-3) and np.allclose(P.max(axis=0), [105, 5, 5], atol=1e-3)


def test_version_checks_live_only_in_compat():
    """'Version differences guarded in one place': no other module of the Blender layer asks."""
    pattern = re.compile(r"bpy\.app\.version|hasattr\(bpy\.ops|getattr\(bpy\.ops|bpy\.app\.version_string")
    hits = [f"{p.relative_to(ROOT)}:{no}: {line.strip()}" for p in (ROOT / "bolus_addon").glob("*.py")
            if p.name != "compat.py"
            for no, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if pattern.search(line)]
    assert not hits, "version-dependent calls belong in bolus_addon/compat.py:\n" + "\n".join(hits)
