"""The two jobs the operators run: the skin from a folder, the bolus back as an RTSTRUCT.

`import_skin` reads the folder's CT series and structure sets and makes the skin from the
External ROI's contours (``source='RTSTRUCT'``, or the ROI ``roi_name``) or from the CT
(``'CT'``, `skin.skin_from_ct`); ``'AUTO'`` takes the External ROI when a structure set of
the CT's frame has one.  `export_rtstruct` writes solids onto the CT of a folder
(`rtstruct_write`), carrying over the folder's own structure set when asked.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import BolusError
from .rtstruct import contours_surface, find_roi, read_structure_set, roi_contours
from .rtstruct_write import write_rtstruct
from .series import read_ct, read_folder, scan_folder, choose_series
from .skin import skin_from_ct

__all__ = ["SOURCES", "ImportedSkin", "import_skin", "export_rtstruct", "coverage_warnings", "ct_summary"]

SOURCES = ("AUTO", "CT", "RTSTRUCT")


@dataclass
class ImportedSkin:
    V: np.ndarray
    F: np.ndarray
    source: str            #: "CT" or "RTSTRUCT"
    roi_name: str          #: the ROI read ("" from the CT)
    frame_uid: str
    study_uid: str
    series_uid: str
    patient_id: str
    directory: str
    summary: str           #: the INFO line: patient, series, slices, spacing
    warnings: list = field(default_factory=list)


def ct_summary(vol) -> str:
    """"patient P, CT series S: 111 slices, 0.98 x 0.98 x 2.5 mm"."""
    return (f"patient {vol.patient_id or '(no ID)'}, CT series {vol.series_uid}: {len(vol.positions)} slices, "
            f"{vol.spacing[1]:.3g} x {vol.spacing[0]:.3g} x {vol.slice_spacing:.3g} mm")


def _structure_sets(paths: list, frame_uid: str, warnings: list, strict: bool) -> list:
    """The folder's structure sets on the CT's frame; one on another frame is an error when
    ``strict`` (its ROI was asked for), else warned and left out."""
    out = []
    for p in paths:
        ss = read_structure_set(p)
        if ss.frame_uids and frame_uid not in ss.frame_uids:
            msg = (f"the structure set '{p}' is on another frame of reference ({', '.join(sorted(ss.frame_uids))}) "
                   f"than the CT ({frame_uid})")
            if strict:
                raise BolusError(msg + ": export the structure set made on this CT")
            warnings.append(msg + ": left out")
            continue
        out.append(ss)
    return out


def import_skin(directory: str, source: str = "AUTO", threshold_hu: float = -350.0, roi_name: str = "",
                progress=None) -> ImportedSkin:
    """The skin of the folder's patient (V (n,3) LPS mm, F (m,3), outward) and where it came from."""
    source = str(source).upper()
    if source not in SOURCES:
        raise BolusError(f"source must be one of {', '.join(SOURCES)}, not '{source}'")
    if not np.isfinite(threshold_hu):
        raise BolusError("the HU threshold must be a number")
    found = scan_folder(directory)
    warnings = [f"{found.ignored} file(s) in the folder are neither CT images nor structure sets: ignored"] \
        if found.ignored else []
    _, paths = choose_series(found, warnings)
    want_rt = source == "RTSTRUCT" or (source == "AUTO" and (found.rtstruct or roi_name))
    if source == "RTSTRUCT" and not found.rtstruct:
        raise BolusError(f"no structure set (RTSTRUCT) in '{directory}': import the skin from the CT instead")
    reading = _part(progress, 0.0, 0.4)
    vol = read_ct(paths, directory, warnings, reading if not want_rt else None, pixels=not want_rt)
    chosen = None
    if want_rt:
        for ss in _structure_sets(found.rtstruct, vol.frame_uid, warnings, strict=True):
            roi = find_roi(ss, roi_name)
            if roi is not None:
                chosen = (ss, roi)
                break
        if chosen is None and source == "RTSTRUCT":
            raise BolusError("the structure set has no External ROI (Interpreted Type EXTERNAL or a name like "
                             "BODY): give its name (ROI name) or import the skin from the CT")
    if chosen is not None:
        ss, roi = chosen
        V, F = contours_surface(vol, roi_contours(ss, roi.number), f"the ROI '{roi.name}'")
        src, name = "RTSTRUCT", roi.name
    else:
        if want_rt:  # AUTO without an External ROI: the CT after all
            vol = read_ct(paths, directory, [], reading, pixels=True)
        V, F = skin_from_ct(vol, threshold_hu, _part(progress, 0.4, 1.0))
        src, name = "CT", ""
    return ImportedSkin(V=V, F=F, source=src, roi_name=name, frame_uid=vol.frame_uid, study_uid=vol.study_uid,
                        series_uid=vol.series_uid, patient_id=vol.patient_id, directory=directory,
                        summary=ct_summary(vol), warnings=warnings)


def export_rtstruct(path: str, ct_directory: str, solids: list, rel_electron_density: float = 0.0,
                    include_existing: bool = True, frame_uid: str = "", progress=None) -> dict:
    """Write the RTSTRUCT of ``solids`` [(name, V (n,3) LPS mm, F (m,3))] on the CT of
    ``ct_directory`` to ``path``; ``frame_uid``: the solids' frame (checked against the CT's).
    Returns `write_rtstruct`'s summary plus "existing" (ROIs carried over) and "warnings"."""
    vol, found = read_folder(ct_directory, pixels=False)
    warnings = list(vol.warnings)
    if frame_uid and frame_uid != vol.frame_uid:
        raise BolusError(f"the solid's frame of reference ({frame_uid}) is not the CT's ({vol.frame_uid}) in "
                         f"'{ct_directory}': choose the CT folder its skin was imported from")
    existing, carried = None, []
    if include_existing:
        sets = _structure_sets(found.rtstruct, vol.frame_uid, warnings, strict=False)
        if sets:
            existing = _without(sets[0].ds, {name for name, _, _ in solids})
            carried = [str(r.ROIName) for r in getattr(existing, "StructureSetROISequence", [])]
    for name, V, _ in solids:
        warnings += coverage_warnings(vol, name, V)
    out = write_rtstruct(path, vol, solids, rel_electron_density, existing, progress)
    out.update(existing=carried, warnings=warnings, summary=ct_summary(vol))
    return out


def coverage_warnings(vol, name: str, V) -> list:
    """What of the solid V (n,3) LPS mm lies beyond the CT (the slices' range along the normal,
    half a spacing past the end slices, or the image's rows and columns): the structure stops
    there and the planning system computes no dose with that part; one message per side, in mm."""
    A = vol.to_slice_frame()
    P = np.asarray(V, dtype=np.float64) @ A[:3, :3].T + A[:3, 3]
    rows, cols = vol.hu.shape[1:]
    dr, dc = vol.spacing
    half = 0.5 * vol.slice_spacing
    box = [("along the slice normal", 2, vol.positions[0] - half, vol.positions[-1] + half),
           ("across the rows", 0, -0.5 * dc, (cols - 0.5) * dc), ("along the columns", 1, -0.5 * dr, (rows - 0.5) * dr)]
    out = []
    for what, ax, lo, hi in box:
        beyond = max(lo - float(P[:, ax].min()), float(P[:, ax].max()) - hi)
        if beyond > 0.01:
            out.append(f"'{name}' reaches {beyond:.1f} mm beyond the CT {what}: its structure stops at the CT's edge "
                       f"and that part gets no dose calculation; extend the CT or trim the bolus")
    return out


def _part(progress, lo: float, hi: float):
    """``progress`` for a part of the job: its fractions 0..1 mapped to lo..hi (None stays None)."""
    if progress is None:
        return None
    return lambda f, text="": progress(lo + (hi - lo) * float(f), text)


def _without(ds, names: set):
    """The structure set ``ds`` less the ROIs named in ``names`` (an earlier export of the same bolus)."""
    drop = {int(r.ROINumber) for r in getattr(ds, "StructureSetROISequence", []) if str(r.ROIName) in names}
    if drop:
        ds.StructureSetROISequence = [r for r in ds.StructureSetROISequence if int(r.ROINumber) not in drop]
        for seq in ("ROIContourSequence", "RTROIObservationsSequence"):
            if seq in ds:
                setattr(ds, seq, [x for x in getattr(ds, seq) if int(x.ReferencedROINumber) not in drop])
    return ds
