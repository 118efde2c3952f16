"""All unfolded patches laid out side by side in one pattern mesh (layout.pack_islands)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import BolusError
from ..mesh.layout import pack_islands

__all__ = ["Pattern", "assemble_pattern"]


@dataclass
class Pattern:
    """All patches unfolded and laid out.

    UV (N,2) mm; F (M,3) triangles in the order of the input triangles (row t of F
    is input triangle t; -1 rows for unlabelled triangles); vert_source (N,) input vertex
    of each pattern vertex; tri_patch (M,) patch label (-1 none); patches: list of
    `unfold.Unfolding` (their UV before layout).
    """

    UV: np.ndarray
    F: np.ndarray
    vert_source: np.ndarray
    tri_patch: np.ndarray
    patches: list


def assemble_pattern(F, labels, patches: list, gap_mm: float = 10.0) -> Pattern:
    """Lay the unfolded patches out side by side in one pattern mesh.

    Parameters: F (M,3) the input triangles; labels (M,) patch label of each (-1 none);
    patches: one `unfold.Unfolding` per label 0..p-1 present, in label order (as
    `unfold.iter_unfold_patches` yields them); gap_mm between patches.
    Returns `Pattern`.  Raises `BolusError` if the patches do not match the labels.
    """
    labels = np.asarray(labels, dtype=np.int64)
    if len(labels) != len(F):
        raise BolusError(f"{len(labels)} patch labels for {len(F)} triangles")
    ids = np.unique(labels[labels >= 0])
    if len(ids) == 0:
        raise BolusError("no triangle has a patch label: there is nothing to lay out")
    if len(ids) != len(patches):
        raise BolusError(f"{len(patches)} unfolded patches for {len(ids)} patch labels")
    placed = pack_islands([u.UV for u in patches], gap_mm=gap_mm)
    UV_all, src_all = [], []
    F_all = np.full((len(F), 3), -1, dtype=np.int64)
    tri_patch = np.full(len(F), -1, dtype=np.int64)
    offset = 0
    for p, u, P in zip(ids, patches, placed):
        rows = np.nonzero(labels == p)[0]
        if len(rows) != len(u.F):
            raise BolusError(f"patch {p} has {len(rows)} triangles but its unfolding {len(u.F)}")
        F_all[rows] = u.F + offset
        tri_patch[rows] = p
        UV_all.append(P)
        src_all.append(u.vert_origin)
        offset += len(P)
    return Pattern(np.concatenate(UV_all), F_all, np.concatenate(src_all), tri_patch, patches)
