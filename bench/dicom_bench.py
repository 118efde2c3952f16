"""Benchmark of the DICOM import and the RTSTRUCT export (printed, not asserted).

Run from the repository root:

    .venv/bin/python bench/dicom_bench.py            # 300 x 512 x 512 CT import, 111-slice export (about 3 minutes)
    .venv/bin/python bench/dicom_bench.py --quick    # a 60 x 256 x 256 CT import, the same export
    .venv/bin/python bench/dicom_bench.py --markdown docs/benchmarks.md   # append the tables (make bench)

Data (tests/dicomgen.py, written to a temporary folder): a chest-like torso (an elliptic body
340 x 220 mm swelling along z, two lungs at -850 HU) on a couch (a 3 mm carbon plate 4 mm under
the back, foam, a bottom plate), partial volume across one voxel, uint16 pixels with Rescale
Intercept -1024, z falling with the instance number; 0.98 x 0.98 mm pixels, 2.5 mm slices.

* Import (each in a child process of its own, ``--worker``: time of the call, peak = the child's
  VmHWM minus its RSS before the call): ours, ``planning.import_skin(dir, 'CT')`` (read, body
  mask, crop, marching cubes, smoothing); the peer, marching cubes (the same libigl mesher) on
  the whole uncropped volume at the threshold without the component step.  Quality, on the
  vertices more than two slices from the end caps: the share farther than 5 mm from the
  torso's outer surface (the couch, the lungs' walls), the mean distance of the others (the
  torso's approximate analytic distance).
* Export of a 10 mm chest bolus (`dicomgen.chest_bolus`, 220 mm wide, 180 mm tall) on a 111-slice
  CT: ours, ``planning.export_rtstruct`` (exact sections, file written); the peer, the pixel-mask
  approach of rt-utils: the solid rasterised on the CT's pixel grid (pixel centres inside, by
  libigl's winding number), its area the pixel count (the best a traced mask can do: OpenCV's
  traced outline through the boundary pixels' centres loses a further half pixel along the
  perimeter).  Both against the solid's own sections at 0.5 mm on every 10th slice (Dice) and the
  solid's volume (contour areas x slice spacing), measured by tests/dicomcheck.py's reader.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

import benchutil  # (also puts the repository and tests/ on sys.path)
import numpy as np

import dicomgen as g

PIXEL_MM = 500.0 / 512
SLICE_MM = 2.5
THRESHOLD = -350.0
#: the quality of the export: the fine grid (mm) and every how many slices it is measured on
FINE_MM, EVERY = 0.5, 10


def _torso_layers():
    lungs = lambda P: np.where(g.torso_lungs(P), -1.0, 1.0)  # noqa: E731
    return g.couch_layers(118.0) + [(g.torso_sdf, g.TISSUE), (lungs, -850.0)]


def make_ct(directory: str, slices: int, size: int) -> g.Grid:
    px = PIXEL_MM * 512 / size
    grid = g.Grid(rows=size, cols=size, spacing=(px, px), positions=(np.arange(slices) - (slices - 1) / 2) * SLICE_MM,
                  origin=np.array([-250.0, -250.0, 0.0]))
    g.sdf_series(directory, grid, _torso_layers())
    return grid



def worker(kind: str, directory: str) -> dict:
    """One import in this fresh process -> seconds, peak MB above the start, quality."""
    from bolus_addon.core.dicom import planning, series
    from bolus_addon.core.solid.marching import marching_cubes

    benchutil.reset_peak_rss()
    before = benchutil.status_kb("VmRSS")
    t0 = time.perf_counter()
    if kind == "ours":
        skin = planning.import_skin(directory, "CT", THRESHOLD)
        V, F = skin.V, skin.F
    else:
        vol, _ = series.read_folder(directory)
        V, F = marching_cubes(vol.hu - np.float32(THRESHOLD), np.zeros(3), np.ones(3), pad=True)
        V = vol.to_patient(V)
    took = time.perf_counter() - t0
    peak = (benchutil.status_kb("VmHWM") - before) / 1024
    z = V[:, 2]
    side = np.abs(z - 0.5 * (z.min() + z.max())) < 0.5 * np.ptp(z) - 2 * SLICE_MM  # the end caps left out
    d = np.abs(g.torso_sdf(V[side]))
    far = d > 5.0
    return {"s": took, "peak_mb": peak, "triangles": int(len(F)), "far_pct": 100.0 * far.mean(),
            "mean_mm": float(d[~far].mean()) if (~far).any() else float("nan")}


def _child(kind: str, directory: str) -> dict:
    out = subprocess.run([sys.executable, __file__, "--worker", kind, directory], capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "worker failed")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _peer_mask(grid: g.Grid, V, F):
    """rt-utils' way: the solid rasterised on the CT's pixels (those within its bounding box, in
    one call of libigl's exact winding number) -> ({slice k: (rows, cols) bool}, seconds)."""
    import igl

    t0 = time.perf_counter()
    lo, hi = V.min(axis=0), V.max(axis=0)
    ks = [k for k in range(len(grid.positions)) if lo[2] <= grid.positions[k] <= hi[2]]
    P = np.stack([grid.centres(k) for k in ks])  # (len(ks), rows, cols, 3)
    box = np.all((P >= lo - 1.0) & (P <= hi + 1.0), axis=(0, 3)) if ks else None
    inside = np.zeros(P.shape[:3], dtype=bool)
    if ks:
        Q = np.ascontiguousarray(P[:, box].reshape(-1, 3))
        w = igl.winding_number(V, F, Q) > 0.5
        inside[:, box] = w.reshape(len(ks), -1)
    return {k: inside[i] for i, k in enumerate(ks)}, time.perf_counter() - t0


def _peer_quality(grid: g.Grid, masks: dict, V, F, every: int, fine: float) -> dict:
    """Dice of the mask (each fine point takes its pixel's value) and the volume error."""
    import igl
    import manifold3d as m3

    inter = a = b = 0
    for k in sorted(masks)[::every]:
        lo, hi = V.min(axis=0), V.max(axis=0)
        xs = np.arange(lo[0] - 1, hi[0] + 1, fine) + 0.3183 * fine  # no point on a flat face
        ys = np.arange(lo[1] - 1, hi[1] + 1, fine) + 0.2718 * fine
        X, Y = np.meshgrid(xs, ys)
        pts = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, grid.positions[k])])
        truth = igl.winding_number(V, F, pts) > 0.5
        c = np.rint((pts[:, 0] - grid.ipp(k)[0]) / grid.spacing[1]).astype(int)
        r = np.rint((pts[:, 1] - grid.ipp(k)[1]) / grid.spacing[0]).astype(int)
        ok = (r >= 0) & (r < grid.rows) & (c >= 0) & (c < grid.cols)
        mask = np.zeros(len(pts), dtype=bool)
        mask[ok] = masks[k][r[ok], c[ok]]
        inter, a, b = inter + int((truth & mask).sum()), a + int(truth.sum()), b + int(mask.sum())
    vol = m3.Manifold(m3.Mesh(V.astype(np.float32), F.astype(np.uint32))).volume()
    area = sum(int(m.sum()) for m in masks.values()) * grid.spacing[0] * grid.spacing[1]
    return {"dice": 2 * inter / (a + b), "volume_err_pct": 100 * abs(area * SLICE_MM - vol) / vol}


def export_rows(tmp: str) -> list:
    from dicomcheck import check_rtstruct
    from bolus_addon.core.dicom import planning

    ct = os.path.join(tmp, "ct111")
    grid = make_ct(ct, 111, 512)
    V, F = g.chest_bolus(z0=-91.25, z1=88.75, segments=512)
    out = os.path.join(tmp, "rs.dcm")
    t0 = time.perf_counter()
    res = planning.export_rtstruct(out, ct, [("Bolus", V, F)])
    ours_s = time.perf_counter() - t0
    m = check_rtstruct(out, ct, "Bolus", V, F, pixel_mm=FINE_MM, every=EVERY)
    masks, peer_s = _peer_mask(grid, V, F)
    pq = _peer_quality(grid, masks, V, F, EVERY, FINE_MM)
    return [{"method": "ours: exact sections", "s": ours_s, "contours": res["contours"], "dice": m["dice"],
             "volume_err_pct": 100 * m["volume_rel_err"], "plane_err": m["plane_err"]},
            {"method": "peer: pixel mask (rt-utils)", "s": peer_s, "contours": len(masks), "dice": pq["dice"],
             "volume_err_pct": pq["volume_err_pct"], "plane_err": 0.0}]


def main(argv=None) -> int:
    ap = benchutil.parser(__doc__, "a 60 x 256 x 256 CT for the import", repeat=None)
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    slices, size = (60, 256) if args.quick else (300, 512)
    with tempfile.TemporaryDirectory() as tmp:
        ct = os.path.join(tmp, "ct")
        t0 = time.perf_counter()
        make_ct(ct, slices, size)
        print(f"wrote a {slices} x {size} x {size} CT in {time.perf_counter() - t0:.1f} s", flush=True)
        imp = benchutil.Table([("import", "<"), ("time s", ">"), ("peak MB", ">"), ("triangles", ">"),
                               ("far > 5 mm %", ">"), ("mean mm", ">")])
        rows = []
        for kind, label in (("ours", "ours: largest body, cropped"), ("peer", "peer: whole volume, no components")):
            r = _child(kind, ct)
            rows.append({"method": label, **r})
            imp.add(label, f"{r['s']:.2f}", f"{r['peak_mb']:.0f}", f"{r['triangles']:,}", f"{r['far_pct']:.1f}",
                    f"{r['mean_mm']:.3f}")
        print(imp.text())
        exp = benchutil.Table([("export (111 slices, 10 mm chest bolus)", "<"), ("time s", ">"), ("contours", ">"),
                               ("Dice", ">"), ("volume error %", ">"), ("max off-plane mm", ">")])
        erows = export_rows(tmp)
        for r in erows:
            exp.add(r["method"], f"{r['s']:.2f}", r["contours"], f"{r['dice']:.5f}", f"{r['volume_err_pct']:.3f}",
                    f"{r['plane_err']:.1e}")
        print(exp.text())
    md = "\n".join(["## DICOM import and RTSTRUCT export (`bench/dicom_bench.py`)", "",
                    benchutil.run_line("dicom_bench.py", argv), "",
                    f"Import of a {slices}-slice {size} x {size} synthetic CT (torso, lungs, couch):", "",
                    imp.markdown(), "", f"Export on a 111-slice 512 x 512 CT (Dice at {FINE_MM} mm on every {EVERY}th slice):", "",
                    exp.markdown()])
    benchutil.finish(args, {"quick": args.quick, "import": rows, "export": erows}, time.perf_counter() - t_all, md)
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        print(json.dumps(worker(sys.argv[2], sys.argv[3])))
        sys.exit(0)
    sys.exit(main())
