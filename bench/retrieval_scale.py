"""Build and query times of the view matcher at library scale, for bench/retrieval_bench.py.

* `build_times(lib_dir)`: the bench's library described from scratch by ``core.retrieval.library.
  update_library`` (what Build Bolus Library runs) with 1 and with 2 models at a time (joblib threads):
  wall seconds per model;
* `query_times(lib_dir, photos, sizes)`: for each size N a folder of N model files (hard links to the bench's
  models under new names, so the files are real) with a cache whose entries are the described models'
  descriptors with a little noise (synthetic copies: nothing is described again); each photo is then
  searched as Find Matching Bolus does (`library.plan_update` + `library.search`: the folder checked against
  the cache, the cache read, the photo described, every view compared): wall seconds per query.
"""
from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import numpy as np

from bolus_addon.core.retrieval import library, views


def _quiet(*_a) -> None:
    return None


def build_times(lib_dir: Path, work: Path, jobs=(1, 2)) -> list[dict]:
    """[{jobs, models, wall_s, per_model_s, warnings}] of a fresh build of the library in ``lib_dir``."""
    out = []
    for j in jobs:
        d = work / f"build_{j}"
        shutil.rmtree(d, ignore_errors=True)
        shutil.copytree(lib_dir, d, ignore=shutil.ignore_patterns(library.CACHE_FILE + "*"))
        keep, todo, _ = library.plan_update(d, "VIEWS")
        t = time.perf_counter()
        new, warnings = library.describe_models([(p, p) for p in todo], _quiet, 0.0, 1.0, "VIEWS", jobs=j)
        library.save_cache(d, keep + new, "VIEWS")
        wall = time.perf_counter() - t
        out.append({"jobs": j, "models": len(new), "wall_s": wall, "per_model_s": wall / max(1, len(new)),
                    "warnings": len(warnings)})
        shutil.rmtree(d, ignore_errors=True)
    return out


def synthetic_library(lib_dir: Path, folder: Path, n: int, rng=0) -> None:
    """``folder`` with n model files (hard links, or copies, of the described models of ``lib_dir``) and a VIEWS
    cache of their descriptors, each copy's views (whole and cut) jittered by 1 % of the descriptor's spread."""
    g = np.random.default_rng(rng)
    src = library.load_cache(lib_dir, "VIEWS")
    names = sorted(src)
    folder.mkdir(parents=True, exist_ok=True)
    spread = np.concatenate([src[k].descriptor.matrix for k in names]).std(axis=0)
    entries = []
    for i in range(n):
        e = src[names[i % len(names)]]
        name = f"copy{i:04d}_{e.file}"
        target = folder / name
        try:
            os.link(lib_dir / e.file, target)
        except OSError:
            shutil.copyfile(lib_dir / e.file, target)
        M = e.descriptor.matrix + 0.01 * spread * g.standard_normal(e.descriptor.matrix.shape)
        C = e.descriptor.cuts.astype(np.float32)
        C = C + 0.01 * spread[: C.shape[1]] * g.standard_normal(C.shape)
        d = views.ViewsDescriptor(M.astype(np.float32), "model", e.descriptor.size, e.descriptor.seconds,
                                  cuts=C.astype(np.float16))
        entries.append(library.LibraryEntry(name, e.size, e.sha1, d, dict(e.meta), target.stat().st_mtime_ns))
    library.save_cache(folder, entries, "VIEWS")


def query_times(lib_dir: Path, work: Path, photos: list[np.ndarray], sizes=(50, 1000)) -> list[dict]:
    """[{models, queries, median_s, max_s, plan_s, ranking_s}] of searches of ``photos`` in synthetic libraries."""
    out = []
    for n in sizes:
        folder = work / f"scale_{n}"
        shutil.rmtree(folder, ignore_errors=True)
        synthetic_library(lib_dir, folder, n)
        walls, plans, ranks = [], [], []
        for rgb in photos:
            t = time.perf_counter()
            keep, todo, gone = library.plan_update(folder, "VIEWS")
            plans.append(time.perf_counter() - t)
            assert not todo and not gone, (len(todo), gone)
            photo, ranking, _, _ = library.search(folder, rgb, [], keep, [], _quiet, "VIEWS")
            walls.append(time.perf_counter() - t)
            t = time.perf_counter()
            views.rank(photo, {e.file: e.descriptor for e in keep})
            ranks.append(time.perf_counter() - t)
        out.append({"models": n, "queries": len(photos), "median_s": float(np.median(walls)), "max_s": max(walls),
                    "plan_s": float(np.median(plans)), "ranking_s": float(np.median(ranks))})
        shutil.rmtree(folder, ignore_errors=True)
    return out
