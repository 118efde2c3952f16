"""The shell field on the marching-cubes lattice, exact on the corners of every cube the surface
crosses and guessed elsewhere, level by level from a coarse lattice.

Levels: the fine lattice (spacing sp), and coarser ones of spacing 2 sp, 4 sp, ... up to about
a third of the wall (so the coarsest still has three points across it); point m of a level lies
on point 2 m - 2 of the next finer one.  On the coarsest level the field is exact wherever a
triangle centre is within the band (t + 3 spacings + the largest triangle radius), and far
away the bound f <= -3 spacings holds.  Then on every finer level:

    1. guess  g(p) = trilinear interpolation of the coarser level (points on a coarser point
                     copy its value, exact where it was);
    2. exact  f(p) where |g(p)| < one spacing;
    3. close  every cube whose eight corners do not share one sign and has a guessed corner:
              those corners exact; then the 26 neighbours of every point whose exact sign
              differs from its guess, again, until no guessed point is next to a sign change.

A wrong guess survives only inside a region of guessed points that all carry it, away from any
crossing: a feature smaller than a coarse spacing that the coarser levels did not see at all.
Unlike a Lipschitz bound this asks nothing of the rim term (which jumps where border normals
cross), and it evaluates about the two layers of points per face that marching cubes reads.

Arrays: level values flat (C order) float64; the fine lattice is `grid._Grid`'s lattice 0,
returned (nx, ny, nz) (`marching.marching_cubes(pad=True)` closes the surface at its box).
"""
from __future__ import annotations

import numpy as np

from .marching import CUBE_CORNERS

__all__ = ["field_narrow_band", "level_count"]

_NEIGHBOURS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                        if (i, j, k) != (0, 0, 0)], dtype=np.int64)
_CHUNK = 1_000_000  # points per exact evaluation


def level_count(sp: float, wall: float, most: int = 3) -> int:
    """Coarser levels above the fine one: spacing 2^k sp stays within wall / 3 (k <= most)."""
    k = 0
    while k < most and (2.0 ** (k + 1)) * sp <= wall / 3.0:
        k += 1
    return max(k, 1)


class _Level:
    """One lattice: lo (3,), sp (3,) mm, shape; values (flat), which are exact, the count
    evaluated, and the exact evaluation of flat indices."""

    def __init__(self, skin, lo, sp, shape, field_args):
        self.skin, self.args = skin, field_args
        self.lo, self.sp = np.asarray(lo, dtype=np.float64), np.asarray(sp, dtype=np.float64)
        self.shape = tuple(int(x) for x in shape)
        self.h = float(self.sp.max())
        self.vals = np.empty(int(np.prod(self.shape)))
        self.exact = np.zeros(len(self.vals), dtype=bool)
        self.evaluated = 0

    def coarser(self) -> "_Level":
        """The next coarser level, empty: its point m on this level's point 2 m - 2."""
        return _Level(self.skin, self.lo - 2.0 * self.sp, 2.0 * self.sp,
                      tuple((n + 1) // 2 + 3 for n in self.shape), self.args)

    def points(self, idx) -> np.ndarray:
        """(k,3) mm of flat indices idx."""
        ijk = np.unravel_index(idx, self.shape)
        return np.stack([self.lo[a] + ijk[a] * self.sp[a] for a in range(3)], axis=1)

    def evaluate(self, idx) -> np.ndarray:
        """Exact field at the flat indices idx not exact yet; returns those whose sign changed."""
        idx = np.unique(idx)
        idx = idx[~self.exact[idx]]
        flipped = []
        for s in range(0, len(idx), _CHUNK):
            part = idx[s:s + _CHUNK]
            f = self.skin.field(self.points(part), *self.args)
            flipped.append(part[(f > 0) != (self.vals[part] > 0)])
            self.vals[part] = f
            self.exact[part] = True
        self.evaluated += len(idx)
        return np.concatenate(flipped) if flipped else idx

    def neighbours(self, idx) -> np.ndarray:
        """Flat indices of the 26 neighbours of the flat indices idx, inside the lattice."""
        ijk = np.stack(np.unravel_index(idx, self.shape), axis=1)
        nb = (ijk[:, None, :] + _NEIGHBOURS[None]).reshape(-1, 3)
        nb = nb[np.all((nb >= 0) & (nb < np.array(self.shape)), axis=1)]
        return np.ravel_multi_index(nb.T, self.shape)

    def guessed_corners_of_crossings(self, chunk: int = 32) -> np.ndarray:
        """Flat indices of the guessed corners of the cubes whose corners differ in sign."""
        nx, ny, nz = self.shape
        v, ex = self.vals.reshape(self.shape), self.exact.reshape(self.shape)
        out = []
        for i0 in range(0, nx - 1, chunk):
            i1 = min(nx - 1, i0 + chunk)
            cnt = np.zeros((i1 - i0, ny - 1, nz - 1), dtype=np.uint8)
            guessed = np.zeros((i1 - i0, ny - 1, nz - 1), dtype=bool)
            for dx, dy, dz in CUBE_CORNERS:
                sl = (slice(i0 + dx, i1 + dx), slice(dy, ny - 1 + dy), slice(dz, nz - 1 + dz))
                cnt += v[sl] > 0
                guessed |= ~ex[sl]
            cube = np.argwhere((cnt > 0) & (cnt < 8) & guessed)
            if len(cube):
                cube[:, 0] += i0
                corner = (cube[:, None, :] + CUBE_CORNERS[None]).reshape(-1, 3)
                out.append(np.ravel_multi_index(corner.T, self.shape))
        return np.unique(np.concatenate(out)) if out else np.zeros(0, dtype=np.int64)


def _guess_slab(fc, i0, i1, shape) -> np.ndarray:
    """Trilinear guesses (i1 - i0, ny, nz) from the coarser level's values fc (3-D): point i
    lies at the coarser coordinate (i + 2) / 2, on a coarser point (even i) or halfway."""
    out = np.zeros((i1 - i0,) + tuple(shape[1:]))
    axes = []
    for lo, hi in ((i0, i1), (0, shape[1]), (0, shape[2])):
        u = (np.arange(lo, hi) + 2.0) / 2.0
        m = np.floor(u).astype(np.int64)
        axes.append((m, u - m))
    (mx, wx), (my, wy), (mz, wz) = axes
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                w = ((wx if dx else 1 - wx)[:, None, None] * (wy if dy else 1 - wy)[None, :, None]
                     * (wz if dz else 1 - wz)[None, None, :])
                out += w * fc[np.ix_(mx + dx, my + dy, mz + dz)]
    return out


def _coarsest(level: _Level, t: float) -> None:
    """The coarsest level: exact within the band of a triangle centre, -3 spacings elsewhere."""
    skin = level.skin
    band = t + 3.0 * level.h + skin.tri_rmax
    level.vals[:] = -3.0 * level.h
    idx = np.arange(len(level.vals))
    for s in range(0, len(idx), _CHUNK):
        part = idx[s:s + _CHUNK]
        d0, _ = skin.cent_tree.query(level.points(part), k=1, distance_upper_bound=band, workers=2)
        level.evaluate(part[np.isfinite(d0)])


def _refine(level: _Level, coarse: _Level) -> None:
    """Steps 1-3 of the module docstring on `level` from the finished `coarse`."""
    shape = level.shape
    vals = level.vals.reshape(shape)
    fc = coarse.vals.reshape(coarse.shape)
    slab = max(1, int(2_000_000 // max(shape[1] * shape[2], 1)))
    for i0 in range(0, shape[0], slab):
        i1 = min(shape[0], i0 + slab)
        vals[i0:i1] = _guess_slab(fc, i0, i1, shape)
    on, sl = _on_coarse(shape)
    level.exact[on] = coarse.exact.reshape(coarse.shape)[sl].ravel()
    level.evaluate(np.nonzero(np.abs(level.vals) < level.h)[0])
    flipped = level.evaluate(level.guessed_corners_of_crossings())
    while len(flipped):
        flipped = level.evaluate(level.neighbours(flipped))


def _on_coarse(shape):
    """(flat indices of a level's points that lie on coarser points (even indices), the coarser
    level's index slices of those points, in the same order)."""
    ii, jj, kk = (np.arange(0, n, 2) for n in shape)
    flat = ((ii[:, None, None] * shape[1] + jj[None, :, None]) * shape[2] + kk[None, None, :]).ravel()
    return flat, tuple(slice(1, 1 + (n + 1) // 2) for n in shape)


def field_narrow_band(skin, grid, t, c, rim_cap, progress=None, p0=0.0, p1=1.0):
    """The field `SkinDistance.field(., t, c, rim_cap)` on `grid`'s lattice 0 (module docstring):
    (values (nx, ny, nz), number of points evaluated exactly)."""
    fine = _Level(skin, grid.lo, grid.sp, grid.shape0, (t, c, rim_cap))
    chain = [fine]
    for _ in range(level_count(fine.h, t - c)):
        chain.append(chain[-1].coarser())
    _coarsest(chain[-1], t)
    for k in range(len(chain) - 2, -1, -1):
        _progress(progress, p0 + (p1 - p0) * (len(chain) - 1 - k) / len(chain), "distance field")
        _refine(chain[k], chain[k + 1])
    _progress(progress, p1, "distance field")
    return fine.vals.reshape(fine.shape), sum(lv.evaluated for lv in chain)


def _progress(progress, frac, text):
    if progress is not None:
        progress(float(frac), text)
