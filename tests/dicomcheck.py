"""An independent reader of an RTSTRUCT against its CT and the solid it came from.

Nothing of the exporter is used: the CT's slice planes are read here with pydicom, contours
are filled even-odd by a point-in-polygon ray test written here (not a scanline fill), and the
solid's own sections are pixel centres tested against the mesh by libigl's (exact) winding number.
The measures are SPEC's: points on their slice's plane (0.01 mm), references to existing
slices, the frame, RT ROI Interpreted Type, the ROI volume (contour areas x slice spacing)
against the solid's volume inside the CT's range, and Dice on the slice planes.
"""
from __future__ import annotations

import os

import numpy as np


def read_ct_planes(ct_dir: str) -> dict:
    """{SOP Instance UID: (point on the plane (3,), unit normal (3,))}, the frame and spacing."""
    import pydicom

    planes, frame, pos = {}, None, []
    for name in os.listdir(ct_dir):
        try:
            ds = pydicom.dcmread(os.path.join(ct_dir, name), stop_before_pixels=True)
        except Exception:
            continue
        if str(getattr(ds, "SOPClassUID", "")) != "1.2.840.10008.5.1.4.1.1.2":
            continue
        iop = np.array(ds.ImageOrientationPatient, dtype=float)
        n = np.cross(iop[:3], iop[3:])
        p = np.array(ds.ImagePositionPatient, dtype=float)
        planes[str(ds.SOPInstanceUID)] = (p, n / np.linalg.norm(n), iop[:3], iop[3:])
        frame = str(ds.FrameOfReferenceUID)
        pos.append(p @ n)
    pos = np.sort(pos)
    return {"planes": planes, "frame": frame, "positions": pos, "spacing": float(np.median(np.diff(pos)))}


def inside_even_odd(polys: list, pts: np.ndarray) -> np.ndarray:
    """(n,) bool: 2D points inside an odd number of the polygons (a ray towards +x crosses
    the polygon an odd number of times)."""
    inside = np.zeros(len(pts), dtype=bool)
    x, y = pts[:, 0], pts[:, 1]
    for P in polys:
        box = np.flatnonzero((x >= P[:, 0].min()) & (x <= P[:, 0].max()) & (y >= P[:, 1].min()) & (y <= P[:, 1].max()))
        xb, yb = x[box], y[box]
        odd = np.zeros(len(box), dtype=bool)
        for a, b in zip(P, np.roll(P, -1, axis=0)):
            cond = (a[1] > yb) != (b[1] > yb)
            xc = a[0] + (yb - a[1]) * (b[0] - a[0]) / ((b[1] - a[1]) or 1e-300)
            odd ^= cond & (xb < xc)
        inside[box] ^= odd
    return inside


def shoelace(P: np.ndarray) -> float:
    return 0.5 * abs(float(np.dot(P[:, 0], np.roll(P[:, 1], -1)) - np.dot(P[:, 1], np.roll(P[:, 0], -1))))


def check_rtstruct(rs_path: str, ct_dir: str, roi_name: str, V=None, F=None, pixel_mm: float = 0.25,
                   every: int = 1) -> dict:
    """Measures of ROI ``roi_name`` of ``rs_path`` on the CT of ``ct_dir``; with the solid V, F
    also its volume error and Dice (aggregated over every ``every``-th slice)."""
    import pydicom

    ct = read_ct_planes(ct_dir)
    rs = pydicom.dcmread(rs_path)
    num = {str(r.ROIName): int(r.ROINumber) for r in rs.StructureSetROISequence}[roi_name]
    kind = {int(o.ReferencedROINumber): str(o.RTROIInterpretedType) for o in rs.RTROIObservationsSequence}[num]
    rc = [c for c in rs.ROIContourSequence if int(c.ReferencedROINumber) == num][0]
    out = {"frame_ok": str(rs.FrameOfReferenceUID) == ct["frame"]
           and all(str(r.ReferencedFrameOfReferenceUID) == ct["frame"] for r in rs.StructureSetROISequence),
           "kind": kind, "plane_err": 0.0, "refs_ok": True, "min_points": 10 ** 9, "max_ds_len": 0,
           "closed_planar": True, "listed": set(), "numbers": [int(r.ROINumber) for r in rs.StructureSetROISequence]}
    for item in rs.ReferencedFrameOfReferenceSequence[0].RTReferencedStudySequence[0].RTReferencedSeriesSequence:
        out["listed"] |= {str(i.ReferencedSOPInstanceUID) for i in item.ContourImageSequence}
    by_slice = {}
    for c in rc.ContourSequence:
        sop = str(c.ContourImageSequence[0].ReferencedSOPInstanceUID)
        raw = c["ContourData"].value
        out["max_ds_len"] = max(out["max_ds_len"], max(len(str(v)) for v in raw))
        P = np.array([float(v) for v in raw]).reshape(-1, 3)
        out["min_points"] = min(out["min_points"], len(P))
        out["closed_planar"] &= str(c.ContourGeometricType) == "CLOSED_PLANAR"
        if sop not in ct["planes"]:
            out["refs_ok"] = False
            continue
        p0, n, row, col = ct["planes"][sop]
        out["plane_err"] = max(out["plane_err"], float(np.abs((P - p0) @ n).max()))
        by_slice.setdefault(sop, []).append(np.column_stack([(P - p0) @ row, (P - p0) @ col]))
    if V is not None:
        out.update(_against_solid(ct, by_slice, V, F, pixel_mm, every))
    return out


def _against_solid(ct: dict, by_slice: dict, V, F, pixel_mm: float, every: int) -> dict:
    import igl
    import manifold3d as m3

    area = 0.0
    for polys in by_slice.values():
        for i, P in enumerate(polys):
            depth = sum(inside_even_odd([Q], P[:1])[0] for j, Q in enumerate(polys) if j != i)
            area += shoelace(P) * (-1 if depth % 2 else 1)
    h, pos = ct["spacing"], ct["positions"]
    M = m3.Manifold(m3.Mesh(np.asarray(V, np.float32), np.asarray(F, np.uint32)))
    n = next(iter(ct["planes"].values()))[1]
    lo, hi = pos[0] - h / 2, pos[-1] + h / 2
    vol = M.trim_by_plane(list(n), float(lo)).trim_by_plane(list(-n), float(-hi)).volume()
    inter = a_sum = b_sum = 0
    Vd, Fd = np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)
    ranked = sorted(ct["planes"].items(), key=lambda kv: kv[1][0] @ kv[1][1])
    for sop, (p0, n, row, col) in ranked[::every]:
        d = (Vd - p0) @ n
        if d.min() > 0 or d.max() < 0:
            continue
        u, v = (Vd - p0) @ row, (Vd - p0) @ col
        # offset by an odd fraction of a pixel: no point exactly on a flat face of the solid
        gu = np.arange(u.min() - 1, u.max() + 1, pixel_mm) + 0.3183 * pixel_mm
        gv = np.arange(v.min() - 1, v.max() + 1, pixel_mm) + 0.2718 * pixel_mm
        UU, VV = np.meshgrid(gu, gv)
        pts2 = np.column_stack([UU.ravel(), VV.ravel()])
        pts3 = p0 + pts2[:, :1] * row + pts2[:, 1:] * col
        solid = igl.winding_number(Vd, Fd, np.ascontiguousarray(pts3)) > 0.5
        roi = inside_even_odd(by_slice.get(sop, []), pts2)
        inter += int(np.sum(solid & roi))
        a_sum += int(solid.sum())
        b_sum += int(roi.sum())
    return {"roi_volume": area * h, "solid_volume": vol, "volume_rel_err": abs(area * h - vol) / vol,
            "dice": 2 * inter / max(a_sum + b_sum, 1)}
