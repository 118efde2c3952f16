"""STL reader (binary and ASCII) for the bolus library and scripts (no Blender needed).

`load_stl(path)` returns ``V`` (n,3) float64 and ``F`` (m,3) int64: an STL file is a triangle
soup, so corners with equal coordinates are merged into one vertex (as a slicer does) and
triangles that collapse by that merge are dropped.  Binary files are recognised by their size
(84 + 50 x the announced count bytes), so an ASCII file that starts with "solid" and a binary
one whose header happens to start with "solid" are both read right.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import BolusError

__all__ = ["load_stl"]

_RECORD = np.dtype([("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])


def _binary(data: bytes, name: str) -> np.ndarray | None:
    if len(data) < 84:
        return None
    count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
    if len(data) != 84 + 50 * count:
        return None
    return np.frombuffer(data, dtype=_RECORD, count=count, offset=84)["v"].astype(np.float64)


def _ascii(data: bytes, name: str) -> np.ndarray:
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError:
        raise BolusError(f"{name} is neither a binary STL (its size does not match its triangle count) nor an "
                         "ASCII one") from None
    if not text.lstrip().lower().startswith("solid"):
        raise BolusError(f"{name} is not an STL file (no 'solid' at the start of an ASCII file, and the size of a "
                         "binary one does not match)")
    rows = []
    for lineno, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if parts and parts[0].lower() == "vertex":
            try:
                rows.append([float(x) for x in parts[1:4]])
            except ValueError:
                raise BolusError(f"{name} line {lineno}: a vertex needs three numbers, got {line.strip()!r}") from None
            if len(parts) < 4:
                raise BolusError(f"{name} line {lineno}: a vertex needs three numbers, got {line.strip()!r}")
    if len(rows) % 3:
        raise BolusError(f"{name}: {len(rows)} vertices is not a whole number of triangles")
    return np.asarray(rows, dtype=np.float64).reshape(-1, 3, 3)


def load_stl(path, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Read a binary or ASCII STL; ``scale`` multiplies the coordinates -> (V (n,3), F (m,3)).

    Refuses (BolusError) a missing or unreadable file, one with no triangles and non-finite
    coordinates, naming the file."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise BolusError(f"cannot read {path}: {exc.strerror or exc}") from None
    P = _binary(data, path.name)
    if P is None:
        P = _ascii(data, path.name)
    if len(P) == 0:
        raise BolusError(f"{path.name} holds no triangles")
    if not np.isfinite(P).all():
        raise BolusError(f"{path.name} has a NaN or infinite coordinate")
    V, inv = np.unique(P.reshape(-1, 3), axis=0, return_inverse=True)
    F = inv.reshape(-1, 3)
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    if len(F) == 0:
        raise BolusError(f"{path.name}: every triangle collapses to a line or a point")
    used, F = np.unique(F, return_inverse=True)
    return V[used] * float(scale), F.reshape(-1, 3).astype(np.int64)
