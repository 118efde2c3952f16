"""Helpers shared by the benchmark scripts (not part of the add-on)."""
from __future__ import annotations

import contextlib
import gc
import json
import os
import platform
import resource
import sys
import tempfile
from pathlib import Path


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


def current_rss_kb() -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


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
    if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    for me in list(bpy.data.meshes):
        bpy.data.meshes.remove(me)
    for mat in list(bpy.data.materials):
        if mat.users == 0:
            bpy.data.materials.remove(mat)
    gc.collect()


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


def write_json(path, payload: dict) -> None:
    """Write the figures with the versions and the machine they were measured on."""
    import bpy
    import numpy
    import scipy
    import sklearn

    env = {"bpy": bpy.app.version_string, "python": platform.python_version(), "numpy": numpy.__version__,
           "scipy": scipy.__version__, "sklearn": sklearn.__version__, "cpus": os.cpu_count()}
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({**env, **payload}, indent=2, default=float))
    print(f"figures written to {out}")
