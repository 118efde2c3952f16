"""Blender-side tests of `bpy.ops.bolus.import_dicom` and `bpy.ops.bolus.export_rtstruct` (SPEC).

A synthetic CT (tests/dicomgen.py) is imported as a user does; the skin's coordinates (scene
units, SPEC's unit rule) are compared with the known sphere; a bolus made on it with Make Bolus
(or any closed mesh on its source chain) is exported and read back by the independent reader
(tests/dicomcheck.py: pydicom and its own rasteriser, not the exporter's code).
"""
from __future__ import annotations

import os

import manifold3d as m3
import numpy as np
import pytest

import dicomgen as g
from bpy_helpers import enter_edit_mode_with_faces, make_object
from dicomcheck import check_rtstruct

pytestmark = pytest.mark.blender
pytest.importorskip("pydicom")

R = 22.0


def _ct(path, **kw):
    grid = g.Grid(rows=60, cols=64, spacing=(1.0, 0.8), positions=np.arange(28) * 2.0 - 27.0,
                  origin=np.array([-25.6, -30.0, 0.0]))
    return g.sdf_series(str(path), grid, g.couch_layers(R + 3.0) + [(lambda P: np.linalg.norm(P, axis=-1) - R,
                                                                     g.TISSUE)], **kw)


def _world_mm(ob, scale_length):
    M = np.array(ob.matrix_world)
    co = np.array([v.co for v in ob.data.vertices])
    return (co @ M[:3, :3].T + M[:3, 3]) * 1000.0 * scale_length


@pytest.mark.smoke
@pytest.mark.parametrize("scale_length", [1.0, 0.001])
def test_import_ct_then_export_a_closed_solid(bpy_addon, scene, capfd, tmp_path, scale_length):
    bpy = bpy_addon
    scene.unit_settings.scale_length = scale_length
    ids = _ct(tmp_path / "ct")
    assert bpy.ops.bolus.import_dicom(directory=str(tmp_path / "ct"), source="CT") == {"FINISHED"}
    skin = bpy.context.active_object
    assert skin.select_get() and skin.name.startswith("BOLUS-TEST")
    assert skin["bolus_dicom_frame_uid"] == ids["frame"] and skin["bolus_dicom_study_uid"] == ids["study"]
    assert skin["bolus_dicom_ct_series_uid"] == ids["series"] and skin["bolus_dicom_patient_id"] == "BOLUS-TEST"
    assert os.path.samefile(skin["bolus_dicom_ct_dir"], tmp_path / "ct")
    out = capfd.readouterr().out
    assert "BOLUS-TEST" in out and "28 slices" in out and ids["series"] in out
    r = np.linalg.norm(_world_mm(skin, scale_length), axis=1)
    assert np.abs(r - R).mean() <= 0.5  # LPS mm under the unit rule; the couch left out
    # a closed solid whose source is the skin: found through the chain, exported on that CT
    V, F = g.manifold_arrays(m3.Manifold.sphere(15.0, 48))
    skin.select_set(False)
    solid = make_object(bpy, V / (1000.0 * scale_length), F, name="solid")
    solid["bolus_source"] = skin.name
    path = str(tmp_path / "rs.dcm")
    assert bpy.ops.bolus.export_rtstruct(filepath=path, rel_electron_density=1.02) == {"FINISHED"}
    m = check_rtstruct(path, str(tmp_path / "ct"), "Bolus", V, F)
    assert m["plane_err"] <= 0.01 and m["refs_ok"] and m["frame_ok"] and m["kind"] == "BOLUS"
    assert m["volume_rel_err"] <= 0.01 and m["dice"] >= 0.99
    assert "check the structure in the planning system" in capfd.readouterr().out


def test_make_shell_bolus_carries_the_frame_and_goes_back(bpy_addon, scene, tmp_path):
    bpy = bpy_addon
    scene.unit_settings.scale_length = 0.001
    _ct(tmp_path / "ct")
    bpy.ops.bolus.import_dicom(directory=str(tmp_path / "ct"), source="CT")
    skin = bpy.context.active_object
    co = np.array([v.co for v in skin.data.vertices])
    centre = np.array([np.mean([co[v] for v in p.vertices], axis=0) for p in skin.data.polygons])
    enter_edit_mode_with_faces(bpy, skin, centre[:, 1] < -12.0)  # the front (anterior: -y) cap
    assert bpy.ops.bolus.make_shell(thickness_mm=4.0, resolution_mm=1.0) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    bolus = bpy.data.objects[skin.name + "_bolus"]
    for key in ("bolus_dicom_frame_uid", "bolus_dicom_ct_dir", "bolus_dicom_patient_id"):
        assert bolus[key] == skin[key]
    for o in bpy.context.view_layer.objects:
        o.select_set(o is bolus)
    bpy.context.view_layer.objects.active = bolus
    path = str(tmp_path / "rs.dcm")
    assert bpy.ops.bolus.export_rtstruct(filepath=path, roi_name="Bolus 4mm") == {"FINISHED"}
    Vb = _world_mm(bolus, 0.001)
    Fb = np.array([p.vertices[:] for p in bolus.data.polygons])
    m = check_rtstruct(path, str(tmp_path / "ct"), "Bolus 4mm", Vb, Fb)
    assert m["plane_err"] <= 0.01 and m["refs_ok"] and m["frame_ok"] and m["dice"] >= 0.99
    assert m["volume_rel_err"] <= 0.01
    # split into print parts (held in place in the bolus's mesh): the sections are their union
    assert bpy.ops.bolus.print_segment(parts=2) == {"FINISHED"}
    assert bpy.ops.bolus.export_rtstruct(filepath=path, roi_name="Bolus 4mm") == {"FINISHED"}
    m = check_rtstruct(path, str(tmp_path / "ct"), "Bolus 4mm", Vb, Fb)
    assert m["plane_err"] <= 0.01 and m["dice"] >= 0.98 and m["volume_rel_err"] <= 0.02
    assert bpy.ops.bolus.orient_parts() == {"FINISHED"}
    part = next(o for o in bpy.data.objects if o.name.startswith(bolus.name + "_part_"))
    for o in bpy.context.view_layer.objects:
        o.select_set(o is part)
    bpy.context.view_layer.objects.active = part
    with pytest.raises(RuntimeError, match="print part turned onto the build plate"):
        bpy.ops.bolus.export_rtstruct(filepath=str(tmp_path / "part.dcm"))
    assert not (tmp_path / "part.dcm").exists()


def test_bad_input_is_refused_with_a_message_and_nothing_added_or_written(bpy_addon, scene, tmp_path):
    bpy = bpy_addon
    (tmp_path / "empty").mkdir()
    n = len(bpy.data.objects)
    with pytest.raises(RuntimeError, match="no CT images"):
        bpy.ops.bolus.import_dicom(directory=str(tmp_path / "empty"))
    with pytest.raises(RuntimeError, match="is not a folder"):
        bpy.ops.bolus.import_dicom(directory=str(tmp_path / "missing"))
    assert len(bpy.data.objects) == n
    V, F = g.manifold_arrays(m3.Manifold.sphere(0.015, 32))
    make_object(bpy, V, F, name="plain")
    path = tmp_path / "rs.dcm"
    with pytest.raises(RuntimeError, match="has no DICOM frame"):
        bpy.ops.bolus.export_rtstruct(filepath=str(path))
    ids = _ct(tmp_path / "ct")
    bpy.context.active_object["bolus_dicom_frame_uid"] = g.new_uid()  # another CT's frame
    with pytest.raises(RuntimeError, match="is not the CT's"):
        bpy.ops.bolus.export_rtstruct(filepath=str(path), ct_directory=str(tmp_path / "ct"))
    assert not path.exists()
    bpy.context.active_object["bolus_dicom_frame_uid"] = ids["frame"]
    assert bpy.ops.bolus.export_rtstruct(filepath=str(path), ct_directory=str(tmp_path / "ct")) == {"FINISHED"}


def test_warnings_are_reported_as_warning(bpy_addon, scene, capfd, tmp_path):
    bpy = bpy_addon
    _ct(tmp_path, skip=(13, 14))
    (tmp_path / "readme.txt").write_text("not DICOM")
    assert bpy.ops.bolus.import_dicom(directory=str(tmp_path), source="AUTO") == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Warning:" in out and "missing" in out and "1 file(s)" in out
