"""Fixtures of the whole suite.

Core tests (tests/core/) import only `bolus_addon.core`.  Blender tests (tests/blender/, marker
``blender``) use ``bpy_addon``, which registers the add-on through the extension's root
``__init__.py`` exactly as Blender does, and ``scene``, which empties the file between tests.
Meshes come from ``assets/`` and ``tests/data/`` (`paths.data_mesh`).
"""
from __future__ import annotations

import sys

import pytest
from blender_scene import empty_scene
from paths import ROOT, load_extension_package

sys.path.insert(0, str(ROOT))


@pytest.fixture(scope="session")
def bpy_addon():
    bpy = pytest.importorskip("bpy")
    ext = load_extension_package()
    ext.register()
    yield bpy
    ext.unregister()


@pytest.fixture
def scene(bpy_addon):
    """An empty scene with the default unit scale (1 unit = 1 m)."""
    sc = empty_scene(bpy_addon)
    sc.unit_settings.system = "METRIC"
    sc.unit_settings.scale_length = 1.0
    return sc
