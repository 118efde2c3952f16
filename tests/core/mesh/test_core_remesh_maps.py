"""Maps through a re-meshing (core/remesh_maps.py): label ranges, old edge lookup, corner weights."""
import numpy as np
import pytest

from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.remesh_maps import corner_weights, label_range, pair_index


def test_label_range_finds_mixed_groups():
    lo, hi, present = label_range([0, 0, 1, 1, 3], [2, 2, 0, 5, 7], 4)
    assert present.tolist() == [True, True, False, True]
    mixed = present & (hi > lo)
    assert mixed.tolist() == [False, True, False, False]
    assert hi[0] == 2 and hi[3] == 7
    with pytest.raises(BolusError, match="outside"):
        label_range([0, 4], [1, 1], 4)


def test_pair_index_is_unordered_and_misses_give_minus_one():
    old = [[0, 1], [2, 1], [3, 4]]
    assert pair_index(old, [[1, 0], [1, 2], [4, 3], [0, 4]], 5).tolist() == [0, 1, 2, -1]
    assert pair_index(np.zeros((0, 2)), [[0, 1]], 5).tolist() == [-1]


def test_corner_weights_interpolate_a_split_edge():
    # input triangle (10, 11, 12); result vertices 0..2 are its corners, 3 is the midpoint of 10-11
    vert_src = np.array([[10, 10, 10], [11, 11, 11], [12, 12, 12], [10, 11, 12]])
    vert_weights = np.array([[1, 0, 0], [1, 0, 0], [1, 0, 0], [0.5, 0.5, 0.0]], dtype=float)
    W = corner_weights([[0, 3, 2], [3, 1, 2]], [[10, 11, 12], [10, 11, 12]], vert_src, vert_weights)
    np.testing.assert_allclose(W[0], [[1, 0, 0], [0.5, 0.5, 0], [0, 0, 1]])
    np.testing.assert_allclose(W[1], [[0.5, 0.5, 0], [0, 1, 0], [0, 0, 1]])
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    np.testing.assert_allclose(W[0] @ uv, [[0, 0], [0.5, 0], [0, 1]])
    with pytest.raises(BolusError, match="does not lie"):
        corner_weights([[0, 3, 2]], [[20, 21, 22]], vert_src, vert_weights)
