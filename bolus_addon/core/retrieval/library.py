"""Bolus library and retrieval from a photo (seed chapter 5; SPEC `build_library`, `retrieve`).

A library is a folder of models (``.blend``, ``.stl``, ``.obj``; one model per file).  Its cache
``bolus_library.npz`` in that folder holds every model's `Descriptor` (the feature skeleton of
5.2, sampled for ICP) with the file's fingerprint (size and SHA-1) and `CACHE_VERSION`; it is
rebuilt for the files that changed, were added or removed, and wholly when the version or the
settings of the method change.

`model_descriptor` (5.2: spectral embedding of the vertices, eqs. 5-10, 5-11; skeleton) and
`photo_descriptor` (5.1: edges by visual entropies, eqs. 5-1..5-4; contour by spectral
clustering, 5-5..5-7; embedding of the contour, 5-8, 5-9; skeleton) describe both sides in the
same 3-D feature space; `rank` orders the library by the ICP dissimilarity (5.3, eqs.
5-12..5-14), best first.  Reading ``.blend`` files needs Blender: the Blender layer hands the
arrays in (`describe_arrays`).
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import BolusError

__all__ = [
    "CACHE_FILE",
    "CACHE_VERSION",
    "MODEL_SUFFIXES",
    "Descriptor",
    "LibraryEntry",
    "library_files",
    "fingerprint",
    "read_model",
    "save_cache",
    "load_cache",
    "plan_update",
    "SETTINGS",
    "model_descriptor",
    "photo_descriptor",
    "rank",
    "describe_models",
    "update_library",
    "search",
]

CACHE_FILE = "bolus_library.npz"
#: raise when the descriptors change meaning (method, settings, format): every cache is rebuilt
CACHE_VERSION = 1
MODEL_SUFFIXES = (".blend", ".stl", ".obj")
#: the method's settings stored with the cache (a change rebuilds it): the skeleton's samples, clusters
SETTINGS = {"method": "spectral feature skeleton + ICP (seed ch. 5)", "samples": 64, "clusters": 6, "k": 3}


@dataclass
class Descriptor:
    """What is compared of a model or a photo: its feature skeleton (5.2.2) in the 3-D feature space."""

    points: np.ndarray  #: (s,3) skeleton points (centre first)
    edges: np.ndarray  #: (e,2) int, skeleton connections
    samples: np.ndarray  #: (c,3) points spread evenly along the skeleton (the ICP input)
    kind: str  #: "model" or "photo"
    size: int  #: vertices of the model, or contour pixels of the photo
    seconds: float = 0.0  #: time to describe it

    def arrays(self, prefix: str) -> dict:
        return {f"{prefix}points": np.asarray(self.points, np.float64), f"{prefix}edges": np.asarray(self.edges, np.int64),
                f"{prefix}samples": np.asarray(self.samples, np.float64)}

    @classmethod
    def from_arrays(cls, data: dict, prefix: str, kind: str, size: int, seconds: float) -> Descriptor:
        return cls(np.asarray(data[f"{prefix}points"]), np.asarray(data[f"{prefix}edges"]),
                   np.asarray(data[f"{prefix}samples"]), kind, int(size), float(seconds))


@dataclass
class LibraryEntry:
    """One model of the library: its file name, fingerprint and descriptor."""

    file: str
    size: int
    sha1: str
    descriptor: Descriptor
    meta: dict = field(default_factory=dict)  #: e.g. vertices, triangles, units


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


def _settings_key(settings: dict) -> str:
    return json.dumps(settings, sort_keys=True)


def save_cache(directory, entries: list[LibraryEntry], settings: dict) -> Path:
    """Write the library cache (`CACHE_FILE`) into ``directory`` atomically; returns its path."""
    d = Path(directory)
    arrays = {}
    meta = {"version": CACHE_VERSION, "settings": settings, "entries": []}
    for i, e in enumerate(entries):
        arrays.update(e.descriptor.arrays(f"m{i}_"))
        meta["entries"].append({"file": e.file, "size": e.size, "sha1": e.sha1, "kind": e.descriptor.kind,
                                "points": int(e.descriptor.size), "seconds": e.descriptor.seconds, **e.meta})
    arrays["meta"] = np.array(json.dumps(meta))
    tmp = d / (CACHE_FILE + ".tmp")
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
        tmp.replace(d / CACHE_FILE)
    except OSError as exc:
        raise BolusError(f"cannot write the library cache into {d}: {exc.strerror or exc}") from None
    return d / CACHE_FILE


def load_cache(directory, settings: dict) -> dict[str, LibraryEntry]:
    """The cached entries by file name; {} when there is no cache, it is unreadable, of another
    version or made with other settings (all of it is then rebuilt)."""
    p = Path(directory) / CACHE_FILE
    if not p.is_file():
        return {}
    try:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
        meta = json.loads(str(data["meta"]))
        if meta.get("version") != CACHE_VERSION or _settings_key(meta.get("settings", {})) != _settings_key(settings):
            return {}
        out = {}
        for i, m in enumerate(meta["entries"]):
            desc = Descriptor.from_arrays(data, f"m{i}_", m["kind"], m["points"], m["seconds"])
            extra = {k: v for k, v in m.items() if k not in ("file", "size", "sha1", "kind", "points", "seconds")}
            out[m["file"]] = LibraryEntry(m["file"], int(m["size"]), m["sha1"], desc, extra)
        return out
    except Exception:  # a damaged or foreign file: rebuild  # noqa: BLE001
        return {}


def plan_update(directory, settings: dict) -> tuple[list[LibraryEntry], list[Path], list[str]]:
    """(entries still valid, files to describe anew, names of cached files no longer there)."""
    files = library_files(directory)
    cached = load_cache(directory, settings)
    keep, todo = [], []
    for f in files:
        size, sha1 = fingerprint(f)
        e = cached.get(f.name)
        if e is not None and e.size == size and e.sha1 == sha1:
            keep.append(e)
        else:
            todo.append(f)
    gone = sorted(set(cached) - {f.name for f in files})
    return keep, todo, gone


def _descriptor(skel, kind: str, size: int, seconds: float) -> Descriptor:
    from .spectral_skeleton import skeleton_samples  # noqa: PLC0415

    return Descriptor(np.asarray(skel.points, np.float64), np.asarray(skel.edges, np.int64),
                      skeleton_samples(skel, SETTINGS["samples"]), kind, int(size), float(seconds))


def model_descriptor(V, F, rng=0) -> Descriptor:
    """The feature skeleton of a model V (n,3), F (m,3) (5.2: eqs. 5-10, 5-11, skeleton 5.2.2)."""
    from .spectral_skeleton import model_skeleton  # noqa: PLC0415
    from ..mesh.topology import check_mesh  # noqa: PLC0415

    V, F = check_mesh(V, F, "the model", nondegenerate=False)
    t = time.perf_counter()
    skel = model_skeleton(V, F, clusters=SETTINGS["clusters"], k=SETTINGS["k"], rng=rng)
    return _descriptor(skel, "model", len(V), time.perf_counter() - t)


def photo_descriptor(rgb, rng=0) -> Descriptor:
    """The feature skeleton of a photo's object contour (5.1: eqs. 5-1..5-7; 5.2: 5-8, 5-9)."""
    from .image_contour import contour_pixels  # noqa: PLC0415
    from .spectral_skeleton import image_skeleton  # noqa: PLC0415

    t = time.perf_counter()
    contour = contour_pixels(rgb, rng=rng)
    skel = image_skeleton(contour.points, clusters=SETTINGS["clusters"], k=SETTINGS["k"], rng=rng)
    return _descriptor(skel, "photo", len(contour.points), time.perf_counter() - t)


def rank(query: Descriptor, library: dict) -> list[tuple[str, float]]:
    """[(name, dissimilarity)] of every library `Descriptor`, best (lowest) first, ties by name
    (eqs. 5-12..5-14: the ICP error between the skeletons' samples)."""
    from .spectral_skeleton import dissimilarity  # noqa: PLC0415

    if not library:
        raise BolusError("the library is empty: build it from a folder of models first")
    scores = [(name, float(dissimilarity(query.samples, d.samples))) for name, d in library.items()]
    return sorted(scores, key=lambda x: (x[1], x[0]))


def describe_models(items, progress, start: float, span: float) -> tuple[list, list[str]]:
    """(LibraryEntry list, warnings) for ``items``: (file, (V, F) or the file itself to read here); one
    model that cannot be read or described is left out with a warning (bpy-free: a worker thread)."""
    entries, warnings = [], []
    for k, (path, data) in enumerate(items):
        progress(start + span * k / max(len(items), 1), f"model {k + 1}/{len(items)}: {path.name}")
        try:
            V, F = read_model(path) if isinstance(data, Path) else data
            desc = model_descriptor(V, F)
        except BolusError as exc:  # one bad model does not stop the library
            warnings.append(f"{path.name} left out of the library: {exc}")
            continue
        size, sha1 = fingerprint(path)
        entries.append(LibraryEntry(path.name, size, sha1, desc, {"vertices": int(len(V)), "triangles": int(len(F))}))
    return entries, warnings


def update_library(folder: str, items, keep, progress, start: float, span: float):
    """Describe ``items`` (`describe_models`), save the cache with the still valid ``keep`` entries
    -> (entries by file name, the new entries, warnings)."""
    new, warnings = describe_models(items, progress, start, span)
    entries = sorted(keep + new, key=lambda e: e.file)
    if not entries:
        raise BolusError(f"no model of the library {folder} could be described: " + "; ".join(warnings))
    save_cache(folder, entries, SETTINGS)
    return {e.file: e for e in entries}, new, warnings


def search(folder, rgb, items, keep, gone, progress) -> tuple[Descriptor, list, list[str], int]:
    """Retrieval of a photo rgb (H,W,3) in a library (bpy-free: a worker thread): the cache brought up
    to date first when ``items`` (to describe) or ``gone`` (removed files) say so, then the photo
    described and the library ranked -> (photo descriptor, [(file, dissimilarity)] best first,
    warnings, models described)."""
    entries, warnings = {e.file: e for e in keep}, []
    if items or gone:
        entries, _, warnings = update_library(folder, items, keep, progress, 0.0, 0.6)
    progress(0.6, "describing the photo")
    photo = photo_descriptor(rgb)
    progress(0.8, f"comparing with {len(entries)} models")
    ranking = rank(photo, {k: e.descriptor for k, e in entries.items()})
    return photo, ranking, warnings, len(items)
