"""Extension entry point: Blender imports this file when the extension is enabled.

No Blender import at module level; the add-on itself is the `bolus_addon` package.
"""


def register():
    from .bolus_addon import register as _register

    _register()


def unregister():
    from .bolus_addon import unregister as _unregister

    _unregister()
