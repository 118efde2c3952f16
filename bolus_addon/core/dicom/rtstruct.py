"""A structure set read: its ROIs, the External ROI, and an ROI's contours made a surface.

The External ROI is the one whose RT ROI Interpreted Type is EXTERNAL, else the first named
like BODY / External / Skin / Outline.  Its contours become a surface this way: each contour
plane is a plane of a grid in the slice frame (x along the CT's rows, y along its columns, z
along the normal) at half the CT's finer pixel spacing; the plane's contours are rasterised
even-odd (nested contours are holes) and turned into a signed distance (mm, positive inside;
scipy's Euclidean distance transform); marching cubes (`core.solid.marching`) runs on the stack
of planes, whose ends get the mirrored field so the caps lie half a slice beyond the last
contours (the convention of planning systems).  Vertices are mapped back to LPS mm.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..errors import BolusError
from ..solid.marching import marching_cubes
from .series import CTVolume
from .skin import signed_volume

__all__ = ["ROI", "StructureSet", "EXTERNAL_NAMES", "read_structure_set", "find_roi", "roi_contours",
           "rasterise_even_odd", "contours_surface"]

EXTERNAL_NAMES = ("body", "external", "skin", "outline", "patient")


@dataclass
class ROI:
    number: int
    name: str
    kind: str  #: RT ROI Interpreted Type ("" when none)


@dataclass
class StructureSet:
    path: str
    ds: object
    frame_uids: set
    rois: list


def read_structure_set(path: str) -> StructureSet:
    """The structure set at ``path``: its ROIs (number, name, interpreted type) and frames."""
    import pydicom

    ds = pydicom.dcmread(path)
    kinds = {int(o.ReferencedROINumber): str(getattr(o, "RTROIInterpretedType", "") or "")
             for o in getattr(ds, "RTROIObservationsSequence", [])}
    rois = [ROI(int(r.ROINumber), str(getattr(r, "ROIName", "")), kinds.get(int(r.ROINumber), ""))
            for r in getattr(ds, "StructureSetROISequence", [])]
    frames = {str(f.FrameOfReferenceUID) for f in getattr(ds, "ReferencedFrameOfReferenceSequence", [])}
    frames |= {str(r.ReferencedFrameOfReferenceUID) for r in getattr(ds, "StructureSetROISequence", [])
               if "ReferencedFrameOfReferenceUID" in r}
    return StructureSet(path=path, ds=ds, frame_uids=frames, rois=rois)


def find_roi(ss: StructureSet, roi_name: str = "") -> ROI | None:
    """The ROI named ``roi_name`` (case-insensitive), else the External one, else None."""
    if roi_name:
        for r in ss.rois:
            if r.name.strip().lower() == roi_name.strip().lower():
                return r
        names = ", ".join(r.name for r in ss.rois) or "none"
        raise BolusError(f"the structure set has no ROI named '{roi_name}' (its ROIs: {names})")
    for r in ss.rois:
        if r.kind.upper() == "EXTERNAL":
            return r
    for r in ss.rois:
        if any(w in r.name.strip().lower() for w in EXTERNAL_NAMES):
            return r
    return None


def roi_contours(ss: StructureSet, number: int) -> list[np.ndarray]:
    """The ROI's contours, each (p,3) LPS mm (points and lines left out)."""
    out = []
    for rc in getattr(ss.ds, "ROIContourSequence", []):
        if int(rc.ReferencedROINumber) != number:
            continue
        for c in getattr(rc, "ContourSequence", []):
            if str(getattr(c, "ContourGeometricType", "CLOSED_PLANAR")) != "CLOSED_PLANAR":
                continue
            P = np.asarray([float(v) for v in c.ContourData], dtype=np.float64).reshape(-1, 3)
            if len(P) >= 3:
                out.append(P)
    return out


def rasterise_even_odd(polys: list, x0: float, y0: float, h: float, shape: tuple) -> np.ndarray:
    """(ny, nx) bool: pixel centres (x0 + i h, y0 + j h) inside an odd number of the 2D
    polygons ``polys`` (each (p,2), closed implicitly)."""
    ny, nx = shape
    toggles = np.zeros((ny, nx + 1), dtype=np.int32)
    for P in polys:
        a, b = P, np.roll(P, -1, axis=0)
        for (xa, ya), (xb, yb) in ((a[i], b[i]) for i in range(len(a)) if a[i][1] != b[i][1]):
            jlo = int(np.ceil((min(ya, yb) - y0) / h))
            jhi = int(np.ceil((max(ya, yb) - y0) / h))  # rows with ya <= y < yb (half-open)
            j = np.arange(max(jlo, 0), min(jhi, ny))
            if len(j) == 0:
                continue
            x = xa + (y0 + j * h - ya) * (xb - xa) / (yb - ya)
            i = np.clip(np.ceil((x - x0) / h).astype(np.int64), 0, nx)
            np.add.at(toggles, (j, i), 1)
    return (np.cumsum(toggles, axis=1)[:, :nx] % 2).astype(bool)


def contours_surface(vol: CTVolume, contours: list, what: str = "the ROI") -> tuple[np.ndarray, np.ndarray]:
    """The closed surface (V (n,3) LPS mm, F (m,3), outward) of CLOSED_PLANAR ``contours``."""
    if not contours:
        raise BolusError(f"{what} has no closed contours")
    A = vol.to_slice_frame()
    local = [P @ A[:3, :3].T + A[:3, 3] for P in contours]
    allp = np.concatenate(local)
    h = 0.5 * min(vol.spacing)
    x0, y0 = allp[:, 0].min() - 3 * h, allp[:, 1].min() - 3 * h
    nx = int(np.ceil((allp[:, 0].max() + 3 * h - x0) / h)) + 1
    ny = int(np.ceil((allp[:, 1].max() + 3 * h - y0) / h)) + 1
    zs = np.array([float(np.mean(P[:, 2])) for P in local])
    planes = np.unique(np.round(zs, 2))
    if nx * ny * (len(planes) + 2) > 400_000_000:
        raise BolusError(f"{what} is too large to mesh at {h:g} mm")
    field = np.empty((len(planes) + 2, ny, nx), dtype=np.float32)
    which = np.searchsorted(planes, np.round(zs, 2))
    for j in range(len(planes)):
        inside = rasterise_even_odd([P[:, :2] for P, w in zip(local, which) if w == j], x0, y0, h, (ny, nx))
        field[j + 1] = (ndimage.distance_transform_edt(inside, sampling=h)
                        - ndimage.distance_transform_edt(~inside, sampling=h))
    field[0], field[-1] = -np.abs(field[1]), -np.abs(field[-2])
    V, F = marching_cubes(field, np.zeros(3), np.ones(3), pad=False)
    if len(F) == 0:
        raise BolusError(f"{what} encloses no area")
    step = np.diff(planes) if len(planes) > 1 else np.array([vol.slice_spacing])
    zpos = np.concatenate([[planes[0] - step[0]], planes, [planes[-1] + step[-1]]])
    k = V[:, 0]
    i = np.clip(np.floor(k).astype(np.int64), 0, len(zpos) - 2)
    z = zpos[i] + (k - i) * (zpos[i + 1] - zpos[i])
    local_pts = np.column_stack([x0 + V[:, 2] * h, y0 + V[:, 1] * h, z])
    R, t = A[:3, :3], A[:3, 3]
    V = (local_pts - t) @ R  # R is orthonormal: its inverse is its transpose
    if signed_volume(V, F) < 0:
        F = F[:, ::-1]
    return V, np.ascontiguousarray(F)
