"""The planning CT in, the bolus back: DICOM CT series and RTSTRUCT (pydicom, bpy-free)."""
