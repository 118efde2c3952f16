"""Writing files whole or not at all."""

import os
import tempfile

from .errors import BolusError

__all__ = ["write_atomic"]

# Read once, at import (in the main thread): os.umask can only be read by setting it.
_UMASK = os.umask(0o022)
os.umask(_UMASK)


def write_atomic(path: str, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder and os.replace:
    either the whole file is there or nothing changed; BolusError naming the path otherwise.
    The file gets the permissions an ordinary ``open(path, "w")`` would give (0o666 less the
    umask), not mkstemp's private 0o600: a pattern is shared with the workshop."""
    folder = os.path.dirname(os.path.abspath(path))
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp", dir=folder)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        if os.name == "posix":
            os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, path)
        tmp = None
    except OSError as exc:
        raise BolusError(f"could not write '{path}': {exc.strerror or exc}") from None
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
