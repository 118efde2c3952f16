"""Threaded modal runs of the long operators: `compute` in a worker thread, a timer, Esc.

A long operator splits its work in three (see `operator_base`): ``prepare`` and ``finish`` in
the main thread, ``compute(job, progress)`` bpy-free.  ``invoke`` with a window runs `prepare`,
then `compute` in a daemon `threading.Thread` (`Worker`) whose progress callback only records
(fraction, text) under a lock and raises `Cancelled` once Esc was pressed; a 0.1 s timer drives
``modal``, which copies the fraction to the progress bar and the text to the header / status
bar.  Esc or right-click cancels at once with a WARNING "<label> cancelled: '<object>'
unchanged": nothing is written (the worker is abandoned and stops at its next progress call),
and a CANCELLED operator pushes no undo step.  When the worker is done, ``modal`` calls
`finish` in the main thread; an error in the worker (`BolusError` or unexpected) is reported
like any other.  numpy and scipy release the GIL, so the interface stays responsive; view
navigation (mouse move, wheel, middle mouse, trackpad) passes through, every other event is
held while the worker runs (the mesh must not change under it).
"""
from __future__ import annotations

import threading
import traceback

from ..core.budget import Deadline, budget_s
from ..core.errors import BolusError

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

    def __init__(self, compute, job, deadline=None):
        self.deadline = deadline  # progress -> the callback compute gets (the time limit's wrapper)
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
            progress = self.progress if self.deadline is None else self.deadline(self.progress)
            self.result = compute(job, progress)
        except Cancelled:
            self.cancelled = True
        except BaseException as exc:  # carried back to the main thread, reported there
            self.error = exc
        finally:
            self.done.set()


class ModalRun:
    """The modal half of `operator_base.BolusOperator`: the timer and progress bar of a modal run
    (`start_modal`, `abort`), and the threaded ``invoke`` / ``modal`` a long operator gets."""

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
        status_text(context, None)

    def _threaded_invoke(self, context, event):
        """prepare here, compute in a `Worker` thread, a 0.1 s timer drives `_threaded_modal`."""
        job = self.prepare(context)
        if isinstance(job, set):
            return job
        obj = getattr(context, "active_object", None)
        self._source_name = obj.name if obj is not None else "the mesh"
        self._source_size = mesh_size(obj)
        self._job = job
        limit, what = budget_s(time_limit_of(context)), self.bl_label  # read here: no bpy in the thread
        self._worker = Worker(type(self).compute, job, lambda progress: Deadline(progress, limit, what))
        self.start_modal(context, MODAL_PERIOD_S)
        self._worker.start()
        status_text(context, f"{self.bl_label}: starting (Esc to cancel)")
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
        status_text(context, f"{self.bl_label}{step} {100 * fraction:.0f} % (Esc to cancel)")
        if not worker.done.is_set():
            return {"RUNNING_MODAL"}
        self.abort(context)
        self._worker = None
        if worker.error is not None:  # reported by the guard (BolusError: its message)
            raise worker.error
        obj = getattr(context, "active_object", None)
        if self._source_size is not None and (obj is None or obj.name != self._source_name
                                              or mesh_size(obj) != self._source_size):
            raise BolusError(f"'{self._source_name}' changed while {self.bl_label} was computing: nothing was "
                             "written; run it again")
        return self.finish(context, self._job, worker.result)


def time_limit_of(context) -> float | None:
    """The user's time limit in seconds (the sidebar's *Time limit (s)*, 0 = none) for core.budget;
    None (the default budget) when the scene has no Bolus settings."""
    settings = getattr(getattr(context, "scene", None), "bolus", None)
    return None if settings is None else float(settings.time_limit_s)


def mesh_size(obj) -> tuple | None:
    """(vertices, edges, polygons) of a mesh object's data, else None: a threaded run checks that
    its source did not change under it before writing."""
    if obj is None or getattr(obj, "type", None) != "MESH":
        return None
    me = obj.data
    return len(me.vertices), len(me.edges), len(me.polygons)


def status_text(context, text) -> None:
    """The header of the area the operator runs in and the status bar; None clears both."""
    area = getattr(context, "area", None)
    if area is not None:
        quietly(lambda c: area.header_text_set(text), context)
    workspace = getattr(context, "workspace", None)
    if workspace is not None:
        quietly(lambda c: workspace.status_text_set(text), context)


def quietly(fn, context) -> None:
    """fn(context), an error in it printed on the console only (the original error is the one to report)."""
    try:
        fn(context)
    except Exception:  # the original error is the one to report
        traceback.print_exc()
