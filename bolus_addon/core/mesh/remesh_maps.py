"""Maps carried through a re-meshing: which old element a new one is, per-group label
ranges, and the barycentric weights that interpolate corner data onto new triangles.

Used by the Blender layer when it writes a cut (`core.cutlines.SmoothCutResult`) into a
mesh: the data of the mesh (labels, selection, UV maps...) follow the new faces.  Pure
numpy, tested without Blender (tests/test_core_remesh_maps.py).
"""
from __future__ import annotations

import numpy as np

from ..errors import BolusError

__all__ = ["label_range", "pair_index", "corner_weights"]

_NONE_LO = np.iinfo(np.int64).max
_NONE_HI = np.iinfo(np.int64).min


def label_range(group, labels, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smallest and largest label in each of n groups.

    group (k,) int in [0, n): the group of each item; labels (k,) int.
    Returns lo (n,), hi (n,) int64 and present (n,) bool; a group is *mixed* where
    ``present & (hi > lo)``, and ``hi`` is its label where it is not mixed.
    """
    group = np.asarray(group, dtype=np.int64)
    labels = np.asarray(labels, dtype=np.int64)
    if group.shape != labels.shape:
        raise BolusError(f"label_range: {group.shape} groups for {labels.shape} labels")
    if len(group) and (group.min() < 0 or group.max() >= n):
        raise BolusError(f"label_range: a group index outside 0..{n - 1}")
    lo = np.full(n, _NONE_LO)
    hi = np.full(n, _NONE_HI)
    np.minimum.at(lo, group, labels)
    np.maximum.at(hi, group, labels)
    return lo, hi, hi != _NONE_HI


def pair_index(old_pairs, new_pairs, n: int) -> np.ndarray:
    """Index of each new vertex pair in the old pairs, or -1 (edges are unordered pairs).

    old_pairs (e,2), new_pairs (k,2) int vertex indices below n.  Returns (k,) int64.
    """
    old = np.sort(np.asarray(old_pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    new = np.sort(np.asarray(new_pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    if len(old) == 0:
        return np.full(len(new), -1, dtype=np.int64)
    old_keys = old[:, 0] * n + old[:, 1]
    order = np.argsort(old_keys)
    sorted_keys = old_keys[order]
    keys = new[:, 0] * n + new[:, 1]
    pos = np.minimum(np.searchsorted(sorted_keys, keys), len(order) - 1)
    return np.where(sorted_keys[pos] == keys, order[pos], -1).astype(np.int64)


def corner_weights(corner_vertex, parent_corners, vert_src, vert_weights) -> np.ndarray:
    """Weights of the parent triangle's corners at every corner of the new triangles.

    corner_vertex (q,3) int: the result vertex at each corner of q new triangles;
    parent_corners (q,3) int: the input vertices of the triangle each new one lies in;
    vert_src (N,3) int, vert_weights (N,3): every result vertex as a barycentric
    combination of input vertices (`SmoothCutResult.vert_src` / ``vert_weights``).
    Returns W (q,3,3): W[t, c, p] is the weight of parent corner p at corner c of t,
    rows summing to 1, so a corner value is ``W @ parent_values``.
    """
    j = np.asarray(corner_vertex, dtype=np.int64)
    corners = np.asarray(parent_corners, dtype=np.int64)
    src = np.asarray(vert_src)[j]  # (q,3,3)
    w = np.asarray(vert_weights, dtype=np.float64)[j]
    W = np.zeros(j.shape + (3,))
    for p in range(3):
        W[:, :, p] = np.where(src == corners[:, None, p, None], w, 0.0).sum(axis=2)
    s = W.sum(axis=2, keepdims=True)
    if np.any(s <= 0):
        raise BolusError("corner_weights: a new vertex does not lie in the triangle it came from")
    return W / s
