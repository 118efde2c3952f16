"""The core's tests: bpy-free, one folder per stage of the method (tests/core/<stage>/).

Every test here is marked ``core``, so ``pytest -m core`` runs the core alone on any Python with
numpy and scipy (no Blender needed).
"""
import pytest

_HERE = __file__.rsplit("conftest.py", 1)[0]


def pytest_collection_modifyitems(items):
    for item in items:
        if str(item.fspath).startswith(_HERE):
            item.add_marker(pytest.mark.core)
