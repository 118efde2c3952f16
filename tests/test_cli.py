"""scripts/bolus_cli.py run as a planning system's script would: a subprocess with this venv's Python
on a binary STL in mm (test_readme's 70 x 50 mm bump), outputs and report.json read back."""
from __future__ import annotations

import hashlib
import json
import re
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from test_readme import _write_stl_mm

ROOT = Path(__file__).resolve().parents[1]
CLI = ROOT / "scripts" / "bolus_cli.py"

pytestmark = pytest.mark.blender


@pytest.fixture(scope="module")
def stl(tmp_path_factory) -> Path:
    pytest.importorskip("bpy")
    path = tmp_path_factory.mktemp("cli") / "skin.stl"
    _write_stl_mm(path)
    return path


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def run_cli(stl: Path, out: Path, *args: str) -> tuple[subprocess.CompletedProcess, dict | None]:
    """The CLI on stl into out; (the finished process, report.json or None); the input unchanged."""
    before = sha(stl)
    run = subprocess.run([sys.executable, str(CLI), str(stl), "--out", str(out), *args],
                         capture_output=True, text=True, timeout=300)
    assert sha(stl) == before, "the input file was modified"
    report = out / "report.json"
    return run, (json.loads(report.read_text()) if report.is_file() else None)


def read_stl(path: Path) -> np.ndarray:
    """(n, 3, 3) triangles of a binary STL."""
    data = path.read_bytes()
    n = struct.unpack("<I", data[80:84])[0]
    assert len(data) == 84 + 50 * n, f"{path.name}: not a binary STL of {n} triangles"
    rec = np.frombuffer(data[84:], dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), count=n)
    return rec["v"].astype(np.float64)


def edge_use(tris: np.ndarray) -> np.ndarray:
    """How many triangles use each undirected edge (vertices welded by their exact coordinates)."""
    _, F = np.unique(tris.reshape(-1, 3), axis=0, return_inverse=True)
    F = F.reshape(-1, 3)
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    return np.unique(E, axis=0, return_counts=True)[1]


def test_default_steps_write_the_pattern_in_mm(stl, tmp_path):
    out = tmp_path / "case"
    run, report = run_cli(stl, out, "--label", "PT1", "--png", "--png-height", "240")
    assert run.returncode == 0, run.stderr[-3000:]
    for name in ("pattern.svg", "pattern.dxf", "pattern_a4.pdf", "result.blend", "surface.png", "pattern.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    svg = (out / "pattern.svg").read_text()
    w = float(re.search(r'width="([\d.]+)mm"', svg).group(1))
    assert 70.0 < w < 400.0  # the 70 x 50 mm bump laid out at true size, in mm
    assert (out / "pattern_a4.pdf").read_bytes()[:5] == b"%PDF-"
    assert "$INSUNITS" in (out / "pattern.dxf").read_text()
    assert report["error"] is None and report["input"]["unchanged"]
    assert report["steps_done"] == ["preview", "segment", "cuts", "unfold", "export"]
    patches = report["results"]["cuts"]["bolus_patch_table"]["patches"]
    assert len(patches) == 3 and sum(p["faces"] for p in patches) > 0
    pattern = report["results"]["unfold"]["bolus_pattern_table"]
    assert pattern["islands"] and 0.0 <= pattern["EL"] < 0.1
    assert report["results"]["preview"]["bolus_sum_varpi"] > 0
    assert any(r["operator"] == "bolus.segment" and r["type"] == "INFO" for r in report["reports"])
    assert list(report["step_seconds"]) == report["steps_done"]
    assert set(report["seconds"]) >= {"saliency_preview", "segment", "smooth_cuts", "unfold", "export_pattern"}
    assert {"pattern.svg", "pattern.dxf", "pattern_a4.pdf", "report.json"} <= set(report["outputs"])


def test_shell_and_print_write_closed_stl_parts(stl, tmp_path):
    out = tmp_path / "print"
    run, report = run_cli(stl, out, "--steps", "print", "--resolution-mm", "1.0", "--point", "0", "0", "15",
                          "--radius", "30", "--parts", "2")
    assert run.returncode == 0, run.stderr[-3000:]
    assert report["steps_added"] == ["shell"] and report["steps_done"] == ["shell", "print"]
    assert 0 < report["area"]["faces"] < report["area"]["of_faces"]  # --point picked an area, not the mesh
    files = sorted((out / "parts").glob("*.stl"))
    assert len(files) == 2 and [f.name for f in files] == report["results"]["print"]["stl"]
    for f in files:
        use = edge_use(read_stl(f))
        assert (use == 2).all(), f"{f.name}: {np.count_nonzero(use != 2)} edges not used by exactly two triangles"
    assert report["results"]["shell"]["bolus_volume_cm3"] > 0
    rows = report["results"]["print"]["bolus_orient_table"]["rows"]
    assert len([r for r in rows if r["part"] != "whole"]) == 2  # the parts (and the whole model beside them)
    # the area reaches the bump's edge: select_area's warning is collected
    assert any(w.startswith("bolus.select_area:") for w in report["warnings"])


@pytest.mark.smoke
def test_operator_refusal_exits_2_with_the_message_and_a_report(stl, tmp_path):
    out = tmp_path / "refused"
    run, report = run_cli(stl, out, "--steps", "segment,improve,unfold", "--max-gap-mm", "0")
    assert run.returncode == 2, run.stderr[-3000:]
    assert "air gap must be a positive number" in run.stderr
    assert report["error"]["step"] == "improve" and "air gap" in report["error"]["message"]
    assert report["steps_done"] == ["segment"]  # what finished before the refusal
    assert report["results"]["segment"]["bolus_patch_table"]["patches"]
    assert report["input"]["unchanged"]


def test_point_off_the_mesh_is_select_areas_refusal(stl, tmp_path):
    out = tmp_path / "far"
    run, report = run_cli(stl, out, "--point", "500", "500", "500")
    assert run.returncode == 2
    assert "nearest point of the surface" in run.stderr  # bolus.select_area's message
    assert report["error"]["step"] == "area" and report["steps_done"] == []
    assert not (out / "pattern.svg").exists()


def test_sphere_selects_the_area_and_improve_feeds_unfold(stl, tmp_path):
    out = tmp_path / "sphere"
    run, report = run_cli(stl, out, "--units", "mm", "--steps", "improve,export",
                          "--sphere", "0", "0", "10", "25")
    assert run.returncode == 0, run.stderr[-3000:]
    assert 0 < report["area"]["faces"] < report["area"]["of_faces"]
    assert report["results"]["unfold"]["source"] == "skin_improved"
    assert report["results"]["improve"]["bolus_max_air_gap_mm"] <= 1.0 + 1e-6
    assert (out / "pattern.svg").is_file()


def test_units_scale_the_mesh_and_warnings_are_collected(stl, tmp_path):
    """The 70 mm bump read as metres is 70 m wide: the operators' units warning lands in report.json."""
    run, report = run_cli(stl, tmp_path / "metres", "--units", "m", "--steps", "preview")
    assert run.returncode == 0, run.stderr[-3000:]
    assert any("units are probably wrong" in w for w in report["warnings"]), report["warnings"]
    run, report = run_cli(stl, tmp_path / "mm", "--steps", "preview")
    assert report["warnings"] == []


def test_obj_and_ply_are_read_in_the_files_own_frame(stl, tmp_path):
    """The same bump as OBJ and PLY: the same --sphere (off-centre, so a Y-up conversion would move
    it off the area) selects the same faces as on the STL."""
    V, F = np.unique(read_stl(stl).reshape(-1, 3), axis=0, return_inverse=True)
    F = F.reshape(-1, 3)
    (tmp_path / "skin.obj").write_text("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in V)
                                       + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))
    (tmp_path / "skin.ply").write_text(
        f"ply\nformat ascii 1.0\nelement vertex {len(V)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n"
        + "".join(f"{x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in V) + "".join(f"3 {a} {b} {c}\n" for a, b, c in F))
    faces = {}
    for path in (stl, tmp_path / "skin.obj", tmp_path / "skin.ply"):
        run, report = run_cli(path, tmp_path / path.suffix[1:], "--sphere", "0", "12", "6", "10", "--steps", "preview")
        assert run.returncode == 0, (path.name, run.stderr[-3000:])
        faces[path.suffix] = (report["area"]["faces"], report["input"]["faces"])
    assert faces[".obj"] == faces[".ply"] == faces[".stl"] and 0 < faces[".stl"][0] < faces[".stl"][1], faces


@pytest.mark.smoke
@pytest.mark.parametrize("content, says", [(b"", "could not be read"), (bytes(80) + struct.pack("<I", 0), "no faces")])
def test_unreadable_or_empty_file_is_refused(tmp_path, content, says):
    pytest.importorskip("bpy")
    bad = tmp_path / "bad.stl"
    bad.write_bytes(content)
    run, report = run_cli(bad, tmp_path / "out")
    assert run.returncode == 2 and says in run.stderr, run.stderr[-2000:]
    assert report["error"]["step"] == "load" and "Traceback" not in run.stderr


@pytest.mark.smoke
@pytest.mark.parametrize("args, says", [
    (("--steps", "preview,foo"), "unknown step"),
    (("--units", "inch"), "invalid choice"),
    (("--point", "0", "0", "0", "--sphere", "0", "0", "0", "5"), "not allowed with"),
])
def test_bad_argument_is_argparses_exit_2(stl, tmp_path, args, says):
    run, report = run_cli(stl, tmp_path / "bad", *args)
    assert run.returncode == 2 and says in run.stderr and report is None


def test_ct_folder_in_rtstruct_out(tmp_path):
    """--ct: the skin from a generated planning CT, a bolus on its front, the RTSTRUCT back on that CT."""
    pytest.importorskip("bpy")
    pytest.importorskip("pydicom")
    import dicomgen as g
    from dicomcheck import check_rtstruct

    grid = g.Grid(rows=60, cols=64, spacing=(1.0, 0.8), positions=np.arange(28) * 2.0 - 27.0,
                  origin=np.array([-25.6, -30.0, 0.0]))
    ids = g.sdf_series(str(tmp_path / "ct"), grid, [(lambda P: np.linalg.norm(P, axis=-1) - 22.0, g.TISSUE)])
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, str(CLI), "--ct", str(tmp_path / "ct"), "--sphere", "0", "-22", "0", "12",
                          "--steps", "shell", "--thickness-mm", "4", "--resolution-mm", "1", "--out", str(out)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["steps_done"] == ["shell", "rtstruct"] and "RS_bolus.dcm" in report["outputs"]
    src = report["input"]
    assert (src["patient_id"], src["series"], src["frame"]) == ("BOLUS-TEST", ids["series"], ids["frame"])
    m = check_rtstruct(str(out / "RS_bolus.dcm"), str(tmp_path / "ct"), "Bolus")
    assert m["plane_err"] <= 0.01 and m["refs_ok"] and m["frame_ok"] and m["kind"] == "BOLUS"
    assert report["results"]["rtstruct"]["frame"] == ids["frame"]


def test_ct_and_a_mesh_file_together_are_refused(stl, tmp_path):
    run = subprocess.run([sys.executable, str(CLI), str(stl), "--ct", str(tmp_path), "--out", str(tmp_path / "o")],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and "one of the two" in run.stderr
