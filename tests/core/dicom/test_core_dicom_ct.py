"""The skin from synthetic CT series of known meshes: distances, couch, cavities, orientation, bad input."""
import os

import numpy as np
import pytest

import manifold3d as m3

import dicomgen as g
from bolus_addon.core.dicom import planning, series
from bolus_addon.core.dicom.skin import signed_volume
from bolus_addon.core.errors import BolusError
from bolus_addon.core.solid.manifold import closed_report

pytest.importorskip("pydicom")


def _arrays(M):
    mesh = M.to_mesh()
    return np.asarray(mesh.vert_properties)[:, :3].astype(np.float64), np.asarray(mesh.tri_verts).astype(np.int64)


SPHERE = _arrays(m3.Manifold.sphere(22.0, 96).translate([3.0, -2.0, 1.0]))
#: a cylinder along z with a hole drilled through it along x (open to the outside in every slice)
HOLED = _arrays(m3.Manifold.cylinder(36.0, 20.0, 20.0, 96).translate([0, 0, -18])
                - m3.Manifold.cylinder(60.0, 6.0, 6.0, 48).rotate([0, 90, 0]).translate([-30, 0, 0]))


def _grid(n=30, dz=2.0, **kw):
    kw.setdefault("rows", 64)
    kw.setdefault("cols", 72)
    kw.setdefault("spacing", (1.0, 0.8))
    kw.setdefault("origin", np.array([-28.8, -32.0, 0.0]))
    return g.Grid(positions=np.arange(n) * dz - (n - 1) * dz / 2, **kw)


def _distances(V, F, skin, inner=None):
    """|signed distance| of the skin's vertices to the known mesh, those of the end caps left out."""
    d = np.abs(g.mesh_sdf(V, F)(skin.V))
    return d if inner is None else d[inner(skin.V)]


def test_sphere_with_couch_and_lung_imports_within_half_a_millimetre(tmp_path):
    grid = _grid()
    lung = lambda P: 8.0 - np.linalg.norm(P - [3.0, -2.0, 1.0], axis=-1)  # noqa: E731  (a cavity inside)
    couch = g.couch_layers(23.5)  # 3.5 mm under the sphere: left out
    ids = g.sdf_series(str(tmp_path), grid, couch + [(g.mesh_sdf(*SPHERE, band=3.0), g.TISSUE), (lambda P: -lung(P), g.AIR)])
    skin = planning.import_skin(str(tmp_path), "CT")
    assert skin.source == "CT" and skin.frame_uid == ids["frame"] and skin.study_uid == ids["study"]
    assert skin.series_uid == ids["series"] and skin.patient_id == "BOLUS-TEST"
    assert "30 slices" in skin.summary and skin.warnings == []
    d = _distances(*SPHERE, skin)
    assert d.mean() <= 0.5 and skin.V[:, 1].max() < 21.0  # the couch is not in the skin
    rep = closed_report(skin.V, skin.F)
    assert rep["closed"] and rep["components"] == 1  # the lung is filled: one outer surface
    assert signed_volume(skin.V, skin.F) == pytest.approx(4 / 3 * np.pi * 22.0 ** 3, rel=0.03)


def test_couch_plate_touching_the_body_is_cut_off_by_the_opening(tmp_path):
    grid = _grid()
    touching = g.couch_layers(19.5)  # the carbon plate runs 0.5 mm into the sphere's back
    g.sdf_series(str(tmp_path), grid, touching + [(g.mesh_sdf(*SPHERE, band=3.0), g.TISSUE)])
    skin = planning.import_skin(str(tmp_path), "CT")
    assert np.ptp(skin.V[:, 0]) < 46.0  # not the couch's 57.6 mm width
    assert skin.V[:, 1].max() < 19.5 + 3.0 + 1.0  # at most the plate's piece under the contact
    assert _distances(*SPHERE, skin, inner=lambda P: P[:, 1] < 17.0).mean() <= 0.5


def test_holed_cylinder_keeps_its_hole_and_follows_the_mesh(tmp_path):
    grid = _grid(n=24, dz=2.5)
    g.sdf_series(str(tmp_path), grid, [(g.mesh_sdf(*HOLED, band=3.0), g.TISSUE)])
    skin = planning.import_skin(str(tmp_path), "CT")
    d = _distances(*HOLED, skin, inner=lambda P: np.abs(P[:, 2]) < 15.0)
    assert d.mean() <= 0.5
    assert closed_report(skin.V, skin.F)["genus"] == 1


def test_oblique_orientation_is_followed_through_the_affine(tmp_path):
    a = np.radians(20.0)
    grid = _grid(row_cos=np.array([np.cos(a), 0.0, np.sin(a)]), col_cos=np.array([0.0, 1.0, 0.0]),
                 origin=np.array([-28.0, -32.0, 10.0]))
    g.sdf_series(str(tmp_path), grid, [(g.mesh_sdf(*SPHERE, band=3.0), g.TISSUE)])
    skin = planning.import_skin(str(tmp_path), "CT")
    assert any("oblique" in w for w in skin.warnings)
    assert _distances(*SPHERE, skin).mean() <= 0.5


def test_uneven_spacing_and_missing_slices_are_warned_and_placed_where_they_are(tmp_path):
    pos = np.concatenate([np.arange(-30.0, 0.0, 2.0), np.arange(0.0, 31.0, 2.5)])
    uneven = g.Grid(rows=64, cols=72, spacing=(1.0, 0.8), positions=pos, origin=np.array([-28.8, -32.0, 0]))
    g.sdf_series(str(tmp_path / "a"), uneven, [(g.mesh_sdf(*SPHERE, band=3.0), g.TISSUE)])
    skin = planning.import_skin(str(tmp_path / "a"), "CT")
    assert any("not uniform" in w for w in skin.warnings)
    assert _distances(*SPHERE, skin).mean() <= 0.5
    g.sdf_series(str(tmp_path / "b"), _grid(), [(g.mesh_sdf(*SPHERE, band=3.0), g.TISSUE)], skip=(14, 15))
    skin = planning.import_skin(str(tmp_path / "b"), "CT")
    assert any("gap" in w and "missing" in w for w in skin.warnings)
    assert _distances(*SPHERE, skin).mean() <= 0.6  # 6 mm spanned by straight lines


def test_two_series_take_the_larger_and_name_both(tmp_path):
    big = g.sdf_series(str(tmp_path), _grid(), [(g.mesh_sdf(*SPHERE, band=3.0), g.TISSUE)])
    small = g.sdf_series(str(tmp_path / "x"), _grid(n=6), [(g.mesh_sdf(*SPHERE, band=3.0), g.TISSUE)])
    for p in small["paths"]:
        os.replace(p, str(tmp_path / ("S" + os.path.basename(p))))
    (tmp_path / "notes.txt").write_text("not DICOM")
    skin = planning.import_skin(str(tmp_path), "CT")
    assert skin.series_uid == big["series"]
    text = " ".join(skin.warnings)
    assert big["series"] in text and small["series"] in text and "1 file(s)" in text


def test_bad_folders_are_refused_with_a_clear_message(tmp_path):
    with pytest.raises(BolusError, match="not a folder"):
        planning.import_skin(str(tmp_path / "nowhere"))
    with pytest.raises(BolusError, match="no CT images"):
        planning.import_skin(str(tmp_path))
    (tmp_path / "a.txt").write_text("hello")
    (tmp_path / "b.dcm").write_bytes(b"\0" * 300)
    with pytest.raises(BolusError, match=r"no CT images .*2 other file"):
        planning.import_skin(str(tmp_path))
    with pytest.raises(BolusError, match="source must be"):
        planning.import_skin(str(tmp_path), source="MRI")


def test_compressed_transfer_syntax_is_refused(tmp_path):
    g.sdf_series(str(tmp_path), _grid(n=4), [(g.mesh_sdf(*SPHERE, band=3.0), g.TISSUE)], compressed=True)
    with pytest.raises(BolusError, match="compressed .*cannot be decoded"):
        planning.import_skin(str(tmp_path), "CT")


def test_slices_are_sorted_by_position_not_instance_number(tmp_path):
    ids = g.sdf_series(str(tmp_path), _grid(n=8), [(g.mesh_sdf(*SPHERE, band=3.0), g.TISSUE)])
    vol, found = series.read_folder(str(tmp_path))
    assert np.all(np.diff(vol.positions) > 0) and vol.sop_uids == ids["sops"]
    assert vol.hu.dtype == np.float32 and vol.hu.min() == pytest.approx(-1000.0, abs=1)  # rescaled
    assert found.ignored == 0 and "PixelData" not in vol.header


def test_makehuman_chest_on_a_couch_imports_within_half_a_millimetre(tmp_path):
    """The MakeHuman body (tests/data, dm, Y-up) turned into LPS mm, its chest scanned at 2 x 2 x 3 mm."""
    from paths import data_mesh

    from bolus_addon.core.mesh.objfile import load_obj

    V, F, _ = load_obj(data_mesh("makehuman_body.obj"), 100.0)
    V = V @ np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]).T  # Y-up, facing +Z -> LPS (anterior -y)
    grid = g.Grid(rows=112, cols=200, spacing=(2.0, 2.0), positions=np.arange(24) * 3.0 + 326.0,
                  origin=np.array([-200.0, -180.0, 0.0]))
    g.sdf_series(str(tmp_path), grid, g.couch_layers(48.0) + [(g.mesh_sdf(V, F, band=4.0), g.TISSUE)])
    skin = planning.import_skin(str(tmp_path), "CT")
    assert skin.V[:, 1].max() < 47.0  # the couch's plate (y = 48) is not in the skin
    d = _distances(V, F, skin, inner=lambda P: (P[:, 2] > 330.0) & (P[:, 2] < 391.0))
    assert d.mean() <= 0.5
