"""Bolus add-on: flattenability, segmentation and unfolding of skin surfaces for bolus.

The algorithms live in the bpy-free `bolus_addon.core`; this package's other modules are
the Blender layer.  Nothing Blender-specific is imported at module level, so
``import bolus_addon.core`` works in plain Python.
"""

_classes = ()


def register():
    import bpy

    from . import analysis_ops, area_ops, cut_ops, improve_ops, operators, panel, pattern_export_ops, pattern_ops, print_ops, properties, retrieval_ops, shell_ops

    global _classes
    _classes = (properties.BolusSettings, *operators.classes, *area_ops.classes, *analysis_ops.classes, *cut_ops.classes, *improve_ops.classes, *pattern_ops.classes, *pattern_export_ops.classes, *print_ops.classes, *shell_ops.classes, *retrieval_ops.classes, *panel.classes)
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
