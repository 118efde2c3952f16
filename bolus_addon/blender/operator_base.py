"""The operators' common base `BolusOperator` and the names fixed by SPEC.md.

The operators `bpy.ops.bolus.*` (contract: ../shared/SPEC.md) live in one module per
step: analysis_ops (saliency preview, segment), cut_ops, pattern_ops, print_ops.
Each operator is thin: read the region (mesh_io), call the core, write the results,
report.  Everything is computed before the mesh is touched, so an error leaves the
mesh exactly as it was; `BolusError` becomes `self.report({'ERROR'}, ...)` and
``{'CANCELLED'}``, and an unexpected exception is reported the same way (with the
traceback on the console) instead of reaching the user.

Long operators (issue 14 point 4: saliency_preview, segment, smooth_cuts, select_area,
make_shell, print_segment, orient_parts) split their work in three:

- ``prepare(context) -> job`` (main thread): read the region, copy the operator's
  settings into the job, validate (`BolusError` refuses as before).  It may instead
  return a result set such as ``{'FINISHED'}`` when there is nothing to compute.
- ``compute(job, progress) -> result`` (a staticmethod: it cannot see the operator or
  bpy): only core calls, reporting ``progress(fraction, text)``; it may run in a worker
  thread.
- ``finish(context, job, result) -> {'FINISHED'}`` (main thread): write objects and
  attributes, report.

``execute`` (scripts, redo, ``blender --background``) runs the three in the main thread,
as before, with progress lines on stdout in background runs.  ``invoke`` with a window
runs `prepare`, then `compute` in a daemon `threading.Thread` whose progress callback
only records (fraction, text) under a lock and raises `Cancelled` once Esc was
pressed; a 0.1 s timer drives ``modal``, which copies the fraction to the progress bar
and the text to the header / status bar.  Esc or right-click cancels at once with a
WARNING "<label> cancelled: '<object>' unchanged": nothing was written (the worker is
abandoned and stops at its next progress call), and a CANCELLED operator pushes no
undo step.  When the worker is done, ``modal`` calls `finish` in the main thread; an
error in the worker (`BolusError` or unexpected) is reported like any other.  numpy
and scipy release the GIL, so the interface stays responsive; view navigation (mouse
move, wheel, middle mouse, trackpad) passes through, every other event is held while
the worker runs (the mesh must not change under it).  unfold and
improve_flattenability keep their own step jobs (one island / job step per 10 ms tick;
Esc there keeps nothing / the best surface so far).
"""
from __future__ import annotations

import functools
import threading
import time
import traceback

import bpy
from . import mesh_io
from ..core.errors import BolusError
from ..core.mesh.topology import MeshTopology

#: names fixed by SPEC.md
ATTR_FLATTENABILITY = "bolus_flattenability"
ATTR_SALIENCY = "bolus_saliency"
ATTR_SALIENCY_COLOR = "bolus_saliency_color"
ATTR_PATCH = "bolus_patch"
#: ours: a display colour per patch (corner domain, so borders stay crisp)
ATTR_PATCH_COLOR = "bolus_patch_color"
#: custom properties of ours (read by the panel)
PROP_PATCH_TABLE = "bolus_patch_table"
PROP_SUM_VARPI = "bolus_sum_varpi"
PROP_FLV = "bolus_flv"


#: seconds between two progress lines on stdout in background runs
PROGRESS_PERIOD_S = 2.0
#: seconds between two timer ticks of a threaded modal run (progress bar, "done?")
MODAL_PERIOD_S = 0.1
#: events a threaded modal run lets through to the interface while it works (view navigation)
NAVIGATION_EVENTS = frozenset({
    "MOUSEMOVE", "INBETWEEN_MOUSEMOVE", "MIDDLEMOUSE", "WHEELUPMOUSE", "WHEELDOWNMOUSE", "WHEELINMOUSE",
    "WHEELOUTMOUSE", "TRACKPADPAN", "TRACKPADZOOM", "MOUSEROTATE", "MOUSESMARTZOOM",
    "NDOF_MOTION", "NDOF_BUTTON_FIT", "WINDOW_DEACTIVATE",
})
#: events that cancel a threaded modal run
CANCEL_EVENTS = frozenset({"ESC", "RIGHTMOUSE"})


class Cancelled(Exception):
    """Raised inside `compute` by a modal run's progress callback once Esc was pressed."""


class Worker:
    """`compute(job, progress)` in a daemon thread; the main thread polls `state` and `done`.

    The progress callback only records (fraction, text) under a lock, and raises
    `Cancelled` once `cancel` was set: no bpy call happens in the thread."""

    def __init__(self, compute, job):
        self.lock = threading.Lock()
        self.fraction, self.text = 0.0, ""
        self.cancel = threading.Event()
        self.done = threading.Event()
        self.result = None
        self.error: BaseException | None = None
        self.cancelled = False
        self.thread = threading.Thread(target=self._main, args=(compute, job), daemon=True, name="bolus-compute")

    def start(self) -> "Worker":
        self.thread.start()
        return self

    def progress(self, fraction: float, text: str = "") -> None:
        if self.cancel.is_set():
            raise Cancelled()
        with self.lock:
            self.fraction = min(max(float(fraction), 0.0), 1.0)
            if text:
                self.text = str(text)

    def state(self) -> tuple[float, str]:
        with self.lock:
            return self.fraction, self.text

    def _main(self, compute, job) -> None:
        try:
            self.result = compute(job, self.progress)
        except Cancelled:
            self.cancelled = True
        except BaseException as exc:  # carried back to the main thread, reported there
            self.error = exc
        finally:
            self.done.set()


class BolusOperator:
    """Shared poll / error handling / progress for the bolus operators.

    Every way into an operator is guarded in one place: `execute` (scripts, redo),
    and any ``invoke`` or ``modal`` a subclass defines (wrapped by `__init_subclass__`):
    a `BolusError` becomes an ERROR report and ``{'CANCELLED'}``, any other exception
    the same with "Unexpected error" (traceback on the console), never a traceback at
    the user; a failed ``modal`` calls `abort` first (timers, progress bar).  Without a
    window (``blender --background``, bpy as a module) ``invoke`` falls back to
    `execute`: there is no file browser or modal loop to run.
    """

    bl_options = {"REGISTER", "UNDO"}

    #: long operators: a staticmethod compute(job, progress) -> result, with prepare / finish
    #: (see the module docstring); they get the threaded invoke / modal below
    compute = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if getattr(cls, "compute", None) is not None and "invoke" not in cls.__dict__ and "modal" not in cls.__dict__:
            cls.invoke = BolusOperator._threaded_invoke
            cls.modal = BolusOperator._threaded_modal
        own_invoke = cls.__dict__.get("invoke")
        if own_invoke is not None and not getattr(own_invoke, "_bolus_guarded", False):

            def invoke(self, context, event):
                if context.window is None:
                    return self.execute(context)
                self._progress_start(context)
                return self._guarded(functools.partial(own_invoke, self), context, event)

            invoke._bolus_guarded = True
            invoke.__doc__ = own_invoke.__doc__
            cls.invoke = invoke
        own_modal = cls.__dict__.get("modal")
        if own_modal is not None and not getattr(own_modal, "_bolus_guarded", False):

            def modal(self, context, event):
                return self._guarded(functools.partial(own_modal, self), context, event, on_error=self.abort)

            modal._bolus_guarded = True
            modal.__doc__ = own_modal.__doc__
            cls.modal = modal

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        if obj is None:
            cls.poll_message_set("No active object: select the skin surface mesh first")
            return False
        if obj.type != "MESH":
            cls.poll_message_set(f"'{obj.name}' is not a mesh: select the skin surface mesh")
            return False
        return True

    def run(self, context) -> set[str]:
        """prepare, compute, finish in the main thread (a long operator; others override run)."""
        if self.compute is None:  # pragma: no cover - every operator has one or the other
            raise NotImplementedError
        job = self.prepare(context)
        if isinstance(job, set):
            return job
        return self.finish(context, job, self.compute(job, self.progress))

    _timer = None
    _worker = None

    def start_modal(self, context, period: float = 0.01) -> set[str]:
        """Begin a modal run: the progress bar, a timer (every ``period`` s) whose ticks drive
        ``modal``, and this operator as the modal handler."""
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(period, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def abort(self, context) -> None:
        """Undo what `start_modal` set up (the timer, the progress bar, the header and status
        text): at the end of a modal run, on Esc and after an error; nothing when no modal run
        was started."""
        if self._timer is None:
            return
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        self._timer = None
        wm.progress_end()
        _status_text(context, None)

    # ---------------------------------------------------------------- threaded modal runs
    def _threaded_invoke(self, context, event):
        """prepare here, compute in a `Worker` thread, a 0.1 s timer drives `_threaded_modal`."""
        job = self.prepare(context)
        if isinstance(job, set):
            return job
        obj = getattr(context, "active_object", None)
        self._source_name = obj.name if obj is not None else "the mesh"
        self._source_size = _mesh_size(obj)
        self._job = job
        self._worker = Worker(type(self).compute, job)
        self.start_modal(context, MODAL_PERIOD_S)
        self._worker.start()
        _status_text(context, f"{self.bl_label}: starting (Esc to cancel)")
        return {"RUNNING_MODAL"}

    def _threaded_modal(self, context, event):
        """Esc / right-click: cancel at once, nothing written; a tick: the progress bar and the
        header text, and once the worker is done its error raised or `finish` called."""
        worker = self._worker
        if event.type in CANCEL_EVENTS:
            worker.cancel.set()
            self.abort(context)
            self.report({"WARNING"}, f"{self.bl_label} cancelled: '{self._source_name}' unchanged")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"} if event.type in NAVIGATION_EVENTS else {"RUNNING_MODAL"}
        fraction, text = worker.state()
        context.window_manager.progress_update(int(100 * fraction))
        step = f": {text}" if text else ""
        _status_text(context, f"{self.bl_label}{step} {100 * fraction:.0f} % (Esc to cancel)")
        if not worker.done.is_set():
            return {"RUNNING_MODAL"}
        self.abort(context)
        self._worker = None
        if worker.error is not None:  # reported by the guard (BolusError: its message)
            raise worker.error
        obj = getattr(context, "active_object", None)
        if self._source_size is not None and (obj is None or obj.name != self._source_name
                                              or _mesh_size(obj) != self._source_size):
            raise BolusError(f"'{self._source_name}' changed while {self.bl_label} was computing: nothing was "
                             "written; run it again")
        return self.finish(context, self._job, worker.result)

    def execute(self, context):
        wm = self._progress_start(context)
        wm.progress_begin(0, 100)
        try:
            return self._guarded(self.run, context)
        finally:
            wm.progress_end()

    def _guarded(self, fn, context, *args, on_error=None):
        """fn(context, *args) with every error reported (ERROR, CANCELLED), never raised."""
        try:
            return fn(context, *args)
        except BolusError as exc:
            if on_error is not None:
                _quietly(on_error, context)
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except Exception as exc:  # never a traceback at the user
            traceback.print_exc()
            if on_error is not None:
                _quietly(on_error, context)
            self.report({"ERROR"}, f"Unexpected error, nothing was changed ({type(exc).__name__}: {exc})")
            return {"CANCELLED"}

    def read_region(self, context, allow_nonmanifold: bool):
        """The region (mesh_io.read_region), its topology, checked, and the warnings so far.

        mesh_io.read_region also refuses NaN/inf coordinates and warns when the region's
        size says the scene's units are wrong, for every operator that reads a region."""
        region = mesh_io.read_region(context)
        topo = MeshTopology(region.V, region.F)
        return region, topo, region.warnings + check_topology(topo, allow_nonmanifold, region.vert_ids)

    def _progress_start(self, context):
        self._wm = context.window_manager
        self._progress_printed = None
        return self._wm

    def progress(self, fraction: float, text: str = "") -> None:
        """Progress bar; in background runs also a line on stdout, the first at once, then every 2 s.

        The line reads ``bolus.unfold: patch 2/5: relaxing springs 43 %``."""
        fraction = min(max(float(fraction), 0.0), 1.0)
        wm = getattr(self, "_wm", None) or bpy.context.window_manager
        wm.progress_update(int(100 * fraction))
        if not bpy.app.background:
            return
        now = time.monotonic()
        last = getattr(self, "_progress_printed", None)
        if last is not None and now - last < PROGRESS_PERIOD_S:
            return
        self._progress_printed = now
        step = f" {text}" if text else ""
        print(f"{operator_name(self)}:{step} {100 * fraction:.0f} %", flush=True)

    def warn_all(self, messages) -> None:
        for msg in messages:
            self.report({"WARNING"}, msg)


def time_limit(context) -> float | None:
    """The user's time limit in seconds (the sidebar's *Time limit (s)*, 0 = none) for core.budget;
    None (the default budget) when the scene has no Bolus settings."""
    settings = getattr(getattr(context, "scene", None), "bolus", None)
    return None if settings is None else float(settings.time_limit_s)


def operator_name(op) -> str:
    """'bolus.unfold' (Blender shows a registered operator's bl_idname as 'BOLUS_OT_unfold')."""
    head, sep, tail = op.bl_idname.partition("_OT_")
    return f"{head.lower()}.{tail}" if sep else op.bl_idname


def _mesh_size(obj) -> tuple | None:
    """(vertices, edges, polygons) of a mesh object's data, else None: a threaded run checks that
    its source did not change under it before writing."""
    if obj is None or getattr(obj, "type", None) != "MESH":
        return None
    me = obj.data
    return len(me.vertices), len(me.edges), len(me.polygons)


def _status_text(context, text) -> None:
    """The header of the area the operator runs in and the status bar; None clears both."""
    area = getattr(context, "area", None)
    if area is not None:
        _quietly(lambda c: area.header_text_set(text), context)
    workspace = getattr(context, "workspace", None)
    if workspace is not None:
        _quietly(lambda c: workspace.status_text_set(text), context)


def _quietly(fn, context) -> None:
    try:
        fn(context)
    except Exception:  # the original error is the one to report
        traceback.print_exc()


def check_topology(topo: MeshTopology, allow_nonmanifold: bool, vert_ids=None) -> list[str]:
    """The core's surface check (`MeshTopology.surface_warnings`) on a region read from Blender."""
    return topo.surface_warnings(allow_nonmanifold, "the region", vert_ids)


# the analysis operators (saliency preview, segment) live in analysis_ops.py
classes = ()
