"""docs/operators.md, the script writer's reference, agrees with the registered add-on: its
generated tables are what the operators and Scene.bolus say of themselves, and every operator
has its row in the "leaves behind" table."""
from __future__ import annotations

import re
import sys

import pytest
from paths import ROOT

pytestmark = pytest.mark.blender


@pytest.fixture(scope="module")
def operators_doc(bpy_addon):
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import operators_doc
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    return operators_doc


def test_the_page_is_the_one_the_code_generates(operators_doc):
    assert operators_doc.DOC.read_text(encoding="utf-8") == operators_doc.render(), \
        "docs/operators.md is stale: run scripts/operators_doc.py"


def test_every_registered_operator_has_its_row_and_section(bpy_addon):
    text = (ROOT / "docs" / "operators.md").read_text(encoding="utf-8")
    registered = {c.bl_idname.split(".", 1)[1] for c in bpy_addon.types.Operator.__subclasses__()
                  if getattr(c, "bl_idname", "").startswith("bolus.")}
    rows = set(re.findall(r"^\| `(\w+)` \| ", text[text.index("| operator | leaves behind |"):], flags=re.M))
    sections = set(re.findall(r"^### `bpy\.ops\.bolus\.(\w+)`", text, flags=re.M))
    assert registered and rows >= registered and sections == registered, (registered - rows, sections ^ registered)
