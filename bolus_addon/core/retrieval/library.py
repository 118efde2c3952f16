"""Bolus library and retrieval from a photo (SPEC `build_library`, `retrieve`).

A library is a folder of models (``.blend``, ``.stl``, ``.obj``; one model per file).  Its cache
``bolus_library.npz`` in that folder holds, per method (`METHODS`: ``VIEWS`` the view matcher,
`views`; ``SKELETON`` the seed's chapter 5, `skeleton_method`), every model's descriptor with the
file's fingerprint (size, modification time, SHA-1), the method's settings and `CACHE_VERSION`.
Each descriptor field is stored stacked over the models (one array per field, with the counts), so
a library of 1,000 models loads in one read.  A method's section is rebuilt for the files that
changed, were added or removed, and wholly when the version or its settings change; the other
method's section is kept.  The file is written to a temporary name and renamed (a crash or a
refusal never leaves a damaged cache).

`describe_models` describes models in parallel (joblib threads: the worker may live inside Blender)
and saves the cache every CHECKPOINT_S seconds, so an interrupted build resumes where it stopped.
Reading ``.blend`` files needs Blender: the Blender layer hands the arrays in.
"""
from __future__ import annotations

import hashlib
import importlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import BolusError

__all__ = ["CACHE_FILE", "CACHE_VERSION", "MODEL_SUFFIXES", "METHODS", "DEFAULT_METHOD", "LibraryEntry",
           "method_module", "library_files", "fingerprint", "read_model", "save_cache", "load_cache",
           "plan_update", "describe_models", "update_library", "search", "confidence"]

CACHE_FILE = "bolus_library.npz"
#: raise when the descriptors change meaning (method, settings, format): every cache is rebuilt
CACHE_VERSION = 3
MODEL_SUFFIXES = (".blend", ".stl", ".obj")
METHODS = {"VIEWS": "views", "SKELETON": "skeleton_method"}  #: method -> module of this package
DEFAULT_METHOD = "VIEWS"
BUILD_JOBS = 2  #: models described at once
CHECKPOINT_S = 5.0  #: a long build saves what it has done at least this often


@dataclass
class LibraryEntry:
    """One model of the library: its file name, fingerprint and descriptor."""

    file: str
    size: int
    sha1: str
    descriptor: object
    meta: dict = field(default_factory=dict)  #: e.g. vertices, triangles
    mtime_ns: int = 0


def method_module(method: str):
    """The module of a retrieval method (`METHODS`); BolusError on an unknown one."""
    if method not in METHODS:
        raise BolusError(f"unknown retrieval method {method!r}: choose one of {', '.join(METHODS)}")
    return importlib.import_module(f"{__package__}.{METHODS[method]}")


def library_files(directory) -> list[Path]:
    """The model files of a library folder (not recursive), sorted by name; BolusError when the folder
    does not exist or holds none."""
    d = Path(directory)
    if not d.is_dir():
        raise BolusError(f"the library folder {d} does not exist")
    files = sorted(p for p in d.iterdir() if p.is_file() and p.suffix.lower() in MODEL_SUFFIXES)
    if not files:
        raise BolusError(f"the library folder {d} holds no models ({', '.join(MODEL_SUFFIXES)} files)")
    return files


def fingerprint(path) -> tuple[int, str]:
    """(size in bytes, SHA-1 hex) of a file."""
    h = hashlib.sha1()
    p = Path(path)
    with open(p, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return p.stat().st_size, h.hexdigest()


def read_model(path) -> tuple[np.ndarray, np.ndarray]:
    """V (n,3), F (m,3) of an ``.obj`` or ``.stl`` file (``.blend`` needs Blender: BolusError)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".obj":
        from ..mesh.objfile import load_obj  # noqa: PLC0415

        V, F, _ = load_obj(p)
        return V, F
    if suffix == ".stl":
        from ..mesh.stlfile import load_stl  # noqa: PLC0415

        return load_stl(p)
    raise BolusError(f"{p.name}: only .obj and .stl models are read without Blender")


def _key(settings: dict) -> str:
    return json.dumps(settings, sort_keys=True)


def _read_raw(path: Path) -> tuple[dict, dict]:
    """(meta, arrays) of a cache file; ({}, {}) when it is missing, damaged, foreign or of another version."""
    if not path.is_file():
        return {}, {}
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
        meta = json.loads(str(data.pop("meta")))
        if meta.get("version") != CACHE_VERSION or not isinstance(meta.get("methods"), dict):
            return {}, {}
        return meta, data
    except Exception:  # a damaged or foreign file: rebuilt  # noqa: BLE001
        return {}, {}


def save_cache(directory, entries: list[LibraryEntry], method: str = DEFAULT_METHOD) -> Path:
    """Write the method's section of the cache (`CACHE_FILE`) into ``directory``, the other methods' sections
    kept; written to a temporary file and renamed.  Returns its path."""
    d = Path(directory)
    mod = method_module(method)
    meta, arrays = _read_raw(d / CACHE_FILE)
    methods = {k: v for k, v in meta.get("methods", {}).items() if k != method}
    arrays = {k: v for k, v in arrays.items() if not k.startswith(method + ".")}
    rows, fields = [], {}
    for e in entries:
        a = e.descriptor.arrays()
        for f, v in a.items():
            fields.setdefault(f, []).append(v)
        rows.append({"file": e.file, "size": e.size, "sha1": e.sha1, "mtime_ns": e.mtime_ns, "kind": e.descriptor.kind,
                     "points": int(e.descriptor.size), "seconds": e.descriptor.seconds, **e.meta})
    for f, vs in fields.items():
        arrays[f"{method}.{f}"] = np.concatenate(vs)
        arrays[f"{method}.{f}.n"] = np.array([len(v) for v in vs], np.int64)
    methods[method] = {"settings": mod.SETTINGS, "entries": rows}
    arrays["meta"] = np.array(json.dumps({"version": CACHE_VERSION, "methods": methods}))
    tmp = d / f"{CACHE_FILE}.{os.getpid()}.tmp"
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
        tmp.replace(d / CACHE_FILE)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise BolusError(f"cannot write the library cache into {d}: {exc.strerror or exc}") from None
    return d / CACHE_FILE


def load_cache(directory, method: str = DEFAULT_METHOD) -> dict[str, LibraryEntry]:
    """The method's cached entries by file name; {} when there is no cache, it is unreadable, of another
    version or made with other settings (all of it is then rebuilt)."""
    mod = method_module(method)
    meta, data = _read_raw(Path(directory) / CACHE_FILE)
    sec = meta.get("methods", {}).get(method)
    if not sec or _key(sec.get("settings", {})) != _key(mod.SETTINGS):
        return {}
    try:
        names = sorted({k[len(method) + 1:-2] for k in data if k.startswith(method + ".") and k.endswith(".n")})
        parts = {f: np.split(data[f"{method}.{f}"], np.cumsum(data[f"{method}.{f}.n"])[:-1]) for f in names}
        out = {}
        for i, m in enumerate(sec["entries"]):
            d = mod.Descriptor.from_arrays({f: parts[f][i] for f in names}, m["kind"], m["points"], m["seconds"])
            extra = {k: v for k, v in m.items() if k not in ("file", "size", "sha1", "mtime_ns", "kind", "points",
                                                              "seconds")}
            out[m["file"]] = LibraryEntry(m["file"], int(m["size"]), m["sha1"], d, extra, int(m.get("mtime_ns", 0)))
        return out
    except Exception:  # an inconsistent file: rebuilt  # noqa: BLE001
        return {}


def plan_update(directory, method: str = DEFAULT_METHOD) -> tuple[list[LibraryEntry], list[Path], list[str]]:
    """(entries still valid, files to describe anew, names of cached files no longer there).  A file whose
    size and modification time match the cache is not read again; otherwise its SHA-1 decides."""
    method_module(method)
    files = library_files(directory)
    cached = load_cache(directory, method)
    keep, todo = [], []
    for f in files:
        e = cached.get(f.name)
        st = f.stat()
        if e is not None and e.size == st.st_size and e.mtime_ns == st.st_mtime_ns:
            keep.append(e)
            continue
        size, sha1 = fingerprint(f)
        if e is not None and e.size == size and e.sha1 == sha1:
            e.mtime_ns = st.st_mtime_ns
            keep.append(e)
        else:
            todo.append(f)
    gone = sorted(set(cached) - {f.name for f in files})
    return keep, todo, gone


def _describe_one(path: Path, data, mod):
    """(LibraryEntry, None) or (None, warning) for one model."""
    try:
        V, F = read_model(path) if isinstance(data, Path) else data
        desc = mod.model_descriptor(V, F)
        size, sha1 = fingerprint(path)
    except BolusError as exc:  # one bad model does not stop the library
        return None, f"{path.name} left out of the library: {exc}"
    except OSError as exc:
        return None, f"{path.name} left out of the library: {exc.strerror or exc}"
    return LibraryEntry(path.name, size, sha1, desc, {"vertices": int(len(V)), "triangles": int(len(F))},
                        path.stat().st_mtime_ns), None


def describe_models(items, progress, start: float, span: float, method: str = DEFAULT_METHOD, jobs: int = BUILD_JOBS,
                    checkpoint=None) -> tuple[list, list[str]]:
    """(LibraryEntry list, warnings) for ``items``: (file, (V, F) or the file itself to read here); one model
    that cannot be read or described is left out with a warning.  ``jobs`` models at a time (joblib threads);
    ``checkpoint(entries so far)`` is called every CHECKPOINT_S seconds (bpy-free: a worker thread)."""
    from joblib import Parallel, delayed  # noqa: PLC0415

    mod = method_module(method)
    entries, warnings = [], []
    batch = max(1, int(jobs)) * 2
    last = time.perf_counter()
    with Parallel(n_jobs=max(1, int(jobs)), prefer="threads") as par:
        for b0 in range(0, len(items), batch):
            chunk = items[b0:b0 + batch]
            progress(start + span * b0 / max(len(items), 1),
                     f"models {b0 + 1}-{b0 + len(chunk)} of {len(items)}: {chunk[0][0].name}")
            for entry, warning in par(delayed(_describe_one)(p, d, mod) for p, d in chunk):
                if entry is not None:
                    entries.append(entry)
                if warning:
                    warnings.append(warning)
            if checkpoint is not None and time.perf_counter() - last > CHECKPOINT_S and b0 + batch < len(items):
                checkpoint(entries)
                last = time.perf_counter()
    return entries, warnings


def update_library(folder: str, items, keep, progress, start: float, span: float, method: str = DEFAULT_METHOD):
    """Describe ``items`` (`describe_models`), save the cache with the still valid ``keep`` entries
    -> (entries by file name, the new entries, warnings)."""
    def checkpoint(done):
        save_cache(folder, sorted(keep + done, key=lambda e: e.file), method)

    new, warnings = describe_models(items, progress, start, span, method, checkpoint=checkpoint)
    entries = sorted(keep + new, key=lambda e: e.file)
    if not entries:
        raise BolusError(f"no model of the library {folder} could be described: " + "; ".join(warnings))
    save_cache(folder, entries, method)
    return {e.file: e for e in entries}, new, warnings


def confidence(ranking) -> float:
    """How clearly the best model wins: (d2 - d1) / d2 of the two best distances (1 with one model)."""
    if len(ranking) < 2 or ranking[1][1] <= 0:
        return 1.0 if len(ranking) < 2 else 0.0
    return float(max(0.0, (ranking[1][1] - ranking[0][1]) / ranking[1][1]))


def search(folder, rgb, items, keep, gone, progress, method: str = DEFAULT_METHOD):
    """Retrieval of a photo rgb (H,W,3) in a library (bpy-free: a worker thread): the cache brought up to
    date first when ``items`` (to describe) or ``gone`` (removed files) say so, then the photo described and
    the library ranked -> (photo descriptor, [(file, dissimilarity)] best first, warnings, models described)."""
    mod = method_module(method)
    progress(0.0, "describing the photo")
    photo = mod.photo_descriptor(rgb)  # a photo without an object is refused before the library is touched
    entries, warnings = {e.file: e for e in keep}, []
    if items or gone:
        entries, _, warnings = update_library(folder, items, keep, progress, 0.1, 0.8, method)
    progress(0.9, f"comparing with {len(entries)} models")
    ranking = mod.rank(photo, {k: e.descriptor for k, e in entries.items()})
    return photo, ranking, warnings, len(items)
