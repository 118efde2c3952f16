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
    #: a point of the first pixel's line along the normal (LPS mm): its in-plane part is used
    origin: np.ndarray = field(default_factory=lambda: np.array([-40.0, -32.0, 0.0]))
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


def mesh_sdf(V, F, band: float | None = None):
    """A signed-distance function (points (..., 3) -> (...) mm, negative inside) of a closed mesh.
    ``band``: on a slice of points (rows, cols, 3), distances are searched only within the band
    (libigl stops early); every region of the slice beyond it takes the sign of its first point's
    winding number, its value +-band: enough for a partial-volume ramp narrower than the band."""
    import igl
    from scipy import ndimage

    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)

    def sdf(P):
        Q = np.ascontiguousarray(P.reshape(-1, 3))
        if band is None or P.ndim != 3:
            return np.asarray(igl.signed_distance(Q, V, F)[0]).reshape(P.shape[:-1])
        d = np.asarray(igl.signed_distance(Q, V, F, igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_PSEUDONORMAL,
                                           -band, band)[0]).reshape(P.shape[:-1])
        far = ~(np.abs(d) < 0.999 * band)  # NaN or the bound: not searched
        lab, n = ndimage.label(far)
        if n:
            first = ndimage.minimum_position(np.arange(lab.size).reshape(lab.shape), lab, np.arange(1, n + 1))
            reps = np.array([P[i, j] for i, j in first])
            inside = igl.winding_number(V, F, np.ascontiguousarray(reps)) > 0.5
            d[far] = np.where(np.concatenate([[False], inside])[lab[far]], -band, band)
        return d
    return sdf


def torso_sdf(P: np.ndarray) -> np.ndarray:
    """Approximate signed distance (mm) of a chest-like body: an ellipse 340 x 220 mm whose size
    swells along z (its lungs: `torso_lungs`)."""
    x, y, z = P[..., 0], P[..., 1], P[..., 2]
    a = 170.0 + 10.0 * np.sin(z / 80.0)
    b = 110.0 + 6.0 * np.cos(z / 60.0)
    rho = np.sqrt((x / a) ** 2 + (y / b) ** 2)
    return (rho - 1.0) * np.minimum(a, b)


def torso_lungs(P: np.ndarray) -> np.ndarray:
    """(...) bool: inside one of two elliptic lungs (100 x 140 mm, 70 mm either side)."""
    x, y = P[..., 0], P[..., 1]
    return np.hypot((np.abs(x) - 70.0) / 50.0, y / 70.0) < 1.0


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


def write_structure_set(path: str, ids: dict, grid: Grid, rois: list, frame_uid: str | None = None) -> None:
    """A structure set as a planning system writes one: ``rois`` [(name, interpreted type,
    {slice k: [(p,2) in-plane polygons (mm along rows, columns)]})] on the series ``ids``."""
    from pydicom.dataset import FileMetaDataset, Dataset
    from pydicom.uid import ExplicitVRLittleEndian

    def item(**kw):
        d = Dataset()
        for k, v in kw.items():
            setattr(d, k, v)
        return d

    frame = frame_uid or ids["frame"]
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID, meta.MediaStorageSOPInstanceUID = "1.2.840.10008.5.1.4.1.1.481.3", new_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID, ds.SOPInstanceUID = meta.MediaStorageSOPClassUID, meta.MediaStorageSOPInstanceUID
    ds.Modality, ds.PatientID, ds.StudyInstanceUID, ds.SeriesInstanceUID = "RTSTRUCT", "BOLUS-TEST", ids["study"], new_uid()
    ds.FrameOfReferenceUID = frame
    ds.StructureSetLabel = "TPS"
    images = [item(ReferencedSOPClassUID="1.2.840.10008.5.1.4.1.1.2", ReferencedSOPInstanceUID=s)
              for s in ids["sops"] if s]
    ds.ReferencedFrameOfReferenceSequence = [item(FrameOfReferenceUID=frame, RTReferencedStudySequence=[item(
        ReferencedSOPClassUID="1.2.840.10008.3.1.2.3.1", ReferencedSOPInstanceUID=ids["study"],
        RTReferencedSeriesSequence=[item(SeriesInstanceUID=ids["series"], ContourImageSequence=images)])])]
    ss, rc, obs = [], [], []
    for i, (name, kind, polys) in enumerate(rois, start=1):
        ss.append(item(ROINumber=i, ReferencedFrameOfReferenceUID=frame, ROIName=name, ROIGenerationAlgorithm="MANUAL"))
        contours = []
        for k, plist in sorted(polys.items()):
            for P in plist:
                X = grid.ipp(k) + P[:, :1] * grid.row_cos + P[:, 1:2] * grid.col_cos
                contours.append(item(ContourGeometricType="CLOSED_PLANAR", NumberOfContourPoints=len(P),
                                     ContourData=[f"{v:.4f}" for v in X.ravel()],
                                     ContourImageSequence=[item(ReferencedSOPClassUID="1.2.840.10008.5.1.4.1.1.2",
                                                                ReferencedSOPInstanceUID=ids["sops"][k])]))
        rc.append(item(ReferencedROINumber=i, ROIDisplayColor=[255, 0, 0], ContourSequence=contours))
        obs.append(item(ObservationNumber=i, ReferencedROINumber=i, RTROIInterpretedType=kind, ROIInterpreter=""))
    ds.StructureSetROISequence, ds.ROIContourSequence, ds.RTROIObservationsSequence = ss, rc, obs
    ds.save_as(path, enforce_file_format=True)


def circle(cx: float, cy: float, r: float, n: int = 72) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])


def manifold_arrays(M):
    """(V (n,3) float64, F (m,3) int64) of a manifold3d Manifold."""
    mesh = M.to_mesh()
    return np.asarray(mesh.vert_properties)[:, :3].astype(np.float64), np.asarray(mesh.tri_verts).astype(np.int64)


def chest_bolus(a: float = 150.0, b: float = 100.0, thickness: float = 10.0, z0: float = -90.0, z1: float = 90.0,
                width: float = 220.0, segments: int = 256):
    """A 10 mm chest-like bolus (V, F, LPS mm): the anterior part (y < -30 mm) of an elliptic
    wall between the ellipses (a, b) and (a + t, b + t), z0 <= z <= z1, at most ``width`` wide."""
    import manifold3d as m3

    def ell(ea, eb, lo, hi):
        return m3.Manifold.cylinder(hi - lo, 1.0, 1.0, segments).scale([ea, eb, 1.0]).translate([0, 0, lo])
    wall = ell(a + thickness, b + thickness, z0, z1) - ell(a, b, z0 - 10.0, z1 + 10.0)
    box = m3.Manifold.cube([width, 200.0, z1 - z0]).translate([-width / 2, -230.0, z0])
    return manifold_arrays(wall ^ box)
