"""A folder of DICOM files read into one CT volume and the folder's structure sets.

Files are classified by SOP Class UID (CT Image Storage, RT Structure Set Storage; anything
else, DICOM or not, is counted and left out).  CT slices are grouped by Series Instance UID
(of two series the larger is taken, with a warning naming both) and sorted by their position
along the slice normal n = row cosines x column cosines of Image Orientation Patient, never by
Instance Number.  Image Position Patient is the centre of the first pixel; Pixel Spacing is
[row spacing, column spacing]; Rescale Slope / Intercept are applied.

Voxel (k, r, c) (slice, row, column; the array's axes) sits at
``origin + c * dc * row_cos + r * dr * col_cos + (pos[k] - pos[0]) * n`` in patient
coordinates (LPS, mm): `CTVolume.to_patient` maps fractional indices, the slice index through
the slices' real positions (piecewise linear), so gaps and uneven spacing are handled; they
are warned about.  HU are stored as float32.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..errors import BolusError

__all__ = ["CT_IMAGE", "RT_STRUCT", "CTVolume", "DicomFolder", "scan_folder", "choose_series", "read_ct", "read_folder"]

CT_IMAGE = "1.2.840.10008.5.1.4.1.1.2"
RT_STRUCT = "1.2.840.10008.5.1.4.1.1.481.3"
#: a gap between two slices over this many times the usual spacing is warned as missing slices
GAP_FACTOR = 1.5
#: relative spread of the slice spacing above which it is warned as non-uniform
UNEVEN_REL = 0.01


@dataclass
class DicomFolder:
    """What `scan_folder` found: CT files per series {uid: [path]}, RTSTRUCT paths, files ignored."""
    directory: str
    ct_series: dict = field(default_factory=dict)
    rtstruct: list = field(default_factory=list)
    ignored: int = 0


@dataclass
class CTVolume:
    """One CT series: ``hu`` (k, rows, cols) float32; geometry and the identifiers the export needs."""
    hu: np.ndarray
    origin: np.ndarray        #: (3,) mm, centre of the first pixel of the first (lowest along n) slice
    row_cos: np.ndarray       #: (3,) direction of increasing column index
    col_cos: np.ndarray       #: (3,) direction of increasing row index
    normal: np.ndarray        #: (3,) row_cos x col_cos
    spacing: tuple            #: (row spacing, column spacing) mm
    positions: np.ndarray     #: (k,) slice positions along ``normal`` (mm), increasing
    sop_uids: list            #: (k,) SOP Instance UID of each slice, in the order of ``positions``
    frame_uid: str
    study_uid: str
    series_uid: str
    patient_id: str
    header: object            #: the first slice's dataset without pixel data (Patient, Study modules)
    directory: str = ""
    warnings: list = field(default_factory=list)

    @property
    def slice_spacing(self) -> float:
        """The median distance between neighbouring slices (mm; 1.0 for a single slice)."""
        return float(np.median(np.diff(self.positions))) if len(self.positions) > 1 else 1.0

    def slice_position(self, k) -> np.ndarray:
        """Position along the normal (mm) of fractional slice indices ``k`` (piecewise linear,
        extrapolated past the ends with the neighbouring spacing)."""
        k = np.asarray(k, dtype=np.float64)
        p = self.positions
        if len(p) == 1:
            return p[0] + k * self.slice_spacing
        i = np.clip(np.floor(k).astype(np.int64), 0, len(p) - 2)
        return p[i] + (k - i) * (p[i + 1] - p[i])

    def to_patient(self, krc) -> np.ndarray:
        """(n,3) fractional voxel indices (slice, row, column) -> (n,3) LPS mm."""
        krc = np.asarray(krc, dtype=np.float64)
        d = self.slice_position(krc[:, 0]) - self.positions[0]
        return (self.origin + krc[:, 2:3] * self.spacing[1] * self.row_cos
                + krc[:, 1:2] * self.spacing[0] * self.col_cos + d[:, None] * self.normal)

    def to_slice_frame(self) -> np.ndarray:
        """(4,4) affine LPS mm -> the slice frame (x along rows, y along columns, z = position along n)."""
        R = np.stack([self.row_cos, self.col_cos, self.normal])
        A = np.eye(4)
        A[:3, :3] = R
        A[:3, 3] = -R @ self.origin + np.array([0.0, 0.0, self.positions[0]])
        return A


def _read_header(path: str):
    import pydicom
    from pydicom.errors import InvalidDicomError

    try:
        return pydicom.dcmread(path, stop_before_pixels=True)
    except (InvalidDicomError, OSError, EOFError, ValueError, TypeError, AttributeError, KeyError):
        return None


def scan_folder(directory: str) -> DicomFolder:
    """Classify the files of ``directory`` (not its subfolders); BolusError when it is missing."""
    if not directory or not os.path.isdir(directory):
        raise BolusError(f"'{directory}' is not a folder: choose the folder that holds the CT's DICOM files")
    found = DicomFolder(directory=directory)
    for name in sorted(os.listdir(directory)):
        path = os.path.join(directory, name)
        if not os.path.isfile(path):
            continue
        ds = _read_header(path)
        sop = str(getattr(ds, "SOPClassUID", "")) if ds is not None else ""
        if sop == CT_IMAGE:
            found.ct_series.setdefault(str(getattr(ds, "SeriesInstanceUID", "")), []).append(path)
        elif sop == RT_STRUCT:
            found.rtstruct.append(path)
        else:
            found.ignored += 1
    return found


def _orientation(ds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    iop = np.asarray([float(x) for x in ds.ImageOrientationPatient], dtype=np.float64)
    row, col = iop[:3] / np.linalg.norm(iop[:3]), iop[3:] / np.linalg.norm(iop[3:])
    n = np.cross(row, col)
    return row, col, n / np.linalg.norm(n)


def choose_series(found: DicomFolder, warnings: list) -> tuple[str, list]:
    if not found.ct_series:
        extra = f" ({found.ignored} other file(s) ignored)" if found.ignored else ""
        raise BolusError(f"no CT images (CT Image Storage) in '{found.directory}'{extra}: choose the folder of "
                         "the planning CT's slices")
    ranked = sorted(found.ct_series.items(), key=lambda kv: (-len(kv[1]), kv[0]))
    if len(ranked) > 1:
        others = ", ".join(f"{uid} ({len(p)} slices)" for uid, p in ranked[1:])
        warnings.append(f"the folder holds {len(ranked)} CT series: took {ranked[0][0]} ({len(ranked[0][1])} "
                        f"slices), left out {others}")
    return ranked[0]


def _pixels(ds, path: str) -> np.ndarray:
    try:
        arr = ds.pixel_array
    except Exception as exc:  # pydicom raises several types for missing decoders
        ts = getattr(getattr(ds, "file_meta", None), "TransferSyntaxUID", None)
        name = getattr(ts, "name", str(ts))
        raise BolusError(f"'{os.path.basename(path)}' is compressed ({name}) and cannot be decoded here "
                         f"({type(exc).__name__}): export the CT uncompressed (Explicit VR Little Endian) "
                         "from the planning system") from None
    slope = float(getattr(ds, "RescaleSlope", 1.0) or 1.0)
    icpt = float(getattr(ds, "RescaleIntercept", 0.0) or 0.0)
    out = arr.astype(np.float32)
    if slope != 1.0:
        out *= np.float32(slope)
    if icpt != 0.0:
        out += np.float32(icpt)
    return out


def _permute(a: np.ndarray, order: np.ndarray) -> None:
    """a[i] = a[order[i]] for all i, in place (one slice of extra memory)."""
    done = np.zeros(len(order), dtype=bool)
    for s in range(len(order)):
        if done[s]:
            continue
        tmp, i = a[s].copy(), s
        while True:
            done[i] = True
            j = int(order[i])
            if j == s:
                a[i] = tmp
                break
            a[i] = a[j]
            i = j


def _spacing_warnings(pos: np.ndarray, warnings: list) -> None:
    if len(pos) < 2:
        return
    d = np.diff(pos)
    if np.any(d < 1e-6):
        raise BolusError("two CT slices lie at the same position: the series holds duplicates; export one "
                         "series of distinct slices")
    med = float(np.median(d))
    gaps = np.flatnonzero(d > GAP_FACTOR * med)
    if len(gaps):
        warnings.append(f"{len(gaps)} gap(s) between CT slices wider than {GAP_FACTOR} x the spacing "
                        f"({med:.3g} mm), the widest {d.max():.3g} mm: slices may be missing; the surface "
                        "spans the gaps with straight lines")
    elif d.max() - d.min() > UNEVEN_REL * med:
        warnings.append(f"the CT slice spacing is not uniform ({d.min():.3g} to {d.max():.3g} mm): each "
                        "slice is used at its own position")


def read_ct(paths: list, directory: str = "", warnings: list | None = None, progress=None,
            pixels: bool = True) -> CTVolume:
    """The CT volume of one series' files, sorted along the slice normal (``pixels=False``: the
    geometry and identifiers only, ``hu`` empty (0, rows, cols))."""
    import pydicom

    warnings = [] if warnings is None else warnings
    first = pydicom.dcmread(paths[0], stop_before_pixels=True)
    try:
        row, col, n = _orientation(first)
        spacing = tuple(float(x) for x in first.PixelSpacing)
        rows, cols = int(first.Rows), int(first.Columns)
    except (AttributeError, ValueError, TypeError):
        raise BolusError("the CT slices lack Image Orientation Patient, Pixel Spacing or their size: "
                         "not a planning CT") from None
    if abs(np.dot(row, col)) > 1e-3:
        raise BolusError("the CT's row and column directions are not perpendicular (Image Orientation Patient)")
    if abs(abs(n[2]) - 1.0) > 1e-4:
        warnings.append("the CT is oblique (its slices are not axial): it is read in its own orientation")
    hu = np.empty((len(paths) if pixels else 0, rows, cols), dtype=np.float32)
    pos, sops, ipps = np.empty(len(paths)), [], np.empty((len(paths), 3))
    for i, path in enumerate(paths):
        ds = pydicom.dcmread(path, stop_before_pixels=not pixels)
        if (int(ds.Rows), int(ds.Columns)) != (rows, cols):
            raise BolusError("the CT slices differ in size: not one series")
        ipps[i] = [float(x) for x in ds.ImagePositionPatient]
        pos[i] = float(ipps[i] @ n)
        sops.append(str(ds.SOPInstanceUID))
        if pixels:
            hu[i] = _pixels(ds, path)
        if progress is not None and i % 16 == 0:
            progress(0.9 * (i + 1) / len(paths), "reading the CT slices")
    order = np.argsort(pos, kind="stable")
    if pixels:
        _permute(hu, order)
    pos, ipps, sops = pos[order], ipps[order], [sops[i] for i in order]
    _spacing_warnings(pos, warnings)
    header = pydicom.dcmread(paths[int(order[0])], stop_before_pixels=True)
    return CTVolume(hu=hu, origin=ipps[0], row_cos=row, col_cos=col, normal=n, spacing=spacing, positions=pos,
                    sop_uids=sops, frame_uid=str(getattr(first, "FrameOfReferenceUID", "")),
                    study_uid=str(getattr(first, "StudyInstanceUID", "")),
                    series_uid=str(getattr(first, "SeriesInstanceUID", "")),
                    patient_id=str(getattr(first, "PatientID", "")), header=header, directory=directory,
                    warnings=warnings)


def read_folder(directory: str, progress=None, pixels: bool = True) -> tuple[CTVolume, DicomFolder]:
    """The folder's CT (`read_ct` of the larger series) and what `scan_folder` found; the
    warnings (ignored files, series left out, gaps) are in the volume's ``warnings``."""
    found = scan_folder(directory)
    warnings = []
    if found.ignored:
        warnings.append(f"{found.ignored} file(s) in the folder are neither CT images nor structure sets: ignored")
    _, paths = choose_series(found, warnings)
    return read_ct(paths, directory, warnings, progress, pixels), found
