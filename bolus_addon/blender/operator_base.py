"""The operators' common base `BolusOperator`: poll, error guard, progress, the region.

Each operator `bpy.ops.bolus.*` (docs/operators.md; one module of operators/ per stage) reads the
region (mesh_region), calls the core, writes the results and reports.  Everything is computed
before the mesh is touched, so an error leaves the mesh as it was; a `BolusError`, or any other
exception (its traceback on the console), becomes ``self.report({'ERROR'}, ...)`` and
``{'CANCELLED'}``.  Long operators split their work in three:

- ``prepare(context) -> job`` (main thread): read the region, copy the operator's settings into
  the job, validate (`BolusError` refuses); or a result set such as ``{'FINISHED'}`` when there is
  nothing to compute;
- ``compute(job, progress) -> result`` (a staticmethod that sees neither the operator nor bpy):
  core calls only, reporting ``progress(fraction, text)``; it may run in a worker thread;
- ``finish(context, job, result) -> {'FINISHED'}`` (main thread): write objects, attributes, report.

``execute`` runs the three in the main thread (progress lines on stdout in background runs);
``invoke`` from the sidebar runs `compute` in a worker thread (`modal_run`).  Either way the
progress callback carries the user's time limit (`deadline`): past it the job stops with an
ERROR saying how far it got, nothing written.

Design notes: docs/design/blender.md.
"""
from __future__ import annotations

import functools
import time
import traceback

import bpy
from . import mesh_region
from .modal_run import ModalRun, quietly, time_limit_of
from ..core.budget import Deadline, budget_s
from ..core.errors import BolusError
from ..core.mesh.topology import MeshTopology

#: seconds between two progress lines on stdout in background runs
PROGRESS_PERIOD_S = 2.0


class BolusOperator(ModalRun):
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
    #: (see the module docstring); they get the threaded invoke / modal of `ModalRun`
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
        return self.finish(context, job, self.compute(job, self.deadline(context, self.progress)))

    def deadline(self, context, progress=None) -> Deadline:
        """``progress`` wrapped in the user's time limit (`core.budget.Deadline`): the job stops at
        its first progress call past the limit with `TimeLimitReached`, nothing written."""
        return Deadline(progress, budget_s(time_limit(context)), self.bl_label)

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
                quietly(on_error, context)
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except Exception as exc:  # never a traceback at the user
            traceback.print_exc()
            if on_error is not None:
                quietly(on_error, context)
            self.report({"ERROR"}, f"Unexpected error, nothing was changed ({type(exc).__name__}: {exc})")
            return {"CANCELLED"}

    def read_region(self, context, allow_nonmanifold: bool):
        """The region (mesh_region.read_region), its topology, checked, and the warnings so far.

        mesh_region.read_region also refuses NaN/inf coordinates and warns when the region's
        size says the scene's units are wrong, for every operator that reads a region."""
        region = mesh_region.read_region(context)
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


time_limit = time_limit_of  # the operators' name for it


def operator_name(op) -> str:
    """'bolus.unfold' (Blender shows a registered operator's bl_idname as 'BOLUS_OT_unfold')."""
    head, sep, tail = op.bl_idname.partition("_OT_")
    return f"{head.lower()}.{tail}" if sep else op.bl_idname


def check_topology(topo: MeshTopology, allow_nonmanifold: bool, vert_ids=None) -> list[str]:
    """The core's surface check (`MeshTopology.surface_warnings`) on a region read from Blender."""
    return topo.surface_warnings(allow_nonmanifold, "the region", vert_ids)
