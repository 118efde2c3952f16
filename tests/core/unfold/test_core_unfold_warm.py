"""Warm starts: `unfold_patch(start_uv=...)` relaxes from a given flip-free pattern instead of the
conformal map, and `sheet_pieces` carries a piece's trial pattern to the pieces cut from it
(`piece_geometry._inherit_uv`); both are initialisations, the model and its measures unchanged."""
import numpy as np
import pytest
from meshgen import height_field, spherical_cap

from bolus_addon.core.errors import BolusError
from bolus_addon.core.unfold import piece_geometry as G
from bolus_addon.core.unfold.measures import length_area_errors
from bolus_addon.core.unfold.overlap import signed_areas
from bolus_addon.core.unfold.unfold import unfold_patch


def _cap():
    return spherical_cap(100.0, 50.0, 3)


def test_a_relaxed_start_gives_the_same_pattern_quality_in_fewer_iterations():
    V, F = _cap()
    cold = unfold_patch(V, F)
    mesh = G._piece_mesh(V, F, np.arange(len(F)), np.zeros((0, 2), dtype=np.int64))
    el, ea, uv = G._trial(mesh, with_uv=True)
    warm = unfold_patch(mesh.Vc, mesh.Fc, start_uv=uv)
    # measured independently on the 3D triangles
    el_c, ea_c = length_area_errors(V[cold.vert_origin], cold.F, cold.UV)
    el_w, ea_w = length_area_errors(mesh.Vc[warm.vert_origin], warm.F, warm.UV)
    assert el_w == pytest.approx(el_c, rel=0.02) and ea_w == pytest.approx(ea_c, rel=0.05)
    assert warm.flipped == 0 and warm.overlaps == 0
    assert (signed_areas(warm.UV, warm.F) > 0).all()
    assert warm.iterations < cold.iterations  # it starts nearer the minimum
    assert el >= el_w  # the trial is the shorter relaxation of the same model


def test_a_start_with_a_flipped_triangle_is_ignored():
    V, F = _cap()
    cold = unfold_patch(V, F)
    bad = V[:, :2].copy()
    bad[F[0, 0]] = 1e3  # folds the first triangle's fan over
    assert (signed_areas(bad, F) <= 0).any()
    again = unfold_patch(V, F, start_uv=bad)
    np.testing.assert_allclose(again.UV, cold.UV)


@pytest.mark.parametrize("bad", [np.zeros((3, 2)), np.full((400, 2), np.nan), np.zeros((400,))])
def test_a_bad_start_is_refused_by_name(bad):
    V, F = _cap()
    with pytest.raises(BolusError, match="start_uv"):
        unfold_patch(V, F, start_uv=bad)


def test_a_dart_opens_from_the_parent_pattern_corner_by_corner():
    V, F = height_field(lambda x, y: 20.0 * np.exp(-(x * x + y * y) / 400.0), 12, 12, 100.0)
    faces = np.arange(len(F))
    parent = G._piece_mesh(V, F, faces, np.zeros((0, 2), dtype=np.int64))
    _, _, uv = G._trial(parent, with_uv=True)
    top = int(np.argmax(V[:, 2]))
    path = G._dart_path(parent, int(np.nonzero(parent.origin == top)[0][0]))
    gpath = parent.origin[path]
    child = G._piece_mesh(V, F, faces, np.stack([gpath[:-1], gpath[1:]], 1))
    assert len(child.Vc) > len(parent.Vc)  # the dart's vertices but its apex come twice
    start = G._inherit_uv(parent, faces, uv, child, faces)
    assert start is not None
    # every triangle corner sits where the parent had it: the dart opens from zero width
    np.testing.assert_array_equal(start[child.Fc], uv[parent.Fc])
    np.testing.assert_array_equal(child.origin[child.Fc], parent.origin[parent.Fc])
    # and one side of a split: the parent's pattern restricted to its faces
    half = faces[V[F].mean(axis=1)[:, 0] < 0]
    side = G._piece_mesh(V, F, half, np.zeros((0, 2), dtype=np.int64))
    start = G._inherit_uv(parent, faces, uv, side, half)
    np.testing.assert_array_equal(start[side.Fc], uv[parent.Fc[half]])
