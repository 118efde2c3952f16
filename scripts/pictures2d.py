"""Pictures drawn with numpy alone (no renderer): the PNG writer of the README pictures and the
cross-section through a bolus on the skin (`section_png`), used by scripts/demo.py and
scripts/readme_pictures.py.

The cross-section is exact: the triangles of the skin and of the bolus are cut by the plane,
the bolus's section (closed loops) is filled with the even-odd rule, the skin's section is drawn
as a line on top, so any air gap between the bolus's inner face and the skin shows as a white
sliver at true scale (a 10 mm bar is drawn for scale).
"""
from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

#: low bits dropped per 8-bit channel before compressing (64 levels are plenty for these renders)
QUANTIZE_BITS = 2
BOLUS_RGB = (70, 130, 220)
SKIN_RGB = (20, 20, 20)
SKIN_LINE_PX = 2.0


def write_png(path: Path, rgb: np.ndarray) -> None:
    """Write (h, w, 3) uint8 rows (top row first) as an 8-bit RGB PNG, zlib level 9.

    The two lowest bits of every channel are dropped (64 levels: no visible banding on
    Workbench shading, half the bytes) and the smallest of the PNG filters None, Sub and Up
    is used for the whole image."""
    h, w, _ = rgb.shape
    q = ((rgb >> QUANTIZE_BITS) << QUANTIZE_BITS).astype(np.int16)
    candidates = []
    for code, rows in ((0, q), (1, np.diff(q, axis=1, prepend=np.zeros((h, 1, 3), np.int16))),
                       (2, np.diff(q, axis=0, prepend=np.zeros((1, w, 3), np.int16)))):
        raw = np.concatenate([np.full((h, 1), code, np.uint8), (rows % 256).astype(np.uint8).reshape(h, -1)], axis=1)
        candidates.append(zlib.compress(raw.tobytes(), 9))
    data = min(candidates, key=len)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", data) + chunk(b"IEND", b""))


def plane_segments(V: np.ndarray, F: np.ndarray, origin: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(k, 2, 3) segments where the triangles (V (n,3), F (m,3)) cross the plane through `origin`
    with unit `normal` (vertices exactly on the plane are nudged to its positive side)."""
    d = (V - origin) @ normal
    d = np.where(np.abs(d) < 1e-9, 1e-9, d)
    s = d[F] > 0
    cross = F[s.any(axis=1) & ~s.all(axis=1)]
    if not len(cross):
        return np.zeros((0, 2, 3))
    dc = d[cross]
    sc = dc > 0
    lone = np.where(sc.sum(axis=1) == 1, np.argmax(sc, axis=1), np.argmin(sc, axis=1))  # the vertex alone on its side
    rows = np.arange(len(cross))
    a = cross[rows, lone]
    ends = []
    for k in (1, 2):
        b = cross[rows, (lone + k) % 3]
        t = d[a] / (d[a] - d[b])
        ends.append(V[a] + t[:, None] * (V[b] - V[a]))
    return np.stack(ends, axis=1)


def section_png(path: Path, skin: tuple[np.ndarray, np.ndarray], bolus: tuple[np.ndarray, np.ndarray],
                origin, normal, up, px_per_mm: float = 8.0, margin_mm: float = 6.0,
                size_px: tuple[int, int] | None = None) -> dict:
    """Draw the section of `bolus` (closed solid, filled) and `skin` (a line) by a plane.

    skin, bolus: (V (n,3), F (m,3)) in mm; origin, normal: the plane; up: the picture's vertical
    (projected onto the plane); size_px: (width, height) to fit the section into (centred, the
    scale chosen to fit; px_per_mm is then ignored).
    Returns {"width_px", "height_px", "px_per_mm", "bolus_segments", "skin_segments"}."""
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    up = np.asarray(up, float) - np.dot(up, normal) * normal
    up /= np.linalg.norm(up)
    right = np.cross(up, normal)
    origin = np.asarray(origin, float)
    segs_b = plane_segments(*bolus, origin, normal)
    segs_s = plane_segments(*skin, origin, normal)
    if not len(segs_b):
        raise ValueError("the plane does not cut the bolus")

    def to2d(P):
        Q = P - origin
        return np.stack([Q @ right, Q @ up], axis=-1)

    b2, s2 = to2d(segs_b), to2d(segs_s)
    lo = b2.reshape(-1, 2).min(axis=0) - margin_mm
    hi = b2.reshape(-1, 2).max(axis=0) + margin_mm
    if size_px is not None:
        px_per_mm = float(min((size_px[0] - 1) / (hi[0] - lo[0]), (size_px[1] - 1) / (hi[1] - lo[1])))
        pad = (np.array(size_px, float) - 1) / px_per_mm - (hi - lo)
        lo, hi = lo - pad / 2, hi + pad / 2
        w, h = size_px
    else:
        w, h = (np.ceil((hi - lo) * px_per_mm)).astype(int) + 1
    img = np.full((h, w, 3), 255, np.uint8)

    def px(P):  # (x, y) mm -> (column, row), row 0 at the top
        return np.stack([(P[..., 0] - lo[0]) * px_per_mm, (hi[1] - P[..., 1]) * px_per_mm], axis=-1)

    pb = px(b2)
    # even-odd fill, row by row: crossings of each pixel row's centre line with the segments
    y0, y1 = pb[:, 0, 1], pb[:, 1, 1]
    x0, x1 = pb[:, 0, 0], pb[:, 1, 0]
    for r in range(h):
        yc = r + 0.5
        hit = (np.minimum(y0, y1) <= yc) & (np.maximum(y0, y1) > yc)
        if not hit.any():
            continue
        t = (yc - y0[hit]) / (y1[hit] - y0[hit])
        xs = np.sort(x0[hit] + t * (x1[hit] - x0[hit]))
        for a, b in zip(xs[0::2], xs[1::2]):
            img[r, max(int(np.ceil(a - 0.5)), 0):max(min(int(np.floor(b - 0.5)) + 1, w), 0)] = BOLUS_RGB
    # the skin's line on top: points every 0.25 px along each segment, stamped as discs
    ps = px(s2)
    if len(ps):
        n = np.maximum(np.ceil(np.linalg.norm(ps[:, 1] - ps[:, 0], axis=1) * 4).astype(int), 1)
        t = np.concatenate([np.linspace(0, 1, k + 1) for k in n])
        seg = np.repeat(np.arange(len(ps)), n + 1)
        pts = ps[seg, 0] + t[:, None] * (ps[seg, 1] - ps[seg, 0])
        rr = int(np.ceil(SKIN_LINE_PX))
        for dx in range(-rr, rr + 1):
            for dy in range(-rr, rr + 1):
                if dx * dx + dy * dy > SKIN_LINE_PX ** 2:
                    continue
                c = np.round(pts[:, 0] + dx).astype(int)
                r = np.round(pts[:, 1] + dy).astype(int)
                ok = (c >= 0) & (c < w) & (r >= 0) & (r < h)
                img[r[ok], c[ok]] = SKIN_RGB
    # a 10 mm scale bar at the bottom left
    bar = int(round(10 * px_per_mm))
    r0 = h - int(2 * px_per_mm)
    img[max(r0 - 3, 0):r0, int(px_per_mm):int(px_per_mm) + bar] = SKIN_RGB
    write_png(Path(path), img)
    return {"width_px": int(w), "height_px": int(h), "px_per_mm": px_per_mm, "bolus_segments": int(len(segs_b)),
            "skin_segments": int(len(segs_s))}
