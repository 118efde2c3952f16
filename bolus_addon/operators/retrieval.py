"""Operators for the bolus library: `build_library`, `retrieve` (SPEC; seed chapter 5).

A library is a folder of models (.blend, .stl, .obj; one model per file).  `build_library`
caches every model's descriptors in the folder (core.retrieval: ``bolus_library.npz``, versioned;
only changed, added or removed files are redone): with ``method='VIEWS'`` (the default) the
silhouettes from 40 directions, with ``'SKELETON'`` the seed's feature skeleton.  `retrieve`
describes the photo, brings the cache up to date, ranks the models, imports the best one as a new
object and stores the ``count`` best as the scene's ``bolus_retrieval`` (JSON list of {"model",
"score"}, best first), the method and the confidence (how much farther the runner-up is) as
``bolus_retrieval_info``; a near tie is warned.

The main thread reads what needs Blender (the photo's pixels through ``bpy.data.images``, the
meshes of .blend files); the describing and ranking run in the worker thread (blender/modal_run.py).
STL and OBJ models are taken as millimetres (planning systems write mm), so the imported match
has its true size in the scene's unit.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from types import SimpleNamespace

import bpy
import numpy as np
from bpy.props import EnumProperty, IntProperty, StringProperty

from ..blender import mesh_io
from ..blender.objects import PROP_LIBRARY, PROP_MATCH_SOURCE, PROP_RETRIEVAL, PROP_RETRIEVAL_INFO
from ..blender.properties import RETRIEVE_METHODS
from ..blender.operator_base import BolusOperator
from ..core.errors import BolusError
from ..core.retrieval import library as retrieval

AMBIGUOUS = 0.05  #: the runner-up within 5 % of the best's dissimilarity: warned as a near tie
#: what the bench measured for a method that misses its targets, warned with each result (VIEWS meets them)
CAVEAT = {"SKELETON": "Experimental: in the benchmark the right model came first for 15 % of photos (chance 10 %)"}
PHOTO_MAX_PIXELS = 800 * 600  #: photos above this are scaled down first (seed 5.4: keep under 800 x 600)


def _library_dir(path: str) -> str:
    folder = bpy.path.abspath(path) if path else ""
    if not folder:
        raise BolusError("choose the library folder first")
    return folder


def read_blend_model(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """V (n,3) world coordinates and F (m,3) of every mesh object in a .blend file, joined; the
    appended objects and meshes are removed again (nothing is left in the open file)."""
    try:
        with bpy.data.libraries.load(str(path), link=False) as (src, dst):
            dst.objects = list(src.objects)
    except (OSError, RuntimeError) as exc:
        raise BolusError(f"{path.name} is not a .blend file Blender can read ({exc})") from None
    Vs, Fs, n = [], [], 0
    meshes = set()
    try:
        for ob in dst.objects:
            if ob is None or ob.type != "MESH":
                continue
            me = ob.data
            meshes.add(me)
            co = mesh_io.get_array(me.vertices, "co", len(me.vertices), np.float64, 3)
            me.calc_loop_triangles()
            T = mesh_io.get_array(me.loop_triangles, "vertices", len(me.loop_triangles), np.int64, 3)
            M = np.array(ob.matrix_world)
            Vs.append(co @ M[:3, :3].T + M[:3, 3])
            Fs.append(T + n)
            n += len(co)
    finally:
        for ob in dst.objects:
            if ob is not None:
                bpy.data.objects.remove(ob, do_unlink=True)
        for me in meshes:
            if me.users == 0:
                bpy.data.meshes.remove(me)
    if not Fs:
        raise BolusError(f"{path.name} holds no mesh object")
    return np.concatenate(Vs), np.concatenate(Fs)


def read_models(todo: list[Path]) -> list[tuple[Path, object]]:
    """(file, arrays or the file itself) for the models to describe: .blend files are read here (main
    thread, Blender), .obj / .stl later in the worker (core.retrieval.describe_models)."""
    return [(p, read_blend_model(p) if p.suffix.lower() == ".blend" else p) for p in todo]


def read_photo(path: str) -> np.ndarray:
    """(H,W,3) float RGB of an image file, top row first, scaled down to at most `PHOTO_MAX_PIXELS`."""
    p = bpy.path.abspath(path) if path else ""
    if not p or not os.path.isfile(p):
        raise BolusError(f"the photo '{path}' does not exist: choose an image file (PNG, JPEG, ...)")
    try:
        img = bpy.data.images.load(p, check_existing=False)
    except RuntimeError:
        raise BolusError(f"'{os.path.basename(p)}' is not an image Blender can read") from None
    try:
        w, h = img.size
        if w < 1 or h < 1 or img.channels < 1:
            raise BolusError(f"'{os.path.basename(p)}' is not an image Blender can read (size {w} x {h})")
        if w * h > PHOTO_MAX_PIXELS:
            f = (PHOTO_MAX_PIXELS / (w * h)) ** 0.5
            img.scale(max(int(w * f), 8), max(int(h * f), 8))
            w, h = img.size
        px = np.empty(w * h * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    rgb = px.reshape(h, w, 4)[::-1, :, :3].astype(np.float64)  # Blender's rows start at the bottom
    return np.clip(rgb, 0.0, 1.0)


def import_model(context, path: Path, mm: float) -> bpy.types.Object:
    """The library model as a new object in the scene (mm models at true size), active and selected."""
    suffix = path.suffix.lower()
    scale = 1.0 / mm  # 1 mm in scene units
    if suffix == ".blend":
        with bpy.data.libraries.load(str(path), link=False) as (src, dst):
            dst.objects = list(src.objects)
        new = [o for o in dst.objects if o is not None and o.type == "MESH"]
        for o in dst.objects:
            if o is not None and o.type != "MESH":
                bpy.data.objects.remove(o, do_unlink=True)
        for o in new:
            context.scene.collection.objects.link(o)
    else:
        V, F = retrieval.read_model(path)
        me = bpy.data.meshes.new(path.stem)
        me.from_pydata((V * scale).tolist(), [], F.tolist())
        me.validate()
        ob = bpy.data.objects.new(path.stem, me)
        context.scene.collection.objects.link(ob)
        new = [ob]
    if not new:
        raise BolusError(f"{path.name} holds no mesh object to import")
    for o in context.view_layer.objects:
        o.select_set(o in new)
    context.view_layer.objects.active = new[0]
    return new[0]


class BOLUS_OT_build_library(BolusOperator, bpy.types.Operator):
    """Describe every model of a bolus library for retrieval from a photo (silhouettes from 40 directions, whole and cut, and the seed's feature skeletons). Needs a folder of .blend, .stl or .obj models; makes the cache bolus_library.npz in it (only changed, added or removed models are redone)"""

    bl_idname = "bolus.build_library"
    bl_label = "Build Bolus Library"

    directory: StringProperty(name="Library", subtype="DIR_PATH", default="")
    method: EnumProperty(name="Method", items=RETRIEVE_METHODS, default="VIEWS")

    @classmethod
    def poll(cls, context):
        return True

    def prepare(self, context):
        folder = _library_dir(self.directory)
        keep, todo, gone = retrieval.plan_update(folder, self.method)
        return SimpleNamespace(folder=folder, keep=keep, gone=gone, items=read_models(todo), method=self.method)

    @staticmethod
    def compute(job, progress):
        return retrieval.update_library(job.folder, job.items, job.keep, progress, 0.0, 1.0, job.method)

    def finish(self, context, job, result):
        entries, new, warnings = result
        self.warn_all(warnings)
        secs = sum(e.descriptor.seconds for e in new)
        context.scene[PROP_LIBRARY] = json.dumps({"directory": job.folder, "models": len(entries), "described": len(new),
                                                  "kept": len(job.keep), "removed": len(job.gone),
                                                  "method": job.method})
        self.report({"INFO"}, f"Library {job.folder}: {len(entries)} models ({len(new)} described in {secs:.1f} s, "
                              f"{len(job.keep)} from the cache, {len(job.gone)} gone); cache "
                              f"{retrieval.CACHE_FILE} (version {retrieval.CACHE_VERSION}, {job.method})")
        return {"FINISHED"}


class BOLUS_OT_retrieve(BolusOperator, bpy.types.Operator):
    """Find the library models most like a photo of a treatment site or a bolus (their silhouettes from 40 directions against the photo's; or the seed's feature skeletons). Needs the library folder and a photo of the object against a plain background; imports the best match as a new object and lists the best ones with their distances (scene property bolus_retrieval)"""

    bl_idname = "bolus.retrieve"
    bl_label = "Find Matching Bolus"

    filepath: StringProperty(name="Photo", subtype="FILE_PATH", default="")
    directory: StringProperty(name="Library", subtype="DIR_PATH", default="")
    count: IntProperty(name="Matches", description="How many of the best matches to list", default=5, min=1,
                       soft_max=20)
    method: EnumProperty(name="Method", items=RETRIEVE_METHODS, default="VIEWS")

    @classmethod
    def poll(cls, context):
        return True

    def prepare(self, context):
        folder = _library_dir(self.directory)
        rgb = read_photo(self.filepath)
        keep, todo, gone = retrieval.plan_update(folder, self.method)
        return SimpleNamespace(folder=folder, rgb=rgb, keep=keep, gone=gone, items=read_models(todo),
                               photo=os.path.basename(bpy.path.abspath(self.filepath)), count=int(self.count),
                               mm=mesh_io.mm_per_unit(context.scene), method=self.method)

    @staticmethod
    def compute(job, progress):
        return retrieval.search(job.folder, job.rgb, job.items, job.keep, job.gone, progress, job.method)

    def finish(self, context, job, result):
        photo, ranking, warnings, redone = result
        warnings = list(warnings) + (photo.warnings() if hasattr(photo, "warnings") else [])
        conf = retrieval.confidence(ranking)
        tie = len(ranking) > 1 and conf < AMBIGUOUS
        if tie:
            warnings = warnings + [f"near tie: the photo hardly tells {ranking[0][0]} ({ranking[0][1]:.4g}) from "
                                   f"{ranking[1][0]} ({ranking[1][1]:.4g}); look at both before starting from either"]
        self.warn_all(warnings)
        best = ranking[: job.count]
        context.scene[PROP_RETRIEVAL] = json.dumps([{"model": name, "score": float(score)} for name, score in best])
        context.scene[PROP_RETRIEVAL_INFO] = json.dumps({"method": job.method, "photo": job.photo, "confidence": conf,
                                                         "tie": bool(tie), "models": len(ranking)})
        ob = import_model(context, Path(job.folder) / best[0][0], job.mm)
        ob[PROP_MATCH_SOURCE] = json.dumps({"file": best[0][0], "score": float(best[0][1]), "photo": job.photo})
        self.report({"INFO"}, f"Best match for {job.photo}: {best[0][0]} (dissimilarity {best[0][1]:.4g}, confidence "
                              f"{100 * conf:.0f} %), imported as '{ob.name}'"
                              + (f"; {redone} library models described first" if redone else ""))
        for k, (name, score) in enumerate(best, 1):
            self.report({"INFO"}, f"{k}. {name}: {score:.4g}")
        caveat = CAVEAT.get(job.method, "")
        self.report({"WARNING"} if caveat else {"INFO"},
                    (caveat + "; " if caveat else "") + "look through the list, fit the model to this patient's skin "
                    "and check it on the planning CT")
        return {"FINISHED"}


classes = (BOLUS_OT_build_library, BOLUS_OT_retrieve)
