"""docs/operators.md from the registered operators: every operator, its parameters (type,
default, range, unit), and the Scene.bolus settings, around the hand-written contract (units,
frames, objects, attributes, custom properties, quality measures).

    .venv/bin/python scripts/operators_doc.py            # rewrite docs/operators.md
    .venv/bin/python scripts/operators_doc.py --check    # exit 1 when docs/operators.md is stale

The tables are read from Blender's own description of each class (``bl_rna``), so the page
cannot drift from the code; tests/blender/test_operators_doc.py runs ``--check``'s comparison.
"""
from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "operators.md"
TEMPLATE = ROOT / "docs" / "operators.template.md"
SKIP = {"rna_type"}


def load_extension():
    """Register the repository as the extension package 'bolus', as Blender does."""
    if "bolus" not in sys.modules:
        spec = importlib.util.spec_from_file_location("bolus", ROOT / "__init__.py",
                                                      submodule_search_locations=[str(ROOT)])
        mod = importlib.util.module_from_spec(spec)
        sys.modules["bolus"] = mod
        spec.loader.exec_module(mod)
        mod.register()
    return sys.modules["bolus"]


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _default(p) -> str:
    if p.type in ("POINTER", "COLLECTION"):
        return "—"
    if p.type == "ENUM":
        return f"`'{p.default}'`" if not p.is_enum_flag else "`" + repr(set(p.default_flag)) + "`"
    if p.type == "STRING":
        return f'`"{p.default}"`'
    if getattr(p, "array_length", 0):
        return "`" + repr(tuple(round(v, 6) if isinstance(v, float) else v for v in p.default_array)) + "`"
    if p.type == "FLOAT":
        return f"`{p.default:g}`"
    return f"`{p.default}`"


def _range(p) -> str:
    if p.type == "ENUM":
        return ", ".join(f"`{i.identifier}`" for i in p.enum_items)
    if p.type in ("FLOAT", "INT"):
        lo, hi = p.hard_min, p.hard_max
        big = 1e30 if p.type == "FLOAT" else 2**31 - 2
        parts = []
        if lo > -big:
            parts.append(f"≥ {lo:g}")
        if hi < big:
            parts.append(f"≤ {hi:g}")
        unit = "" if p.unit == "NONE" else f" ({p.unit.lower()})"
        return " ".join(parts) + unit
    if p.type == "STRING" and p.subtype != "NONE":
        return p.subtype.lower().replace("_", " ")
    return ""


def property_rows(rna, base) -> list[str]:
    """Rows of the properties `rna` adds to its base type (an Operator's or a PropertyGroup's own)."""
    inherited = {p.identifier for p in base.bl_rna.properties}
    rows = []
    for p in rna.properties:
        if p.identifier in SKIP or p.identifier in inherited or p.is_hidden:
            continue
        meaning = f"{_cell(p.name)}: {_cell(p.description)}" if p.description else _cell(p.name)
        rows.append(f"| `{p.identifier}` | {p.type.lower()} | {_default(p)} | {_cell(_range(p))} | {meaning} |")
    return rows


def operator_section(bpy) -> str:
    ops = sorted((c for c in bpy.types.Operator.__subclasses__() if getattr(c, "bl_idname", "").startswith("bolus.")),
                 key=lambda c: c.bl_idname)
    out = []
    for cls in ops:
        rna = cls.bl_rna
        name = cls.bl_idname.split(".", 1)[1]
        out += [f"### `bpy.ops.bolus.{name}` — {cls.bl_label}", "", _cell(rna.description or cls.__doc__ or ""), ""]
        params = getattr(bpy.ops.bolus, name).get_rna_type()  # the operator's own parameters
        rows = property_rows(params, bpy.types.OperatorProperties)
        if rows:
            out += ["| parameter | type | default | range | meaning |", "|---|---|---|---|---|", *rows, ""]
        else:
            out += ["No parameters.", ""]
    return "\n".join(out).rstrip() + "\n"


def settings_section(bpy) -> str:
    rna = bpy.types.Scene.bl_rna.properties["bolus"].fixed_type
    rows = property_rows(rna, bpy.types.PropertyGroup)
    return "\n".join(["| setting | type | default | range | meaning |", "|---|---|---|---|---|", *rows]) + "\n"


def render() -> str:
    load_extension()
    import bpy

    text = TEMPLATE.read_text(encoding="utf-8")
    text = text.replace("<!-- operators -->\n", operator_section(bpy))
    text = text.replace("<!-- settings -->\n", settings_section(bpy))
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 when docs/operators.md differs from the code")
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        same = DOC.exists() and DOC.read_text(encoding="utf-8") == text
        print("docs/operators.md is " + ("up to date" if same else "stale: run scripts/operators_doc.py"))
        return 0 if same else 1
    DOC.write_text(text, encoding="utf-8")
    print(f"wrote {DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
