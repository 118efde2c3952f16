"""The Blender tests: the add-on registered as Blender registers it, driven through
``bpy.ops.bolus.*`` as a user or a script does (fixtures ``bpy_addon`` and ``scene`` in
tests/conftest.py). Every test here is marked ``blender``, so ``-m "not blender"`` leaves them out
even where a file forgets its ``pytestmark``."""
import pytest

_HERE = __file__.rsplit("conftest.py", 1)[0]


def pytest_collection_modifyitems(items):
    for item in items:
        if str(item.fspath).startswith(_HERE):
            item.add_marker(pytest.mark.blender)
