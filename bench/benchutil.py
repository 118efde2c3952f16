"""Helpers shared by the benchmark scripts (not part of the add-on).

Every bench script imports this module first: it puts the repository root and
``tests/`` (for ``meshgen``) on ``sys.path``.  It also holds the command line every
script shares (``parser``), the text/markdown tables (``Table``), the end of every run
(``finish``: total time, ``--json``, ``--markdown``) and the header of
``docs/benchmarks.md`` that ``make bench`` writes once before the scripts append to it:

    .venv/bin/python bench/benchutil.py --header docs/benchmarks.md
"""
from __future__ import annotations

import argparse
import contextlib
import datetime
import gc
import json
import os
import platform
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for _p in (ROOT, ROOT / "tests"):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

from paths import DATA, data_mesh  # noqa: E402 (tests/paths.py: assets/, then tests/data/)


def mesh_exists(name: str) -> bool:
    """Whether the repository has the mesh ``name`` (assets/ or tests/data/)."""
    try:
        data_mesh(name)
    except FileNotFoundError:
        return False
    return True

BENCH_DOC = ROOT / "docs" / "benchmarks.md"


# ----------------------------------------------------------------------------- command line and results


def parser(doc: str, quick_help: str, repeat: int | None = 3) -> argparse.ArgumentParser:
    """The options every bench script has: --quick, --json, --markdown (and --repeat unless repeat is None)."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help=quick_help)
    ap.add_argument("--json", metavar="PATH", help="also write the figures as JSON to PATH")
    ap.add_argument("--markdown", metavar="FILE",
                    help="append the tables as markdown to FILE (make bench: docs/benchmarks.md)")
    if repeat is not None:
        ap.add_argument("--repeat", type=int, default=repeat,
                        help=f"timed runs of each call, the best is kept (default {repeat})")
    return ap


def error_row(key: str, name: str, exc: BaseException) -> dict:
    """The row of a case that failed: a benchmark reports it and goes on with the next."""
    text = f"{type(exc).__name__}: {exc}"
    print(f"   FAILED: {text}")
    return {key: name, "error": text.splitlines()[0] if text.strip() else type(exc).__name__}


def finish(args, payload: dict, total_s: float, markdown: str | None = None) -> None:
    """End of a run: the total time; the JSON figures (--json); the markdown section appended (--markdown)."""
    print(f"total bench time {total_s:.1f} s")
    if getattr(args, "json", None):
        write_json(args.json, {**payload, "total_s": total_s})
    if getattr(args, "markdown", None) and markdown is not None:
        append_markdown(args.markdown, markdown + f"\n\n_Whole script: {total_s:.0f} s._\n")


def pct(x, digits: int = 2) -> str:
    """A fraction as a percentage without the sign ("n/a" when missing)."""
    return "n/a" if x is None else f"{100.0 * x:.{digits}f}"


class Table:
    """Rows of already formatted cells, printed as aligned text or written as a markdown table.

    columns: (title, align) pairs, align "<" (text) or ">" (figures).
    """

    def __init__(self, columns):
        self.columns = [(str(t), a) for t, a in columns]
        self.rows: list[list[str]] = []

    def add(self, *cells) -> None:
        if len(cells) != len(self.columns):
            raise ValueError(f"{len(cells)} cells for {len(self.columns)} columns")
        self.rows.append([str(c) for c in cells])

    def add_error(self, first: str, text: str) -> None:
        """A row that says why a case has no figures (first cell, then the text)."""
        self.rows.append([str(first), f"ERROR: {text}"] + [""] * (len(self.columns) - 2))

    def text(self, indent: str = "") -> str:
        w = [len(t) for t, _ in self.columns]
        for r in self.rows:
            if not r[1].startswith("ERROR:"):
                w = [max(a, len(c)) for a, c in zip(w, r)]
        def line(cells):
            return indent + " ".join(f"{c:{a}{n}}" for c, (_, a), n in zip(cells, self.columns, w))

        head = line([t for t, _ in self.columns])
        out = [head, indent + "-" * (len(head) - len(indent))]
        for r in self.rows:
            out.append(f"{indent}{r[0]:<{w[0]}} {r[1]}" if r[1].startswith("ERROR:") else line(r).rstrip())
        return "\n".join(out)

    def markdown(self) -> str:
        esc = lambda c: c.replace("|", "\\|")  # noqa: E731
        out = ["| " + " | ".join(esc(t) for t, _ in self.columns) + " |",
               "|" + "|".join("---:" if a == ">" else "---" for _, a in self.columns) + "|"]
        out += ["| " + " | ".join(esc(c) for c in r) + " |" for r in self.rows]
        return "\n".join(out)


# ----------------------------------------------------------------------------- versions, JSON, markdown


def versions() -> dict:
    """Versions of what the figures depend on (bpy only if this process has imported it)."""
    import numpy
    import scipy

    out = {"python": platform.python_version(), "numpy": numpy.__version__, "scipy": scipy.__version__}
    with contextlib.suppress(ImportError):
        import sklearn

        out["sklearn"] = sklearn.__version__
    if "bpy" in sys.modules:
        out["bpy"] = sys.modules["bpy"].app.version_string
    out["cpus"] = os.cpu_count()
    return out


def write_json(path, payload: dict) -> None:
    """Write the figures with the versions and the machine they were measured on."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({**versions(), **payload}, indent=2, default=float))
    print(f"figures written to {out}")


def append_markdown(path, text: str) -> None:
    """Append one section (a heading, what was run, its tables) to the markdown file."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("a", encoding="utf-8") as fh:
        fh.write("\n" + text.strip("\n") + "\n")
    print(f"tables appended to {out}")


def replace_section(path, section: str, text: str) -> None:
    """Replace the section headed ``section`` of the markdown file (up to the next '## ' heading)
    with text, or append text when the file has no such section."""
    p = Path(path)
    old = p.read_text(encoding="utf-8") if p.exists() else ""
    body = text.strip("\n") + "\n"
    i = old.find(section)
    if i < 0:
        append_markdown(path, text)
        return
    m = re.search(r"^## ", old[i + len(section):], flags=re.M)
    j = len(old) if m is None else i + len(section) + m.start()
    p.write_text(old[:i] + body + ("\n" + old[j:] if j < len(old) else ""), encoding="utf-8")
    print(f"section replaced in {p}")


def run_line(script: str, argv) -> str:
    """The command a section was made with, when it finished and how busy the machine was (markdown)."""
    args = [a if " " not in a else repr(a) for a in (argv if argv is not None else sys.argv[1:])]
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    cmd = " ".join([".venv/bin/python", f"bench/{script}", *args])
    return f"`{cmd}`, finished {stamp} ({load_text()})."


def load_text() -> str:
    """The machine's 1-minute load average against its CPU count (timings on a busy machine are slower)."""
    try:
        return f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    except OSError:
        return "load average unknown"


def _cpu_model() -> str:
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def _memory_gb() -> str:
    with contextlib.suppress(OSError, ValueError, IndexError):
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return f"{int(line.split()[1]) / 1024 ** 2:.0f} GB"
    return "unknown"


def _commit() -> str:
    try:
        rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown (not a git checkout)"
    return rev + (" with uncommitted changes" if dirty else "")


def markdown_header() -> str:
    """The top of docs/benchmarks.md: what it is, when and where it was measured."""
    with contextlib.suppress(ImportError):
        import bpy  # noqa: F401  (its version goes into the header)
    v = versions()
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    rows = [("date", stamp), ("commit", _commit()), ("load at the start", load_text()),
            ("machine", f"{platform.system()} {platform.machine()}, {_cpu_model()}, {v['cpus']} CPUs, "
                        f"{_memory_gb()} RAM"),
            ("Blender (bpy module)", v.get("bpy", "not installed")), ("Python", v["python"]),
            ("numpy / scipy / scikit-learn", f"{v['numpy']} / {v['scipy']} / {v.get('sklearn', 'n/a')}")]
    t = Table([("", "<"), ("", "<")])
    for k, val in rows:
        t.add(k, val)
    return ("# Benchmarks\n\n"
            "Written by `make bench` (each script in `bench/` run with `--markdown docs/benchmarks.md`); "
            "do not edit by hand, run `make bench` again.\n"
            "The figures are printed and recorded, not asserted (speed and memory targets live here, not in "
            "the tests).\n"
            "Every table puts us beside a peer measured in the same run on the same input. The machine is "
            "shared (other jobs ran beside these: see the load averages), so compare times within one table, "
            "not across runs.\n\n" + t.markdown() + "\n")


# ----------------------------------------------------------------------------- process and Blender helpers


@contextlib.contextmanager
def captured_output(enabled: bool = True):
    """Redirect the process's stdout/stderr (fds 1, 2) to a temp file.

    Blender prints every operator report ("Info: ...") itself; the bench keeps them
    out of its output and shows them only when an operator does not finish.
    Yields a callable returning the captured text.
    """
    if not enabled:
        yield lambda: ""
        return
    sys.stdout.flush()
    sys.stderr.flush()
    tmp = tempfile.TemporaryFile(mode="w+b")
    saved = os.dup(1), os.dup(2)
    os.dup2(tmp.fileno(), 1)
    os.dup2(tmp.fileno(), 2)

    def text() -> str:
        tmp.seek(0)
        return tmp.read().decode("utf-8", "replace")

    try:
        yield text
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        os.close(saved[0])
        os.close(saved[1])


def status_kb(field: str) -> int:
    """A kB figure of this process from /proc/self/status (VmRSS, VmHWM, ...); 0 where there is none."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return 0


def current_rss_kb() -> int:
    return status_kb("VmRSS")


def reset_peak_rss() -> bool:
    """Reset the kernel's RSS high-water mark (Linux >= 4.0, /proc/self/clear_refs '5')."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def maxrss_kb() -> int:
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r // 1024 if sys.platform == "darwin" else r  # bytes on macOS, KiB on Linux


def clean_scene(bpy) -> None:
    """An empty scene (tests/blender_scene.py, shared with the tests' fixture)."""
    from blender_scene import empty_scene

    empty_scene(bpy)


def timed_uv_operator(bpy, ob, op, what: str, **kw) -> tuple[float, int, list[str]]:
    """Time one UV operator call on every face of ob (Edit Mode, face select, all revealed and selected).

    Only the call op(**kw) is timed; Object Mode afterwards.  Returns (seconds, faces
    selected during the call, the lines the operator printed); raises if it did not finish.
    """
    bpy.context.view_layer.objects.active = ob
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_mode(type="FACE")
    bpy.ops.mesh.reveal()
    bpy.ops.mesh.select_all(action="SELECT")
    ob.update_from_editmode()
    selected = int(ob.data.total_face_sel)
    gc.collect()
    with captured_output() as out:
        t0 = time.perf_counter()
        res = op(**kw)
        dt = time.perf_counter() - t0
    bpy.ops.object.mode_set(mode="OBJECT")
    if res != {"FINISHED"}:
        raise RuntimeError(f"{what} returned {res}:\n{out()}")
    return dt, selected, [ln.strip() for ln in out().splitlines() if ln.strip()]


def import_mesh(bpy, path, scale_length: float):
    """Import one OBJ as the active object in a scene where 1 unit = scale_length m."""
    with captured_output() as out:
        bpy.ops.wm.obj_import(filepath=str(path))
    objs = [o for o in bpy.context.selected_objects if o.type == "MESH"]
    if len(objs) != 1:
        raise RuntimeError(f"{Path(path).name}: expected one mesh object, the importer made {len(objs)}\n{out()}")
    ob = objs[0]
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    bpy.context.scene.unit_settings.system = "METRIC"
    bpy.context.scene.unit_settings.scale_length = scale_length
    return ob


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Write the header of docs/benchmarks.md (make bench does).")
    ap.add_argument("--header", metavar="FILE", required=True, help="write the header to FILE, replacing it")
    args = ap.parse_args(argv)
    out = Path(args.header)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(markdown_header(), encoding="utf-8")
    print(f"header written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
