"""An RTSTRUCT for closed solids on a CT: the exact sections at its slices, one ROI per solid.

Modules written: Patient and General Study copied from the CT's first slice (same Study
Instance UID), RT Series (Modality RTSTRUCT, a new Series Instance UID), Frame of Reference,
Structure Set (Referenced Frame of Reference Sequence -> RT Referenced Study -> RT Referenced
Series -> Contour Image Sequence of every CT slice), Structure Set ROI, ROI Contour (each
contour CLOSED_PLANAR on its slice's plane, referencing that slice's SOP Instance UID), RT ROI
Observations (Interpreted Type BOLUS; ROI Physical Properties REL_ELEC_DENSITY when a density
is given), Approval (UNAPPROVED) and SOP Common.  New UIDs are ``2.25.`` + a random UUID's
integer.  ``existing``: another structure set on the same frame whose ROIs are carried over
(their numbers kept, the new ROIs numbered after them).  The file is written whole or not at
all (`core.files.write_atomic`).
"""
from __future__ import annotations

import datetime
import io
import uuid

import numpy as np

from ..errors import BolusError
from ..files import write_atomic
from .series import CT_IMAGE, RT_STRUCT, CTVolume
from .sections import decimal_strings, slice_sections

__all__ = ["new_uid", "write_rtstruct", "build_rtstruct", "PATIENT_STUDY_TAGS"]

#: the Patient and General Study modules' attributes copied from the CT
PATIENT_STUDY_TAGS = ("PatientName", "PatientID", "PatientBirthDate", "PatientSex", "PatientAge",
                      "StudyInstanceUID", "StudyDate", "StudyTime", "StudyID", "AccessionNumber",
                      "ReferringPhysicianName", "StudyDescription")
#: ROI colours (RGB) of the new ROIs, in turn
COLOURS = ([0, 200, 255], [255, 160, 0], [160, 255, 0], [255, 0, 200])


def new_uid() -> str:
    """A new UID: ``2.25.`` + the integer of a random UUID (ISO/IEC 9834-8)."""
    return "2.25." + str(uuid.uuid4().int)


def _item(**kw):
    from pydicom.dataset import Dataset

    ds = Dataset()
    for k, v in kw.items():
        setattr(ds, k, v)
    return ds


def _referenced_frame(vol: CTVolume):
    images = [_item(ReferencedSOPClassUID=CT_IMAGE, ReferencedSOPInstanceUID=s) for s in vol.sop_uids]
    series = _item(SeriesInstanceUID=vol.series_uid, ContourImageSequence=images)
    study = _item(ReferencedSOPClassUID="1.2.840.10008.3.1.2.3.1",  # Detached Study Management (retired, as used)
                  ReferencedSOPInstanceUID=vol.study_uid, RTReferencedSeriesSequence=[series])
    return _item(FrameOfReferenceUID=vol.frame_uid, RTReferencedStudySequence=[study])


def _roi_contour(vol: CTVolume, number: int, sections: list, colour) -> object:
    contours = []
    for k, polys in enumerate(sections):
        for P in polys:
            ref = _item(ReferencedSOPClassUID=CT_IMAGE, ReferencedSOPInstanceUID=vol.sop_uids[k])
            contours.append(_item(ContourImageSequence=[ref], ContourGeometricType="CLOSED_PLANAR",
                                  NumberOfContourPoints=len(P), ContourNumber=len(contours) + 1,
                                  ContourData=decimal_strings(P)))
    return _item(ROIDisplayColor=list(colour), ReferencedROINumber=number, ContourSequence=contours)


def _observation(number: int, obs: int, name: str, density: float):
    o = _item(ObservationNumber=obs, ReferencedROINumber=number, ROIObservationLabel=name[:16],
              RTROIInterpretedType="BOLUS", ROIInterpreter="")
    if density > 0:
        o.ROIPhysicalPropertiesSequence = [_item(ROIPhysicalProperty="REL_ELEC_DENSITY",
                                                 ROIPhysicalPropertyValue=decimal_strings([density])[0])]
    return o


def _base(vol: CTVolume, now: datetime.datetime):
    from pydicom.dataset import FileMetaDataset, Dataset
    from pydicom.uid import ExplicitVRLittleEndian

    sop = new_uid()
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID, meta.MediaStorageSOPInstanceUID = RT_STRUCT, sop
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    for tag in PATIENT_STUDY_TAGS:
        if tag in vol.header:
            setattr(ds, tag, vol.header[tag].value)
    ds.PatientID = vol.patient_id
    ds.StudyInstanceUID = vol.study_uid
    date, time = now.strftime("%Y%m%d"), now.strftime("%H%M%S")
    ds.SOPClassUID, ds.SOPInstanceUID, ds.SpecificCharacterSet = RT_STRUCT, sop, "ISO_IR 192"
    ds.InstanceCreationDate, ds.InstanceCreationTime = date, time
    ds.Modality, ds.SeriesInstanceUID, ds.SeriesNumber = "RTSTRUCT", new_uid(), 901
    ds.SeriesDescription, ds.Manufacturer, ds.OperatorsName = "Bolus", "Bolus add-on", ""
    ds.FrameOfReferenceUID, ds.PositionReferenceIndicator = vol.frame_uid, ""
    ds.StructureSetLabel, ds.StructureSetName = "Bolus", "Bolus"
    ds.StructureSetDate, ds.StructureSetTime, ds.InstanceNumber = date, time, 1
    ds.ApprovalStatus = "UNAPPROVED"
    return ds


def build_rtstruct(vol: CTVolume, solids: list, rel_electron_density: float = 0.0, existing=None,
                   progress=None):
    """The RTSTRUCT dataset of ``solids`` [(name, V (n,3) LPS mm, F (m,3))] on ``vol``;
    ``existing``: a pydicom structure set of the same frame whose ROIs are carried over."""
    if not solids:
        raise BolusError("no solid to export")
    if rel_electron_density < 0 or not np.isfinite(rel_electron_density):
        raise BolusError("the relative electron density must be a positive number (0: none)")
    ds = _base(vol, datetime.datetime.now())
    ds.ReferencedFrameOfReferenceSequence = [_referenced_frame(vol)]
    rois, contours, observations = [], [], []
    if existing is not None:
        rois = list(getattr(existing, "StructureSetROISequence", []))
        contours = list(getattr(existing, "ROIContourSequence", []))
        observations = list(getattr(existing, "RTROIObservationsSequence", []))
    number = max([int(r.ROINumber) for r in rois], default=0)
    obs = max([int(o.ObservationNumber) for o in observations], default=0)
    for i, (name, V, F) in enumerate(solids):
        sections = slice_sections(vol, V, F, f"'{name}'",
                                  None if progress is None else
                                  (lambda f, t, i=i: progress((i + f) / len(solids), t)))
        if not any(sections):
            raise BolusError(f"'{name}' lies outside the CT's slices ({vol.positions[0]:.1f} to "
                             f"{vol.positions[-1]:.1f} mm along the slice normal): it has no section to export")
        number, obs = number + 1, obs + 1
        rois.append(_item(ROINumber=number, ReferencedFrameOfReferenceUID=vol.frame_uid, ROIName=name[:64],
                          ROIGenerationAlgorithm="SEMIAUTOMATIC"))
        contours.append(_roi_contour(vol, number, sections, COLOURS[i % len(COLOURS)]))
        observations.append(_observation(number, obs, name, rel_electron_density))
    ds.StructureSetROISequence, ds.ROIContourSequence = rois, contours
    ds.RTROIObservationsSequence = observations
    return ds


def write_rtstruct(path: str, vol: CTVolume, solids: list, rel_electron_density: float = 0.0,
                   existing=None, progress=None) -> dict:
    """Build (`build_rtstruct`) and write the RTSTRUCT to ``path`` (atomically); returns
    {"rois": new ROI names, "contours": contours written, "sop_uid", "series_uid"}."""
    ds = build_rtstruct(vol, solids, rel_electron_density, existing, progress)
    buf = io.BytesIO()
    ds.save_as(buf, enforce_file_format=True)
    write_atomic(path, buf.getvalue())
    n_new = len(solids)
    new = ds.ROIContourSequence[-n_new:]
    return {"rois": [str(r.ROIName) for r in ds.StructureSetROISequence[-n_new:]],
            "contours": int(sum(len(getattr(c, "ContourSequence", [])) for c in new)),
            "sop_uid": str(ds.SOPInstanceUID), "series_uid": str(ds.SeriesInstanceUID)}
