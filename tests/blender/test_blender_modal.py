"""Threaded modal runs: every long operator runs modally with a progress bar,
and Esc keeps the mesh as it was.

Headless Blender has no window and no event loop, so the modal path is driven by hand: a
fake context (the real one, with a window, a window manager that records the progress bar and
the timer, a header and a status bar) and fake events ('TIMER', 'ESC', ...).  The shared
machinery (blender/operator_base.BolusOperator: prepare / compute / finish; blender/modal_run `Worker`) is tested on a small
dummy operator; every converted operator is run through the threaded path on one object and
through ``bpy.ops`` (execute, the main thread) on an identical object, with the same result,
``compute`` seen to call no bpy and no Blender-layer code, and a cancelled run leaving the
source exactly as it was.
"""
from __future__ import annotations

import json
import sys
import threading
import time
import types
from types import SimpleNamespace

import numpy as np
import pytest
from bpy_helpers import assert_same_object, make_object, object_snapshot
from meshgen import bump_quads
from test_blender_shell import hemisphere

pytestmark = pytest.mark.blender

#: the operators that run compute() in a worker thread from the sidebar
THREADED = ("saliency_preview", "segment", "smooth_cuts", "select_area", "unfold", "make_shell", "print_segment",
            "orient_parts", "build_library", "retrieve")
#: threaded too, with an invoke of their own that opens the file browser first (tested below)
BROWSING = ("import_dicom", "export_rtstruct")
#: the one that keeps its own step job (one job step per timer tick; Esc keeps the best so far)
STEPPED = ("improve_flattenability",)


# ------------------------------------------------------------------ fakes of the window side
class FakeWM:
    """A window manager that records the progress bar, the timers and the modal handlers."""

    def __init__(self):
        self.updates, self.timers, self.handlers, self.periods = [], [], [], []
        self.bar = 0  # progress_begin - progress_end

    def progress_begin(self, lo, hi):
        assert (lo, hi) == (0, 100)
        self.bar += 1

    def progress_update(self, value):
        assert isinstance(value, int) and 0 <= value <= 100, value
        self.updates.append(value)

    def progress_end(self):
        self.bar -= 1

    def event_timer_add(self, period, window=None):
        assert window is not None
        token = object()
        self.timers.append(token)
        self.periods.append(period)
        return token

    def event_timer_remove(self, token):
        self.timers.remove(token)

    def modal_handler_add(self, op):
        self.handlers.append(op)


class FakeText:
    """An area (header_text_set) and a workspace (status_text_set) in one."""

    def __init__(self):
        self.texts = []

    def header_text_set(self, text):
        self.texts.append(text)

    status_text_set = header_text_set


class Ctx:
    """bpy.context with a window: a FakeWM, a header and a status bar."""

    def __init__(self, bpy):
        self.__dict__.update(_bpy=bpy, window=object(), window_manager=FakeWM(), area=FakeText(),
                             workspace=FakeText())

    def __getattr__(self, name):
        return getattr(self._bpy.context, name)


def event(kind):
    return SimpleNamespace(type=kind, value="PRESS")


# ------------------------------------------------------------------ the shared machinery
def dummy_class(bpy_addon):
    """A long operator (not registered: the machinery is plain Python) whose compute waits for the
    test: ``job.go`` lets it run, each step reports progress, ``job.fail`` raises in the worker."""
    from bolus.bolus_addon.blender.operator_base import BolusOperator  # noqa: PLC0415 (the extension package)

    class Dummy(BolusOperator):
        bl_idname = "BOLUS_OT_dummy"
        bl_label = "Dummy Step"
        nothing_to_do = False
        fail = None

        def __init__(self):
            self.reports, self.finished, self.prepared = [], [], 0

        def report(self, kind, msg):
            self.reports.append((set(kind), msg))

        def prepare(self, context):
            self.prepared += 1
            if self.nothing_to_do:
                self.report({"INFO"}, "nothing to do")
                return {"FINISHED"}
            return SimpleNamespace(go=threading.Event(), steps=4, fail=self.fail, threads=[], stopped=threading.Event())

        @staticmethod
        def compute(job, progress):
            job.threads.append(threading.current_thread())
            try:
                for k in range(job.steps):
                    assert job.go.wait(30)
                    progress(k / job.steps, f"step {k + 1}/{job.steps}")
                    if job.fail is not None:
                        raise job.fail
            finally:
                job.stopped.set()
            return sum(range(job.steps))

        def finish(self, context, job, result):
            self.finished.append((threading.current_thread(), result))
            self.report({"INFO"}, f"done: {result}")
            return {"FINISHED"}

    return Dummy


def tick_until_done(op, ctx, limit_s=600.0):
    t0 = time.monotonic()
    while True:
        r = op.modal(ctx, event("TIMER"))
        if r != {"RUNNING_MODAL"}:
            return r
        assert time.monotonic() - t0 < limit_s, "the worker did not finish"
        time.sleep(0.01)


@pytest.mark.smoke
def test_threaded_run_progress_and_finish(bpy_addon):
    """invoke: prepare, a worker thread, a 0.1 s timer, the progress bar; ticks copy the worker's
    progress to the bar and the header; at the end finish runs in the main thread, all cleared."""
    from bolus.bolus_addon.blender import modal_run  # noqa: PLC0415

    Dummy = dummy_class(bpy_addon)
    ctx, op = Ctx(bpy_addon), Dummy()
    wm = ctx.window_manager
    assert op.invoke(ctx, event("LEFTMOUSE")) == {"RUNNING_MODAL"}
    assert wm.periods == [modal_run.MODAL_PERIOD_S] and wm.handlers == [op] and wm.bar == 1
    worker, job = op._worker, op._job
    assert op.modal(ctx, event("TIMER")) == {"RUNNING_MODAL"}  # nothing done yet
    assert wm.updates == [0]
    assert op.modal(ctx, event("MOUSEMOVE")) == {"PASS_THROUGH"}  # view navigation goes on
    assert op.modal(ctx, event("WHEELUPMOUSE")) == {"PASS_THROUGH"}
    assert op.modal(ctx, event("G")) == {"RUNNING_MODAL"}  # anything else waits: the mesh must not change
    job.go.set()
    assert tick_until_done(op, ctx) == {"FINISHED"}
    worker.thread.join(10)  # `done` is set in the thread's last statement: it ends right after
    assert job.threads and job.threads[0] is not threading.main_thread() and not worker.thread.is_alive()
    assert op.finished == [(threading.main_thread(), 6)]
    assert op.reports == [({"INFO"}, "done: 6")]
    assert worker.state() == (0.75, "step 4/4")
    assert wm.timers == [] and wm.bar == 0 and op._timer is None
    assert ctx.area.texts[-1] is None and ctx.workspace.texts[-1] is None  # header and status bar cleared
    shown = [t for t in ctx.area.texts if t]
    assert any(t.startswith("Dummy Step: step ") and t.endswith("% (Esc to cancel)") for t in shown), shown
    assert max(wm.updates) == 75


@pytest.mark.parametrize("key", ["ESC", "RIGHTMOUSE"])
def test_esc_cancels_at_once_and_the_worker_stops(bpy_addon, key):
    Dummy = dummy_class(bpy_addon)
    ctx, op = Ctx(bpy_addon), Dummy()
    wm = ctx.window_manager
    assert op.invoke(ctx, event("LEFTMOUSE")) == {"RUNNING_MODAL"}
    worker, job = op._worker, op._job
    assert op.modal(ctx, event(key)) == {"CANCELLED"}  # while the worker is busy
    source = ctx.active_object.name if ctx.active_object else "the mesh"
    assert op.reports == [({"WARNING"}, f"Dummy Step cancelled: '{source}' unchanged")]
    assert wm.timers == [] and wm.bar == 0 and ctx.area.texts[-1] is None
    job.go.set()  # the abandoned worker stops at its next progress call
    worker.thread.join(30)
    assert not worker.thread.is_alive() and worker.cancelled and worker.result is None and worker.error is None
    assert op.finished == []


@pytest.mark.parametrize("fail", ["BolusError", "TypeError"])
def test_errors_in_the_worker_are_reported(bpy_addon, fail):
    from bolus.bolus_addon.core.errors import BolusError  # noqa: PLC0415

    Dummy = dummy_class(bpy_addon)
    Dummy.fail = BolusError("the region has 3 holes") if fail == "BolusError" else TypeError("boom")
    ctx, op = Ctx(bpy_addon), Dummy()
    assert op.invoke(ctx, event("LEFTMOUSE")) == {"RUNNING_MODAL"}
    op._job.go.set()
    assert tick_until_done(op, ctx) == {"CANCELLED"}
    expect = ("the region has 3 holes" if fail == "BolusError"
              else "Unexpected error, nothing was changed (TypeError: boom)")
    assert op.reports == [({"ERROR"}, expect)] and op.finished == []
    assert ctx.window_manager.timers == [] and ctx.window_manager.bar == 0


def test_a_source_changed_under_the_worker_is_not_written(bpy_addon, scene):
    """The mesh must not change while the worker computes from it (every event but view navigation
    is held); if it did anyway (a script, another add-on's timer), nothing is written."""
    bpy = bpy_addon
    ob = bump(bpy, "skinA", n=4)
    Dummy = dummy_class(bpy_addon)
    ctx, op = Ctx(bpy), Dummy()
    assert op.invoke(ctx, event("LEFTMOUSE")) == {"RUNNING_MODAL"}
    ob.data.vertices.add(1)  # "meanwhile"
    op._job.go.set()
    assert tick_until_done(op, ctx) == {"CANCELLED"}
    assert op.finished == [] and op.reports == [
        ({"ERROR"}, "'skinA' changed while Dummy Step was computing: nothing was written; run it again")]
    ctx, op = Ctx(bpy), Dummy()  # unchanged: written
    assert op.invoke(ctx, event("LEFTMOUSE")) == {"RUNNING_MODAL"}
    op._job.go.set()
    assert tick_until_done(op, ctx) == {"FINISHED"} and len(op.finished) == 1


def test_without_a_window_and_with_nothing_to_do(bpy_addon):
    """No window (background, bpy as a module): invoke runs execute, compute in the main thread;
    prepare may end the run itself (no thread, no timer)."""
    Dummy = dummy_class(bpy_addon)
    op = Dummy()
    job_go = threading.Event()
    job_go.set()
    orig = Dummy.prepare

    def prepare(self, context):
        job = orig(self, context)
        job.go = job_go
        self.job = job
        return job

    Dummy.prepare = prepare
    ctx = SimpleNamespace(window=None, window_manager=FakeWM())
    assert op.invoke(ctx, event("LEFTMOUSE")) == {"FINISHED"}
    assert op.job.threads == [threading.main_thread()] and op.finished == [(threading.main_thread(), 6)]
    Dummy.prepare = orig
    Dummy.nothing_to_do = True
    ctx, op = Ctx(bpy_addon), Dummy()
    assert op.invoke(ctx, event("LEFTMOUSE")) == {"FINISHED"}
    assert op.reports == [({"INFO"}, "nothing to do")] and ctx.window_manager.timers == [] and op._worker is None


def test_long_operators_are_threaded(bpy_addon):
    """Every long operator has a staticmethod compute (it cannot reach the operator) and the
    guarded threaded invoke / modal; improve keeps its step job."""
    from bolus.bolus_addon.blender.operator_base import BolusOperator  # noqa: PLC0415

    bpy = bpy_addon
    for name in THREADED:
        cls = getattr(bpy.types, f"BOLUS_OT_{name}")
        assert isinstance(cls.__dict__["compute"], staticmethod), name
        for fn in ("invoke", "modal"):
            wrapped = cls.__dict__[fn]
            assert getattr(wrapped, "_bolus_guarded", False), (name, fn)
            assert wrapped.__doc__ == getattr(BolusOperator, f"_threaded_{fn}").__doc__, (name, fn)
    for name in STEPPED:
        cls = getattr(bpy.types, f"BOLUS_OT_{name}")
        assert cls.compute is None and "modal" in cls.__dict__


# ------------------------------------------------------------------ the real operators
def operator_class(name):
    for mod in ("analysis", "cuts", "area", "unfold", "solid", "printing", "retrieval", "dicom"):
        m = sys.modules[f"bolus.bolus_addon.operators.{mod}"]
        for v in vars(m).values():
            if isinstance(v, type) and getattr(v, "bl_idname", None) == f"bolus.{name}":
                return v
    raise KeyError(name)


def fake_of(bpy, name, **props):
    """The real operator's prepare / compute / finish (and helpers) on a plain BolusOperator whose
    properties are plain attributes (the defaults of the registered operator, then ``props``)."""
    from bolus.bolus_addon.blender.operator_base import BolusOperator  # noqa: PLC0415

    Op = operator_class(name)
    ns = {}
    for klass in reversed(Op.__mro__):  # the operator and the mixins of its own module
        if klass.__module__ == Op.__module__:
            ns.update({k: v for k, v in klass.__dict__.items()
                       if isinstance(v, (types.FunctionType, staticmethod)) and k not in ("invoke", "modal")})
    rna = getattr(bpy.ops.bolus, name).get_rna_type()
    values = {p.identifier: p.default for p in rna.properties if p.identifier != "rna_type"}
    values.update(props)

    def __init__(self):
        self.__dict__.update(values)
        self.reports = []

    def report(self, kind, msg):
        self.reports.append((set(kind), msg))

    ns.update(bl_idname=Op.bl_idname, bl_label=Op.bl_label, __init__=__init__, report=report)
    return type(f"Fake_{name}", (BolusOperator,), ns)


def bump(bpy, name, n=14, size=100.0):
    """A (n x n)-quad grid of `size` mm with a bump, 1 unit = 1 mm, active."""
    V, F = bump_quads(n, size)
    return make_object(bpy, V, F, name=name, scale_length=0.001)


def activate(bpy, ob):
    for o in bpy.context.view_layer.objects:
        o.select_set(o is ob)
    bpy.context.view_layer.objects.active = ob


def datablocks(bpy):
    return sorted(o.name for o in bpy.data.objects), sorted(m.name for m in bpy.data.meshes)


class CallWatch:
    """A profiler (threading.setprofile: threads started while it is set) that records every Python
    function the worker enters outside numpy / scipy / the standard library, and every C call on
    a bpy object."""

    def __init__(self):
        self.calls, self.bpy_calls = set(), set()

    def __call__(self, frame, what, arg):
        if what == "call":
            code = frame.f_code
            if "bolus_addon" in code.co_filename or "bpy" in code.co_filename:
                self.calls.add((code.co_filename.replace("\\", "/"), code.co_name))
        elif what == "c_call":
            owner = getattr(arg, "__self__", None)
            kind = type(owner)
            if (kind.__module__.startswith("bpy") or kind.__name__.startswith("bpy")
                    or str(getattr(arg, "__module__", "")).startswith("bpy")):
                self.bpy_calls.add(repr(arg))

    def not_bpy_free(self, module_file: str) -> list:
        """The calls a bpy-free compute must not make: any Blender-layer function of the add-on
        other than compute and its lambdas, the Worker's progress and its time-limit lambda (a core
        Deadline), and the two bpy-free helpers."""
        worker, solid_split, labels, part_checks, unfold = (
            "blender/modal_run.py", "blender/solid_split.py", "blender/labels.py", "blender/part_checks.py",
            "operators/unfold.py")
        allowed = {(worker, "progress"), (worker, "_main"), (worker, "<lambda>"), (module_file, "compute"),
                   (module_file, "<lambda>"), (solid_split, "compute_solid"),
                   (solid_split, "<lambda>"), (labels, "engrave_with"),
                   (part_checks, "part_arrays"), (solid_split, "<genexpr>"),
                   (solid_split, "<listcomp>"), (unfold, "start"), (unfold, "step"),
                   (unfold, "_reference"), (unfold, "compute_pattern"),
                   (unfold, "<listcomp>"), (unfold, "<genexpr>"), (unfold, "<lambda>"),
                   (unfold, "check_unfold_budget")}
        bad = []
        for path, fn in self.calls:
            if "/bolus_addon/core/" in path:
                continue
            if "bolus_addon/" in path and (path.rsplit("bolus_addon/", 1)[-1], fn) in allowed:
                continue
            bad.append((path, fn))
        return bad + sorted(self.bpy_calls)


def test_call_watch_sees_bpy_and_the_blender_layer(bpy_addon, scene):
    """The bpy-free check can fail: a thread that reads the scene through mesh_io and calls a bpy
    collection method is caught on both counts."""
    bpy = bpy_addon
    from bolus.bolus_addon.blender import mesh_io  # noqa: PLC0415

    def work():
        mesh_io.mm_per_unit(bpy.context.scene)
        bpy.data.objects.get("nothing")

    watch = CallWatch()
    threading.setprofile(watch)
    try:
        t = threading.Thread(target=work)
        t.start()
    finally:
        threading.setprofile(None)
    t.join()
    bad = watch.not_bpy_free("operators/analysis.py")
    assert ("mesh_io.py", "mm_per_unit") in {(p.rsplit("/", 1)[-1], fn) for p, fn in watch.calls}, bad
    assert any("method get of bpy_prop_collection" in b for b in watch.bpy_calls), bad
    assert len(bad) >= 2


def modal_run(bpy, name, props, cancel_first=True):
    """On the active object: (if cancel_first) a threaded run cancelled at once, the source and
    the file unchanged; then a threaded run to the end, watched for bpy calls; the fake op."""
    ob = bpy.context.active_object
    module_file = sys.modules[operator_class(name).__module__].__file__.replace("\\", "/").rsplit("bolus_addon/", 1)[-1]
    Fake = fake_of(bpy, name, **props)
    if cancel_first:
        before, blocks = object_snapshot(ob), datablocks(bpy)
        ctx, op = Ctx(bpy), Fake()
        assert op.invoke(ctx, event("LEFTMOUSE")) == {"RUNNING_MODAL"}, op.reports
        worker = op._worker
        assert op.modal(ctx, event("ESC")) == {"CANCELLED"}
        assert op.reports[-1] == ({"WARNING"}, f"{op.bl_label} cancelled: '{ob.name}' unchanged")
        worker.thread.join(600)  # the abandoned worker ends (cancelled, or done with its result dropped)
        assert not worker.thread.is_alive()
        assert_same_object(before, object_snapshot(ob))
        assert datablocks(bpy) == blocks
        assert ctx.window_manager.timers == [] and ctx.window_manager.bar == 0
    ctx, op = Ctx(bpy), Fake()
    watch = CallWatch()
    threading.setprofile(watch)
    try:
        assert op.invoke(ctx, event("LEFTMOUSE")) == {"RUNNING_MODAL"}, op.reports
    finally:
        threading.setprofile(None)
    worker = op._worker
    assert tick_until_done(op, ctx) == {"FINISHED"}, op.reports
    worker.thread.join(10)  # `done` is set in the thread's last statement: it ends right after
    assert not worker.thread.is_alive()
    assert watch.calls, "the profiler saw nothing"
    assert watch.not_bpy_free(module_file) == [], name
    fraction, text = worker.state()
    assert fraction > 0.0 and text, (fraction, text)  # compute reported progress through the worker
    assert ctx.window_manager.timers == [] and ctx.window_manager.bar == 0
    assert not [r for r in op.reports if r[0] == {"ERROR"}], op.reports
    return op


def _untimed(v):
    """JSON data without the run times ("seconds": the pattern table's per island)."""
    if isinstance(v, dict):
        return {k: _untimed(x) for k, x in v.items() if k != "seconds"}
    if isinstance(v, list):
        return [_untimed(x) for x in v]
    return v


def _prop(v, name):
    if hasattr(v, "to_list"):
        return v.to_list()
    if not isinstance(v, str):
        return v
    v = v.replace(name, "skinX")
    try:
        return _untimed(json.loads(v))
    except ValueError:
        return v


def normalised(snapshot, name: str):
    """An object_snapshot with the twin's name ('skinA' / 'skinB') in its string properties as
    'skinX', JSON tables without run times, and ID property arrays as lists."""
    mesh, attrs, props, M, colors = snapshot
    return mesh, attrs, {k: _prop(v, name) for k, v in props.items()}, M, colors


def assert_same_result(a, b):
    assert_same_object(normalised(object_snapshot(a), "skinA"), normalised(object_snapshot(b), "skinB"))


def twins(bpy, make):
    """Two identical objects 'skinA' and 'skinB' made by make(bpy, name)."""
    return make(bpy, "skinA"), make(bpy, "skinB")


@pytest.mark.parametrize("name, props, before", [
    ("saliency_preview", {"smoothing_mm": 2.0}, []),
    ("segment", {"patches": 3}, []),
    ("smooth_cuts", {}, [("segment", {"patches": 3})]),
    ("print_segment", {"parts": 2}, []),
    ("orient_parts", {}, [("print_segment", {"parts": 2})]),
    ("unfold", {"max_el": 2.0, "sheet_thickness_mm": 1.0}, [("segment", {"patches": 3})]),
])
def test_surface_operators_threaded_as_executed(bpy_addon, scene, name, props, before):
    """The threaded run gives what execute gives (bit for bit), a cancelled one changes nothing."""
    bpy = bpy_addon
    a, b = twins(bpy, bump)
    for ob in (a, b):
        activate(bpy, ob)
        for step, kw in before:
            assert getattr(bpy.ops.bolus, step)(**kw) == {"FINISHED"}
    activate(bpy, a)
    modal_run(bpy, name, props)
    activate(bpy, b)
    assert getattr(bpy.ops.bolus, name)(**props) == {"FINISHED"}
    assert_same_result(a, b)
    if name == "unfold":
        assert_same_result(bpy.data.objects["skinA_pattern"], bpy.data.objects["skinB_pattern"])
    if name == "orient_parts":
        for k in range(2):
            pa, pb = bpy.data.objects[f"skinA_part_{k}"], bpy.data.objects[f"skinB_part_{k}"]
            assert_same_result(pa, pb)


def test_select_area_threaded_as_executed(bpy_addon, scene):
    bpy = bpy_addon
    a, b = twins(bpy, bump)
    bpy.context.scene.cursor.location = (0.05, 0.05, 0.02)  # 1 unit = 1 m: the bump's top
    activate(bpy, a)
    modal_run(bpy, "select_area", {"radius_mm": 30.0})
    assert a.mode == "EDIT"
    bpy.ops.object.mode_set(mode="OBJECT")
    activate(bpy, b)
    assert bpy.ops.bolus.select_area(radius_mm=30.0) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    assert_same_result(a, b)
    sel = np.empty(len(a.data.polygons), dtype=bool)
    a.data.polygons.foreach_get("select", sel)
    assert 0 < sel.sum() < len(sel)


def test_make_shell_and_solid_print_threaded_as_executed(bpy_addon, scene):
    """make_shell with a label (the font's outlines read in prepare, engraved in the worker), then
    print_segment of the bolus solid (the same for every part's label)."""
    bpy = bpy_addon
    a, b = twins(bpy, lambda bpy, name: hemisphere(bpy, name=name, R=12.0, rings=12, na=48))
    shell = {"thickness_mm": 4.0, "resolution_mm": 1.0, "label": "T"}
    activate(bpy, a)
    modal_run(bpy, "make_shell", shell)
    activate(bpy, b)
    assert bpy.ops.bolus.make_shell(**shell) == {"FINISHED"}
    ba, bb = bpy.data.objects["skinA_bolus"], bpy.data.objects["skinB_bolus"]
    assert_same_result(ba, bb)
    assert_same_result(a, b)  # the sources: untouched both ways
    activate(bpy, ba)
    modal_run(bpy, "print_segment", {"parts": 2}, cancel_first=True)
    activate(bpy, bb)
    assert bpy.ops.bolus.print_segment(parts=2) == {"FINISHED"}
    assert_same_result(ba, bb)
    assert json.loads(ba["bolus_print_table"])["solid"]


def test_cancelled_run_leaves_nothing_for_undo(bpy_addon, scene):
    """Esc leaves the file as it was: an undo step pushed after the cancelled run holds exactly
    the state before it (Blender itself pushes no undo step for a CANCELLED operator)."""
    bpy = bpy_addon
    ob = bump(bpy, "skinA")
    bpy.ops.ed.undo_push(message="mesh made")
    before, blocks = object_snapshot(ob), datablocks(bpy)
    Fake = fake_of(bpy, "segment", patches=3)
    real = Fake.compute

    def gated(job, progress):  # segment takes < 0.2 s on an idle machine: hold it until Esc
        for _ in range(6000):
            progress(0.0, "waiting for Esc")  # raises Cancelled once Esc was pressed
            time.sleep(0.01)
        return real(job, progress)

    Fake.compute = staticmethod(gated)
    ctx, op = Ctx(bpy), Fake()
    assert op.invoke(ctx, event("LEFTMOUSE")) == {"RUNNING_MODAL"}
    worker = op._worker
    time.sleep(0.2)
    assert op.modal(ctx, event("TIMER")) == {"RUNNING_MODAL"}
    assert op.modal(ctx, event("ESC")) == {"CANCELLED"}
    worker.thread.join(600)
    assert worker.cancelled and worker.result is None
    bpy.ops.ed.undo_push(message="after the cancelled run")
    after = object_snapshot(bpy.data.objects["skinA"])
    assert bpy.ops.ed.undo() == {"FINISHED"}
    undone = object_snapshot(bpy.data.objects["skinA"])
    assert_same_object(before, after)
    assert_same_object(before, undone)
    assert datablocks(bpy) == blocks


def _small_ct(path):
    import dicomgen as g  # noqa: PLC0415

    grid = g.Grid(rows=40, cols=44, spacing=(1.0, 0.9), positions=np.arange(20) * 2.0 - 19.0,
                  origin=np.array([-19.8, -20.0, 0.0]))
    return g.sdf_series(str(path), grid, [(lambda P: np.linalg.norm(P, axis=-1) - 15.0, g.TISSUE)])


@pytest.mark.parametrize("browsed", [False, True])
def test_dicom_import_and_export_threaded_as_executed(bpy_addon, scene, tmp_path, browsed):
    """From the sidebar (folder set) or after the file browser (execute, marked ``browsed``) the
    import and the export run in the worker thread, with Esc, and give what a script's call gives."""
    pytest.importorskip("pydicom")
    import dicomgen as g  # noqa: PLC0415
    import manifold3d as m3  # noqa: PLC0415
    from dicomcheck import check_rtstruct  # noqa: PLC0415

    bpy = bpy_addon
    _small_ct(tmp_path / "ct")
    ct = str(tmp_path / "ct")
    # the script's call, for comparison
    assert bpy.ops.bolus.import_dicom(directory=ct, source="CT") == {"FINISHED"}
    executed = bpy.context.active_object
    V0 = np.array([v.co for v in executed.data.vertices])
    names = set(bpy.data.objects.keys())
    Fake = fake_of(bpy, "import_dicom", directory=ct, source="CT", browsed=browsed)
    ctx, op = Ctx(bpy), Fake()
    start = op.execute(ctx) if browsed else op.invoke(ctx, event("LEFTMOUSE"))
    assert start == {"RUNNING_MODAL"}, op.reports
    assert op.modal(ctx, event("ESC")) == {"CANCELLED"}
    op._worker.thread.join(600)
    assert set(bpy.data.objects.keys()) == names  # nothing added on Esc
    ctx, op = Ctx(bpy), Fake()
    assert (op.execute(ctx) if browsed else op.invoke(ctx, event("LEFTMOUSE"))) == {"RUNNING_MODAL"}
    assert tick_until_done(op, ctx) == {"FINISHED"}, op.reports
    assert ctx.window_manager.timers == [] and ctx.window_manager.bar == 0
    threaded = bpy.context.active_object
    assert threaded.name not in names
    np.testing.assert_array_equal(np.array([v.co for v in threaded.data.vertices]), V0)
    # the export of a closed solid on that CT, threaded
    V, F = g.manifold_arrays(m3.Manifold.sphere(12.0, 40))
    for ob in bpy.context.selected_objects:
        ob.select_set(False)
    solid = make_object(bpy, V / 1000.0, F, name="solid")
    solid["bolus_source"] = threaded.name
    path = str(tmp_path / "rs.dcm")
    Fake = fake_of(bpy, "export_rtstruct", filepath=path, browsed=browsed)
    ctx, op = Ctx(bpy), Fake()
    assert (op.execute(ctx) if browsed else op.invoke(ctx, event("LEFTMOUSE"))) == {"RUNNING_MODAL"}, op.reports
    assert tick_until_done(op, ctx) == {"FINISHED"}, op.reports
    m = check_rtstruct(path, ct, "Bolus", V, F)
    assert m["refs_ok"] and m["frame_ok"] and m["kind"] == "BOLUS" and m["dice"] >= 0.99
