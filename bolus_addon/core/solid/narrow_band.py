"""The shell field on the marching-cubes lattice, exact on the corners of every cube the surface
crosses and guessed elsewhere, level by level from a coarse lattice, stored in bricks.

Levels: the fine lattice (spacing sp) and coarser ones of 2 sp, 4 sp, ... up to about a third of
the wall; point m of a level lies on point 2 m - 2 of the next finer one.  The coarsest is exact
within t + 3 spacings of the skin (libigl's AABB distance) and -3 spacings elsewhere (a bound
of the field there).  Then on every finer level, h its spacing:

    0. bricks  store only the bricks (B^3 points) that meet a coarser cell whose corners are
               not all above h or all below -h; an unstored brick has one sign and reads sign h;
    1. guess   g = trilinear interpolation of the coarser level (exact where it copies one);
    2. exact   f where |g| < h;
    3. close   every cube whose corners differ in sign and has a guessed corner: those corners
               exact; then the 26 neighbours of every point whose sign flipped, until none.

A wrong guess survives only inside a region of guessed points that all carry it, away from any
crossing.  Memory and time follow the surface, not the box (docs/design/solid.md).  The fine
lattice is `grid._Grid`'s lattice 0; outside it the field reads -1, so the surface closes at
its box.  Points are integer lattice coordinates ijk (k,3) int64; values float64 mm, positive
inside the solid.
"""
from __future__ import annotations

import numpy as np

from .marching import CUBE_CORNERS

__all__ = ["field_narrow_band", "level_count", "BrickLevel", "BRICK"]

BRICK = 8                      #: brick side (points); bricks are stored B^3 values at a time
_B3 = BRICK ** 3
_CHUNK = 1_000_000             #: points per exact evaluation
_HALO_BRICKS = 2_000           #: bricks per halo gather (about 2 million points)
_NEIGHBOURS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                        if (i, j, k) != (0, 0, 0)], dtype=np.int64)
_LOCAL = np.stack(np.meshgrid(*[np.arange(BRICK)] * 3, indexing="ij"), -1).reshape(-1, 3)
_HALO = np.stack(np.meshgrid(*[np.arange(-1, BRICK + 1)] * 3, indexing="ij"), -1).reshape(-1, 3)
# a neighbour at offset -1 / 0 / +1 on an axis gives its points B-1 / all / 0 to the halo's 0 / 1..B / B+1
_SRC = {-1: BRICK - 1, 0: slice(None), 1: 0}
_DST = {-1: 0, 0: slice(1, BRICK + 1), 1: BRICK + 1}
_PARENT = np.stack(np.meshgrid(*[np.arange(5)] * 3, indexing="ij"), -1).reshape(-1, 3)
# a fine point l (0..B-1) of a brick lies on coarse block point _ML[l] (+ half a step when odd)
_ML = (np.arange(BRICK) + 2) // 2 - 1
_WL = 0.5 * (np.arange(BRICK) % 2)


def level_count(sp: float, wall: float, most: int = 3) -> int:
    """Coarser levels above the fine one: spacing 2^k sp stays within wall / 3 (k <= most)."""
    k = 0
    while k < most and (2.0 ** (k + 1)) * sp <= wall / 3.0:
        k += 1
    return max(k, 1)


class BrickLevel:
    """One lattice (lo (3,), sp (3,) mm, shape (3,)) stored in bricks of BRICK^3 points.

    map (bricks per axis) int32: the storage slot of each brick, -1 where none is stored (there
    a point's value is the coarser level's trilinear guess); vals, exact (slots * B^3,): the
    stored values and which of them are exact; origin (slots, 3): each stored brick's first
    point.  evaluated: points computed exactly."""

    def __init__(self, skin, field_args, lo, sp, shape, coarser: "BrickLevel | None" = None):
        self.skin, self.args = skin, field_args
        self.lo, self.sp = np.asarray(lo, dtype=np.float64), np.asarray(sp, dtype=np.float64)
        self.shape = np.asarray(shape, dtype=np.int64)
        self.h = float(self.sp.max())
        self.coarser = coarser
        self.nb = -(-self.shape // BRICK)  # bricks per axis
        # the map has one more brick on every side, pointing to slot 0: the outside, -1 and exact
        self.map = np.full(tuple(self.nb + 2), -1, dtype=np.int32)
        self.map[0, :, :] = self.map[-1, :, :] = self.map[:, 0, :] = self.map[:, -1, :] = 0
        self.map[:, :, 0] = self.map[:, :, -1] = 0
        self.sign = np.zeros(tuple(self.nb), dtype=np.int8)  # of an unstored brick; 0: not known yet
        self.vals = np.full(_B3, -1.0)
        self.exact = np.ones(_B3, dtype=bool)
        self.origin = np.full((1, 3), -BRICK, dtype=np.int64)
        self.count = 1
        self.evaluated = 0

    def coarser_level(self) -> "BrickLevel":
        """The next coarser level, empty: its point m on this level's point 2 m - 2."""
        return BrickLevel(self.skin, self.args, self.lo - 2.0 * self.sp, 2.0 * self.sp,
                          (self.shape + 1) // 2 + 3)

    # ------------------------------------------------------------------ storage
    def _slots(self, ijk) -> np.ndarray:
        """Storage indices of lattice points ijk (k,3) (at most one brick beyond the lattice's
        bricks: the outside slot), -1 where the brick is not stored."""
        b = (ijk >> 3) + 1  # BRICK = 8; -1 reads the outside layer at the far end
        b = self.map[b[:, 0], b[:, 1], b[:, 2]].astype(np.int64)
        loc = (((ijk[:, 0] & 7) << 6) | ((ijk[:, 1] & 7) << 3)) | (ijk[:, 2] & 7)
        return np.where(b >= 0, (b << 9) | loc, -1)

    def _ijk_of(self, slots) -> np.ndarray:
        """(k,3) lattice coordinates of storage indices."""
        b, loc = np.divmod(slots, _B3)
        return self.origin[b] + _LOCAL[loc]

    def inside(self, ijk) -> np.ndarray:
        return np.all((ijk >= 0) & (ijk < self.shape), axis=1)

    def get(self, ijk):
        """(values (k,), exact (k,)) at lattice points ijk (k,3): stored where the brick is, the
        guess elsewhere; outside the lattice -1 (taken as exact)."""
        s = self._slots(ijk)
        have = s >= 0
        sh = s[have]
        vals = np.empty(len(ijk))
        ex = np.zeros(len(ijk), dtype=bool)
        vals[have] = self.vals[sh]
        ex[have] = self.exact[sh]
        if not have.all():
            miss = np.nonzero(~have)[0]
            out = ~self.inside(ijk[miss])
            vals[miss[out]], ex[miss[out]] = -1.0, True
            miss = miss[~out]
            vals[miss] = self.h * self._brick_sign(ijk[miss] >> 3)
        return vals, ex

    def _brick_sign(self, bricks) -> np.ndarray:
        """(k,) +-1: the one sign of the guess in each unstored brick (k,3).  Its points lie only
        in coarser cells whose corners are all above h or all below -h (else it would be
        stored), and two such cells that touch share corners, so one sign holds in the brick;
        an unstored point reads sign * h (which keeps every test below on the same side)."""
        sg = self.sign[bricks[:, 0], bricks[:, 1], bricks[:, 2]]
        todo = np.nonzero(sg == 0)[0]
        if len(todo):
            mark = np.zeros(tuple(self.nb), dtype=bool)
            mark[tuple(bricks[todo].T)] = True
            bk = np.argwhere(mark)
            probe = np.minimum(bk * BRICK, self.shape - 1)
            self.sign[tuple(bk.T)] = np.where(self.guess(probe) > 0, 1, -1)
            sg = self.sign[bricks[:, 0], bricks[:, 1], bricks[:, 2]]
        return sg.astype(np.float64)

    def guess(self, ijk) -> np.ndarray:
        """Trilinear guess (k,) from the coarser level at fine points ijk (k,3)."""
        m = (ijk + 2) // 2
        w = 0.5 * (ijk % 2)
        out = np.zeros(len(ijk))
        for d in CUBE_CORNERS:
            wd = np.prod(np.where(d[None] == 1, w, 1.0 - w), axis=1)
            on = wd > 0
            out[on] += wd[on] * self.coarser.get(m[on] + d)[0]
        return out

    def _grow(self, k: int) -> np.ndarray:
        """k new storage slots (their brick indices)."""
        need = self.count + k
        if need * _B3 > len(self.vals):
            cap = max(need, int(1.5 * len(self.vals) // _B3) + 16)
            self.vals = np.concatenate([self.vals, np.empty(cap * _B3 - len(self.vals))])
            self.exact = np.concatenate([self.exact, np.zeros(cap * _B3 - len(self.exact), dtype=bool)])
            self.origin = np.concatenate([self.origin, np.zeros((cap - len(self.origin), 3), dtype=np.int64)])
        ids = np.arange(self.count, need)
        self.count = need
        return ids

    def activate(self, bricks) -> np.ndarray:
        """Store the bricks (k,3) (brick coordinates) not stored yet, filled with the coarser
        level's guess (step 1); returns the storage indices of their points with |g| < h that
        are not exact (step 2's points)."""
        bricks = bricks.reshape(-1, 3)
        bricks = bricks[np.all((bricks >= 0) & (bricks < self.nb), axis=1)]
        mark = np.zeros(tuple(self.nb), dtype=bool)  # each brick once, without a sort
        mark[tuple(bricks.T)] = True
        bricks = np.argwhere(mark & (self.map[1:-1, 1:-1, 1:-1] < 0))
        if len(bricks) == 0:
            return np.zeros(0, dtype=np.int64)
        todo = []
        for s in range(0, len(bricks), _HALO_BRICKS):
            bk = bricks[s:s + _HALO_BRICKS]
            ids = self._grow(len(bk))
            self.map[tuple((bk + 1).T)] = ids
            o = bk * BRICK
            self.origin[ids] = o
            # the coarse block of parents: 5 points per axis from o / 2 + 1
            par = (o // 2 + 1)[:, None, :] + _PARENT[None]
            C, CE = self.coarser.get(par.reshape(-1, 3))
            C = C.reshape(-1, 5, 5, 5)
            for ax in (1, 2, 3):  # separable trilinear: along x, y, z
                C = (np.take(C, _ML, axis=ax) * _shape_w(1.0 - _WL, ax)
                     + np.take(C, _ML + 1, axis=ax) * _shape_w(_WL, ax))
            E = np.zeros((len(bk), BRICK, BRICK, BRICK), dtype=bool)
            E[:, ::2, ::2, ::2] = CE.reshape(-1, 5, 5, 5)[:, :BRICK // 2, :BRICK // 2, :BRICK // 2]
            pts = o[:, None, :] + _LOCAL[None]
            out = ~np.all(pts < self.shape, axis=2).reshape(E.shape)
            C[out] = -1.0
            E[out] = True
            sl = slice(ids[0] * _B3, (ids[-1] + 1) * _B3)
            self.vals[sl] = C.ravel()
            self.exact[sl] = E.ravel()
            near = np.nonzero((np.abs(self.vals[sl]) < self.h) & ~self.exact[sl])[0]
            todo.append(near + ids[0] * _B3)
        return np.concatenate(todo)

    # ------------------------------------------------------------------ exact values
    def evaluate(self, ijk=None, slots=None) -> np.ndarray:
        """The exact field at lattice points ijk (k,3) and/or storage indices slots not exact yet
        (their bricks stored first); returns the (k',3) points whose sign changed."""
        extra = []
        if ijk is not None and len(ijk):
            s = self._slots(ijk)
            if (s < 0).any():  # never outside: that is slot 0
                extra.append(self.activate(ijk[s < 0] // BRICK))
                s = self._slots(ijk)
            extra.append(s)
        if slots is not None:
            extra.append(np.asarray(slots, dtype=np.int64))
        if not extra:
            return np.zeros((0, 3), dtype=np.int64)
        mark = np.zeros(self.count * _B3, dtype=bool)  # each point once, without a sort
        for e in extra:
            mark[e] = True
        mark &= ~self.exact[:len(mark)]
        s = np.nonzero(mark)[0]
        del mark
        flipped = []
        for k in range(0, len(s), _CHUNK):
            part = s[k:k + _CHUNK]
            X = self.lo + self._ijk_of(part) * self.sp
            f = self.skin.field(X, *self.args)
            flipped.append(part[(f > 0) != (self.vals[part] > 0)])
            self.vals[part] = f
            self.exact[part] = True
        self.evaluated += len(s)
        return self._ijk_of(np.concatenate(flipped)) if flipped else np.zeros((0, 3), dtype=np.int64)

    # ------------------------------------------------------------------ cubes
    def halos(self):
        """Yields (origins (k,3), values (k, B+2, B+2, B+2), exact (same)) of the stored bricks,
        each with one layer of points around it (lattice points o - 1 .. o + B): the layer is
        copied face, edge and corner from the 26 neighbouring bricks (an unstored one gives its
        sign * h, guessed; beyond the lattice -1, exact), as `get` reads them."""
        n = BRICK + 2
        c3 = self.count * _B3
        vals3 = self.vals[:c3].reshape(-1, BRICK, BRICK, BRICK)
        ex3 = self.exact[:c3].reshape(-1, BRICK, BRICK, BRICK)
        for s in range(1, self.count, _HALO_BRICKS):
            ids = np.arange(s, min(self.count, s + _HALO_BRICKS))
            o = self.origin[ids]
            b = o // BRICK
            V = np.empty((len(ids), n, n, n))
            E = np.empty((len(ids), n, n, n), dtype=bool)
            V[:, 1:-1, 1:-1, 1:-1] = vals3[ids]
            E[:, 1:-1, 1:-1, 1:-1] = ex3[ids]
            for d in _NEIGHBOURS:
                nb = self.map[b[:, 0] + 1 + d[0], b[:, 1] + 1 + d[1], b[:, 2] + 1 + d[2]]
                src = tuple(_SRC[int(x)] for x in d)
                dst = (slice(None),) + tuple(_DST[int(x)] for x in d)
                have = nb >= 0
                v = vals3[(np.maximum(nb, 0),) + src]
                e = ex3[(np.maximum(nb, 0),) + src]
                if not have.all():
                    miss = np.nonzero(~have)[0]
                    sg = self.h * self._brick_sign(b[miss] + d)
                    v[miss] = sg.reshape((-1,) + (1,) * (v.ndim - 1))
                    e[miss] = False
                V[dst] = v
                E[dst] = e
            edge = np.nonzero(np.any(b >= self.nb - 1, axis=1))[0]
            if len(edge):  # halo points beyond the lattice of the bricks at its border read -1
                pts = o[edge][:, None, :] + _HALO[None]
                out = ~np.all((pts >= 0) & (pts < self.shape), axis=2)
                Vf = V[edge].reshape(len(edge), -1)
                Ef = E[edge].reshape(len(edge), -1)
                Vf[out], Ef[out] = -1.0, True
                V[edge] = Vf.reshape(-1, n, n, n)
                E[edge] = Ef.reshape(-1, n, n, n)
            yield o, V, E

    def cubes(self, guessed_only: bool = False, bound: float | None = None, corners: bool = True):
        """The cubes with a lower corner at o - 1 .. o + B - 1 of a stored brick whose corners do
        not share one sign (with bound: whose corners are not all > bound or all < -bound);
        guessed_only: those with a guessed corner.  Returns (lower corners (k,3), corner values
        (k,8) in CUBE_CORNERS order, corner exact flags (k,8)), each cube once; corners=False:
        the lower corners only, possibly repeated (None for the rest)."""
        n = BRICK + 1
        out_c, out_v, out_e = [], [], []
        for o, V, E in self.halos():
            if bound is None:
                pos = V > 0
                cnt = sum(pos[:, dx:dx + n, dy:dy + n, dz:dz + n].astype(np.uint8) for dx, dy, dz in CUBE_CORNERS)
                sel = (cnt > 0) & (cnt < 8)
            else:
                hi = np.ones(V[:, :n, :n, :n].shape, dtype=bool)
                lo = hi.copy()
                for dx, dy, dz in CUBE_CORNERS:
                    w = V[:, dx:dx + n, dy:dy + n, dz:dz + n]
                    hi &= w > bound
                    lo &= w < -bound
                sel = ~(hi | lo)
            if guessed_only:
                g = np.zeros(sel.shape, dtype=bool)
                for dx, dy, dz in CUBE_CORNERS:
                    g |= ~E[:, dx:dx + n, dy:dy + n, dz:dz + n]
                sel &= g
            b, i, j, k = np.nonzero(sel)
            if len(b) == 0:
                continue
            out_c.append(o[b] + np.stack([i, j, k], axis=1) - 1)
            if not corners:
                continue
            out_v.append(np.stack([V[b, i + dx, j + dy, k + dz] for dx, dy, dz in CUBE_CORNERS], axis=1))
            out_e.append(np.stack([E[b, i + dx, j + dy, k + dz] for dx, dy, dz in CUBE_CORNERS], axis=1))
        if not out_c:
            return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 8)), np.zeros((0, 8), dtype=bool)
        c = np.concatenate(out_c)
        if not corners:
            return c, None, None
        key = np.ravel_multi_index((c + 1).T, tuple(self.nb * BRICK + 2))
        _, first = np.unique(key, return_index=True)
        return c[first], np.concatenate(out_v)[first], np.concatenate(out_e)[first]

    def dense(self) -> np.ndarray:
        """The whole lattice (nx, ny, nz) of values (stored or guessed): for tests of small grids."""
        ijk = np.stack(np.meshgrid(*[np.arange(n) for n in self.shape], indexing="ij"), -1).reshape(-1, 3)
        return self.get(ijk)[0].reshape(tuple(self.shape))


def _shape_w(w, ax):
    shape = [1, 1, 1, 1]
    shape[ax] = len(w)
    return w.reshape(shape)


def _coarsest(level: BrickLevel, t: float, progress, p0, p1) -> None:
    """The coarsest level, every brick stored: exact within t + 3 spacings of the skin, -3
    spacings elsewhere (where the field is below that).  A brick whose centre is farther from
    the skin than that plus its half diagonal is far at every point (distance is 1-Lipschitz)."""
    skin = level.skin
    bricks = np.stack(np.meshgrid(*[np.arange(n) for n in level.nb], indexing="ij"), -1).reshape(-1, 3)
    ids = level._grow(len(bricks))
    level.map[tuple((bricks + 1).T)] = ids
    level.origin[ids] = bricks * BRICK
    level.vals[_B3:] = -3.0 * level.h
    band = t + 3.0 * level.h
    centre = level.lo + (bricks * BRICK + 0.5 * (BRICK - 1)) * level.sp
    dc, _, _ = skin.aabb.squared_distance(skin._Vc, skin._Fc, np.ascontiguousarray(centre))
    reach = band + 0.5 * (BRICK - 1) * float(np.linalg.norm(level.sp))
    near = ids[np.sqrt(np.asarray(dc).ravel()) < reach]
    slots = (near[:, None] * _B3 + np.arange(_B3)[None]).ravel()
    pts = level._ijk_of(slots)
    out = ~level.inside(pts)
    level.vals[slots[out]] = -1.0
    level.exact[slots[out]] = True
    slots, pts = slots[~out], pts[~out]
    far = ~np.isin(np.arange(level.count), near)
    far[0] = False
    fs = (np.nonzero(far)[0][:, None] * _B3 + np.arange(_B3)[None]).ravel()
    fo = ~level.inside(level._ijk_of(fs))
    level.vals[fs[fo]] = -1.0
    level.exact[fs[fo]] = True
    for k in range(0, len(slots), _CHUNK):
        part = slots[k:k + _CHUNK]
        X = np.ascontiguousarray(level.lo + pts[k:k + _CHUNK] * level.sp)
        d2, _, _ = skin.aabb.squared_distance(skin._Vc, skin._Fc, X)
        level.evaluate(slots=part[np.asarray(d2).ravel() < band * band])
        _progress(progress, p0 + (p1 - p0) * min(1.0, (k + _CHUNK) / max(len(slots), 1)), "distance field")


def _close(level: BrickLevel) -> None:
    """Step 3: the guessed corners of crossing cubes, then the neighbours of every flip."""
    cubes, _, ex = level.cubes(guessed_only=True)
    corners = (cubes[:, None, :] + CUBE_CORNERS[None])[~ex]
    flipped = level.evaluate(ijk=corners)
    while len(flipped):
        flipped = level.evaluate(ijk=(flipped[:, None, :] + _NEIGHBOURS[None]).reshape(-1, 3))


def _refine(level: BrickLevel) -> None:
    """Steps 0-3 of the module docstring on `level` from its finished coarser level."""
    cells, _, _ = level.coarser.cubes(bound=level.h, corners=False)
    # coarse cell m holds fine points 2 m - 2 .. 2 m: the bricks of its two ends on every axis
    ends = np.stack([(2 * cells - 2) // BRICK, (2 * cells) // BRICK], axis=1)  # (k, 2, 3)
    bricks = np.stack([np.stack([ends[:, dx, 0], ends[:, dy, 1], ends[:, dz, 2]], axis=1)
                       for dx, dy, dz in CUBE_CORNERS], axis=1)
    level.evaluate(slots=level.activate(bricks.reshape(-1, 3)))
    _close(level)


def field_narrow_band(skin, grid, t, c, rim_cap, progress=None, p0=0.0, p1=1.0) -> BrickLevel:
    """The field `SkinDistance.field(., t, c, rim_cap)` on `grid`'s lattice 0 (module docstring):
    the fine BrickLevel (`cubes()` gives the crossing cubes and their exact corner values;
    `evaluated_total` the points computed exactly on every level)."""
    fine = BrickLevel(skin, (t, c, rim_cap), grid.lo, grid.sp, grid.shape0)
    chain = [fine]
    for _ in range(level_count(fine.h, t - c)):
        chain[-1].coarser = chain[-1].coarser_level()
        chain.append(chain[-1].coarser)
    n = len(chain)
    _coarsest(chain[-1], t, progress, p0, p0 + (p1 - p0) / n)
    for k in range(n - 2, -1, -1):
        _progress(progress, p0 + (p1 - p0) * (n - 1 - k) / n, "distance field")
        _refine(chain[k])
    _progress(progress, p1, "distance field")
    fine.evaluated_total = sum(lv.evaluated for lv in chain)
    fine.stored_points = sum(lv.count for lv in chain) * _B3
    return fine


def _progress(progress, frac, text):
    if progress is not None:
        progress(float(frac), text)
