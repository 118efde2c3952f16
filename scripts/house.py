#!/usr/bin/env python3
"""The shape of the house: packages, modules, import cycles, sizes and stray references.

    python scripts/house.py            # the report; exit 1 when a cap below is broken
    python scripts/house.py --json     # the same figures as JSON

Imports are read with ``ast`` (those inside functions count too), so nothing is imported or
run.  The caps are the project's: core modules <= 500 lines, Blender-layer modules <= 300,
functions <= 80, module docstrings <= 25 (design notes go to docs/design/), no import cycle, no upward import between the core's stages
(`tests/test_layout.py` checks the same with `layout_rules`), no issue numbers in code,
tests, benchmarks or scripts, and no tracked file that points outside the repository.
"""
from __future__ import annotations

import argparse
import ast
import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "bolus_addon"
CORE_MODULE_MAX, BLENDER_MODULE_MAX, FUNCTION_MAX = 500, 300, 80
DOCSTRING_MAX = 25  #: lines of a module docstring; design notes go to docs/design/<stage>.md
#: the core's stages, each with the stages it may import (besides itself and the shared basics)
STAGES = {
    "mesh": set(),
    "analysis": {"mesh"},
    "cuts": {"mesh", "analysis"},
    "improve": {"mesh", "analysis"},
    "unfold": {"mesh", "analysis"},
    "pattern": {"mesh", "analysis", "cuts", "improve", "unfold"},
    "solid": {"mesh", "analysis"},
    "printing": {"mesh", "analysis"},
    "retrieval": {"mesh", "analysis"},
    "dicom": {"mesh", "analysis", "solid"},
}
BASICS_MAX = 6  #: small shared modules directly in core/
ISSUE_RE = re.compile(r"\bissues? [0-9]+|\bissue[- ]?#?[0-9]+\b", re.I)
OUTSIDE_RE = re.compile(r"\.\.[/\\]shared\b|\bshared[/\\](meshes|seed|SPEC)")  # POSIX or Windows separators


def module_files(root: Path = ROOT) -> dict[str, Path]:
    """{dotted module name: file} of every .py file of the add-on package."""
    out = {}
    for f in sorted((root / PACKAGE).rglob("*.py")):
        parts = f.relative_to(root).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = f
    return out


def imports_of(name: str, path: Path, known: set[str]) -> set[str]:
    """The add-on modules `name` imports anywhere in its file (module level or inside functions)."""
    is_pkg = path.name == "__init__.py"
    pkg = name if is_pkg else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                parts = pkg.split(".")
                if node.level - 1 > len(parts):
                    continue
                base = ".".join(parts[: len(parts) - (node.level - 1)] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for a in node.names:  # a submodule by name, else a name of the module `base`
                target = f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                if target in known and target != name and not name.startswith(target + "."):
                    found.add(target)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name in known}
    return found


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    files = module_files(root)
    known = set(files)
    return {m: imports_of(m, f, known) for m, f in files.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(max(10_000, sys.getrecursionlimit()))

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def layer_of(module: str) -> tuple[str, str | None]:
    """('core', stage or None for the shared basics) | ('blender', None) | ('operators', name) | ('top', None)."""
    parts = module.split(".")
    if len(parts) < 2:
        return "top", None
    if parts[1] == "core":
        return "core", (parts[2] if len(parts) > 3 or (len(parts) == 3 and parts[2] in STAGES) else None)
    if parts[1] in ("blender", "operators"):
        return parts[1], parts[2] if len(parts) > 2 else None
    return "top", None


def layout_violations(graph: dict[str, set[str]]) -> list[str]:
    """Every import against the house rules, as 'a -> b: why'."""
    bad = []
    for a, targets in sorted(graph.items()):
        la, sa = layer_of(a)
        for b in sorted(targets):
            lb, sb = layer_of(b)
            why = None
            if la == "core" and lb != "core":
                why = "the core imports nothing of the Blender layer"
            elif la == "core" and sa is None and sb is not None and b != f"{PACKAGE}.core":
                why = "a shared basic imports a stage"
            elif la == "core" and sa is not None and sb is not None and sb != sa and sb not in STAGES[sa]:
                why = f"stage '{sa}' may not import stage '{sb}'"
            elif la == "blender" and lb == "operators":
                why = "the Blender helpers import no operator module"
            elif la == "operators" and lb == "operators" and sa is not None and sb is not None and sa != sb:
                why = "an operator module imports another operator module"
            elif la == "operators" and lb == "top" and b != PACKAGE:
                why = "an operator module imports the panel"
            elif a == f"{PACKAGE}.panel" and lb == "operators" and b != f"{PACKAGE}.operators":
                why = "the panel refers to operators by bl_idname only"
            if why:
                bad.append(f"{a} -> {b}: {why}")
    return bad


def bpy_in_core(root: Path = ROOT) -> list[str]:
    bad = []
    for name, f in module_files(root).items():
        if layer_of(name)[0] != "core":
            continue
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            mods = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
            bad += [f"{name} imports {m}" for m in mods if m.split(".")[0] in {"bpy", "bmesh", "mathutils", "gpu"}]
    return bad


def sizes(root: Path = ROOT) -> tuple[list[tuple[int, str, int]], list[tuple[int, str, str]]]:
    """([(lines, module, cap)], [(lines, module, function)]) of the add-on, longest first."""
    mods, funcs = [], []
    for name, f in module_files(root).items():
        text = f.read_text(encoding="utf-8")
        cap = CORE_MODULE_MAX if layer_of(name)[0] == "core" else BLENDER_MODULE_MAX
        mods.append((len(text.splitlines()), name, cap))
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                funcs.append((node.end_lineno - node.lineno + 1, name, node.name))
    return sorted(mods, reverse=True), sorted(funcs, reverse=True)


def long_docstrings(root: Path = ROOT) -> list[tuple[int, str]]:
    """[(lines, module)] of the module docstrings over DOCSTRING_MAX lines, longest first."""
    out = []
    for name, f in module_files(root).items():
        doc = ast.get_docstring(ast.parse(f.read_text(encoding="utf-8")), clean=False)
        if doc and doc.count("\n") + 1 > DOCSTRING_MAX:
            out.append((doc.count("\n") + 1, name))
    return sorted(out, reverse=True)


def tracked_files(root: Path = ROOT) -> list[Path]:
    try:
        out = subprocess.run(["git", "ls-files"], cwd=root, capture_output=True, text=True, check=True).stdout
        return [root / p for p in out.splitlines() if (root / p).is_file()]
    except (OSError, subprocess.CalledProcessError):
        return [p for p in root.rglob("*") if p.is_file() and ".git" not in p.parts and ".venv" not in p.parts[0]]


def reference_hits(root: Path = ROOT) -> tuple[list[str], list[str]]:
    """(issue-number references in code, tests, bench and scripts; tracked files pointing outside the repository)."""
    issue, outside = [], []
    for p in tracked_files(root):
        rel = p.relative_to(root).as_posix()
        if p.suffix in {".obj", ".npz", ".png", ".stl", ".blend"}:
            continue
        try:
            text = p.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue
        code = rel.split("/")[0] in {PACKAGE, "tests", "bench", "scripts"}
        for no, line in enumerate(text.splitlines(), 1):
            if code and ISSUE_RE.search(line):
                issue.append(f"{rel}:{no}: {line.strip()[:100]}")
            if OUTSIDE_RE.search(line):
                outside.append(f"{rel}:{no}: {line.strip()[:100]}")
    return issue, outside


def report(root: Path = ROOT) -> dict:
    graph = import_graph(root)
    mods, funcs = sizes(root)
    issue, outside = reference_hits(root)
    packages = sorted(m for m, f in module_files(root).items() if f.name == "__init__.py")
    basics = sorted(m for m in graph if layer_of(m) == ("core", None) and m != f"{PACKAGE}.core")
    return {
        "modules": len(graph), "packages": packages, "basics": basics,
        "cycles": cycles(graph), "layout_violations": layout_violations(graph), "bpy_in_core": bpy_in_core(root),
        "modules_over_cap": [(n, m, c) for n, m, c in mods if n > c], "longest_modules": mods[:10],
        "functions_over_cap": [(n, m, fn) for n, m, fn in funcs if n > FUNCTION_MAX], "longest_functions": funcs[:10],
        "long_docstrings": long_docstrings(root),
        "issue_references": issue, "outside_references": outside,
    }


def broken(r: dict) -> list[str]:
    checks = [("import cycles", r["cycles"]), ("imports against the layout", r["layout_violations"]),
              ("Blender imports in the core", r["bpy_in_core"]), ("modules over their cap", r["modules_over_cap"]),
              ("functions over 80 lines", r["functions_over_cap"]),
              (f"module docstrings over {DOCSTRING_MAX} lines", r["long_docstrings"]), ("issue-number references", r["issue_references"]),
              ("references outside the repository", r["outside_references"])]
    out = [f"{len(v)} {what}" for what, v in checks if v]
    if len(r["basics"]) > BASICS_MAX:
        out.append(f"{len(r['basics'])} shared basics in core/ (at most {BASICS_MAX})")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = ap.parse_args(argv)
    r = report()
    if args.json:
        print(json.dumps(r, indent=1))
        return 1 if broken(r) else 0
    short = lambda m: m.removeprefix(PACKAGE + ".")  # noqa: E731
    print(f"{r['modules']} modules in {len(r['packages'])} packages: " + ", ".join(short(p) for p in r["packages"]))
    print(f"shared basics in core/ ({len(r['basics'])}, at most {BASICS_MAX}): " + ", ".join(short(b) for b in r["basics"]))
    print(f"import cycles: {len(r['cycles'])}")
    for c in r["cycles"]:
        print("   ", " <-> ".join(short(m) for m in c))
    print(f"imports against the layout: {len(r['layout_violations'])}")
    for v in r["layout_violations"]:
        print("   ", v.replace(PACKAGE + ".", ""))
    print(f"Blender imports in the core: {len(r['bpy_in_core'])}")
    print(f"longest modules (cap: core {CORE_MODULE_MAX}, Blender layer {BLENDER_MODULE_MAX} lines):")
    for n, m, c in r["longest_modules"]:
        print(f"    {n:5d}  {short(m)}{'  OVER' if n > c else ''}")
    print(f"longest functions (cap {FUNCTION_MAX} lines):")
    for n, m, fn in r["longest_functions"]:
        print(f"    {n:5d}  {short(m)}.{fn}{'  OVER' if n > FUNCTION_MAX else ''}")
    print(f"module docstrings over {DOCSTRING_MAX} lines (design notes: docs/design/): {len(r['long_docstrings'])}")
    for n, m in r["long_docstrings"]:
        print(f"    {n:5d}  {short(m)}")
    print(f"issue-number references in code, tests, benchmarks, scripts: {len(r['issue_references'])}")
    for h in r["issue_references"][:10]:
        print("   ", h)
    print(f"references outside the repository in tracked files: {len(r['outside_references'])}")
    for h in r["outside_references"][:10]:
        print("   ", h)
    bad = broken(r)
    print("caps: " + ("all kept" if not bad else "BROKEN: " + "; ".join(bad)))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
