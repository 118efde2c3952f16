"""Bolus add-on: flattenability, segmentation and unfolding of skin surfaces for bolus.

The algorithms live in the bpy-free `bolus_addon.core`; this package's other modules are
the Blender layer.  Nothing Blender-specific is imported at module level, so
``import bolus_addon.core`` works in plain Python.
"""

_classes = ()


def register():
    import bpy

    from . import panel
    from .blender import properties
    from .operators import analysis, area, cuts, dicom, improve, pattern, printing, retrieval, solid, unfold

    global _classes
    _classes = (properties.BolusSettings, *dicom.classes, *area.classes, *analysis.classes, *cuts.classes, *improve.classes,
                *unfold.classes, *pattern.classes, *printing.classes, *solid.classes, *retrieval.classes,
                *panel.classes)
    for cls in _classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.bolus = bpy.props.PointerProperty(type=properties.BolusSettings)


def unregister():
    import bpy

    global _classes
    if hasattr(bpy.types.Scene, "bolus"):
        del bpy.types.Scene.bolus
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
    _classes = ()
