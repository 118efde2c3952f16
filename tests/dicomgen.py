"""Synthetic CT series (and structure sets) with known geometry, written with pydicom.

HU come from a signed distance d (mm, negative inside) with a partial-volume ramp across one
voxel: HU = air + (tissue - air) * clip(0.5 - d / ramp, 0, 1).  Meshes give d through libigl's
signed distance; `torso_sdf` is an analytic chest-like body (elliptic, lungs inside) for the
large benchmark series.  Slices are written with z decreasing as the instance number grows,
pixels as uint16 with Rescale Intercept -1024, so a reader must sort by position and rescale.
"""
from __future__ import annotations

import os
import uuid
from dataclasses import dataclass, field

import numpy as np

AIR, TISSUE, COUCH = -1000.0, 40.0, 300.0


def new_uid() -> str:
    return "2.25." + str(uuid.uuid4().int)


@dataclass
class Grid:
    """A CT geometry: slice positions along the normal, in-plane size and spacing, orientation."""
    rows: int = 64
    cols: int = 80
    spacing: tuple = (1.25, 1.0)  #: (row spacing, column spacing) mm
    positions: np.ndarray = field(default_factory=lambda: np.arange(40) * 2.0 - 40.0)
    origin: np.ndarray = field(default_factory=lambda: np.array([-40.0, -32.0, 0.0]))  #: in-plane origin (x, y) ...
    row_cos: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    col_cos: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))

    @property
    def normal(self) -> np.ndarray:
        return np.cross(self.row_cos, self.col_cos)

    def ipp(self, k: int) -> np.ndarray:
        """Image Position Patient of slice k: the in-plane origin moved to its position along n."""
        base = self.origin - (self.origin @ self.normal) * self.normal
        return base + self.positions[k] * self.normal

    def centres(self, k: int) -> np.ndarray:
        """(rows, cols, 3) LPS mm pixel centres of slice k."""
        r = np.arange(self.rows)[:, None, None] * self.spacing[0] * self.col_cos
        c = np.arange(self.cols)[None, :, None] * self.spacing[1] * self.row_cos
        return self.ipp(k) + r + c


def ramp_hu(d: np.ndarray, ramp: float, inside: float = TISSUE, outside: float = AIR) -> np.ndarray:
    return outside + (inside - outside) * np.clip(0.5 - d / ramp, 0.0, 1.0)


def mesh_sdf(V, F):
    """A signed-distance function (points (n,3) -> (n,) mm, negative inside) of a closed mesh."""
    import igl

    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)

    def sdf(P):
        res = igl.signed_distance(np.ascontiguousarray(P.reshape(-1, 3)), V, F)
        return np.asarray(res[0]).reshape(P.shape[:-1])
    return sdf


def torso_sdf(P: np.ndarray) -> np.ndarray:
    """Approximate signed distance (mm) of a chest-like body: an ellipse 340 x 220 mm whose size
    swells along z, two lungs (returned separately by `torso_lungs`)."""
    x, y, z = P[..., 0], P[..., 1], P[..., 2]
    a = 170.0 + 10.0 * np.sin(z / 80.0)
    b = 110.0 + 6.0 * np.cos(z / 60.0)
    rho = np.sqrt((x / a) ** 2 + (y / b) ** 2)
    return (rho - 1.0) * np.minimum(a, b) * (1 + 0.0 * rho)


def torso_lungs(P: np.ndarray) -> np.ndarray:
    x, y = P[..., 0], P[..., 1]
    return np.minimum(np.hypot((np.abs(x) - 70.0) / 50.0, y / 70.0) - 1.0, 0.0) < 0


def couch_sdf(top: float, thickness: float = 3.0, half_width: float = 250.0):
    """A slab under the body (LPS: posterior is +y): from y = top to top + thickness."""
    def sdf(P):
        y, x = P[..., 1], P[..., 0]
        return np.maximum(np.maximum(top - y, y - top - thickness), np.abs(x) - half_width)
    return sdf


def couch_layers(top: float, half_width: float = 250.0) -> list:
    """[(sdf, HU)] of a couch as planning CTs show it: a 3 mm carbon plate at y = top, 30 mm of
    foam (below the skin threshold), a 3 mm bottom plate; put before the body's layers."""
    return [(couch_sdf(top, 36.0, half_width), -850.0), (couch_sdf(top, 3.0, half_width), COUCH),
            (couch_sdf(top + 33.0, 3.0, half_width), COUCH)]


def write_series(directory: str, grid: Grid, hu_of_slice, patient_id: str = "BOLUS-TEST", study_uid=None,
                 frame_uid=None, series_uid=None, compressed: bool = False, skip=()) -> dict:
    """Write one CT series: ``hu_of_slice(k, centres (rows, cols, 3)) -> (rows, cols) HU``.
    Instance numbers grow as z falls (slice k = positions[k] gets instance n - k).  Returns the
    identifiers {study, frame, series, sops (per k, None where skipped), paths}."""
    import pydicom
    from pydicom.dataset import FileMetaDataset, Dataset
    from pydicom.uid import ExplicitVRLittleEndian, JPEG2000Lossless

    os.makedirs(directory, exist_ok=True)
    study_uid, frame_uid, series_uid = study_uid or new_uid(), frame_uid or new_uid(), series_uid or new_uid()
    n = len(grid.positions)
    out = {"study": study_uid, "frame": frame_uid, "series": series_uid, "sops": [None] * n, "paths": []}
    for k in range(n):
        if k in skip:
            continue
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.2"
        sop = new_uid()
        meta.MediaStorageSOPInstanceUID = sop
        meta.TransferSyntaxUID = JPEG2000Lossless if compressed else ExplicitVRLittleEndian
        ds = Dataset()
        ds.file_meta = meta
        ds.SOPClassUID, ds.SOPInstanceUID = meta.MediaStorageSOPClassUID, sop
        ds.Modality, ds.PatientID, ds.PatientName = "CT", patient_id, "Test^Phantom"
        ds.StudyInstanceUID, ds.SeriesInstanceUID, ds.FrameOfReferenceUID = study_uid, series_uid, frame_uid
        ds.StudyDate, ds.StudyID, ds.SeriesNumber = "20260101", "1", 1
        ds.InstanceNumber = n - k
        ds.ImagePositionPatient = [f"{v:.6f}" for v in grid.ipp(k)]
        ds.ImageOrientationPatient = [f"{v:.9f}" for v in np.concatenate([grid.row_cos, grid.col_cos])]
        ds.PixelSpacing = [f"{v:g}" for v in grid.spacing]
        ds.SliceThickness = f"{float(np.median(np.abs(np.diff(grid.positions)))) if n > 1 else 1.0:g}"
        ds.Rows, ds.Columns = grid.rows, grid.cols
        ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 0
        ds.RescaleIntercept, ds.RescaleSlope = "-1024", "1"
        hu = hu_of_slice(k, grid.centres(k))
        ds.PixelData = np.clip(np.rint(hu + 1024.0), 0, 65535).astype("<u2").tobytes()
        path = os.path.join(directory, f"CT{n - k:04d}.dcm")
        ds.save_as(path, enforce_file_format=True) if not compressed else _save_raw(ds, path)
        out["sops"][k] = sop
        out["paths"].append(path)
    return out


def _save_raw(ds, path):
    """Save with a compressed transfer syntax declared but the pixel bytes left as they are
    (encapsulation is not checked until the pixels are decoded)."""
    from pydicom.encaps import encapsulate

    ds.PixelData = encapsulate([ds.PixelData])
    ds["PixelData"].VR = "OB"
    ds.save_as(path, enforce_file_format=True)


def sdf_series(directory: str, grid: Grid, sdfs, ramp: float | None = None, **kw) -> dict:
    """A series from [(sdf, HU inside)], later ones over earlier ones, air elsewhere."""
    ramp = ramp or float(np.mean(grid.spacing))

    def hu_of_slice(k, P):
        hu = np.full(P.shape[:2], AIR)
        for sdf, inside in sdfs:
            f = np.clip(0.5 - sdf(P) / ramp, 0.0, 1.0)
            hu = hu + (inside - hu) * f
        return hu
    return write_series(directory, grid, hu_of_slice, **kw)
