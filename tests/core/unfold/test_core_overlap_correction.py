"""Overlap correction (seed 4.5.3): overlap_correction.py."""
import numpy as np
from meshgen import grid

from bolus_addon.core.unfold.overlap import boundary_self_intersections, overlapping_faces, signed_areas
from bolus_addon.core.unfold.overlap_correction import local_outline, untangle
from bolus_addon.core.unfold.springs import build_springs
from bolus_addon.core.mesh.topology import MeshTopology


def test_a_local_fold_is_untangled_without_a_global_round():
    V, F = grid(20, 20)
    topo = MeshTopology(V, F)
    UV = V[:, :2].copy()
    v = 10 * 21 + 10  # an interior vertex pushed far across its neighbours: a fold
    UV[v] += [12.0, 9.0]
    assert np.count_nonzero(signed_areas(UV, F) <= 0) > 0
    X, flips = untangle(UV, topo)
    assert flips == 0 and np.count_nonzero(signed_areas(X, F) <= 0) == 0
    far = np.linalg.norm(V[:, :2] - V[v, :2], axis=1) > 30.0
    np.testing.assert_array_equal(X[far], UV[far])  # only the neighbourhood of the fold moved


def test_outline_crossing_is_corrected_locally():
    """A strip laid on a circle of 1.04 turns: its two ends overlap.  `local_outline` moves
    only the vertices near the ends apart; the middle of the strip stays exactly in place."""
    V, F = grid(60, 3, 60.0)
    V[:, 1] *= 3.0 / 60.0  # a 60 x 3 mm strip
    topo = MeshTopology(V, F)
    theta = V[:, 0] / 60.0 * 2.0 * np.pi * 1.04
    UV = np.stack([(10.0 + V[:, 1]) * np.cos(theta), (10.0 + V[:, 1]) * np.sin(theta)], 1)
    if signed_areas(UV, F).sum() < 0:
        UV[:, 0] = -UV[:, 0]
    assert len(boundary_self_intersections(UV, F)) and overlapping_faces(UV, F).sum() > 0
    X, _, crossings = local_outline(UV, build_springs(topo), topo)
    assert crossings == 0 and len(boundary_self_intersections(X, F)) == 0
    assert overlapping_faces(X, F).sum() == 0 and np.count_nonzero(signed_areas(X, F) <= 0) == 0
    middle = np.abs(V[:, 0] - 30.0) < 15.0
    np.testing.assert_array_equal(X[middle], UV[middle])
