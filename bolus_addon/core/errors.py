"""The one user-facing error type of the add-on.

`BolusError` subclasses `ValueError`, so the core keeps the gpytoolbox/libigl
convention (bad arrays -> `ValueError` at the boundary) while the Blender layer can
catch exactly this type and turn it into `self.report({'ERROR'}, ...)`.  Its message
is written for the modeler: what is wrong and what to do about it.
"""


class BolusError(ValueError):
    """Bad input or a result that cannot be produced; the message is shown to the user."""
