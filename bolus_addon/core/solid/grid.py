"""The voxel part of the bolus shell: the grid, the field of `distance_field.SkinDistance` on
it (exact only where it decides the surface) and its zero surface.

The field is positive inside the solid (see distance_field).  By default it is sampled on one
cubic lattice, exact on the corners of the cubes the surface crosses (`narrow_band`), and meshed
by `marching.marching_manifold` (libigl's compiled marching cubes on those cubes).  The peer, manifold3d's level set, takes a per-point Python
callable only, so for it the field is computed beforehand on exactly the points it asks for
(the body-centred cubic grid of manifold's sdf.cpp) and the callback just looks them up.
"""
from __future__ import annotations

import time

import numpy as np

import manifold3d as m3

from ..errors import BolusError
from .creases import sharpen_creases
from .manifold import from_manifold, to_manifold
from .marching import marching_cubes_on
from .narrow_band import field_narrow_band

__all__ = ["COPLANAR_TOL_MM", "_Grid", "_coarse_terms", "_field_coarse_to_fine", "_level_set_fast", "_tight_box",
           "_solid_on_grid", "_progress"]


def _progress(progress, frac, text):
    if progress is not None:
        progress(float(frac), text)


# ---------------------------------------------------------------------------- the grid
class _Grid:
    """manifold3d's level-set grid (sdf.cpp): gridSize = dim / edgeLength + 1 points per axis,
    spacing = dim / (gridSize - 1); lattice 0 at lo + i sp (i < gs), lattice 1 at
    lo + (i - 1/2) sp (i <= gs)."""

    def __init__(self, lo, hi, res):
        self.lo = np.asarray(lo, dtype=np.float64)
        self.hi = np.asarray(hi, dtype=np.float64)
        self.res = float(res)
        dim = self.hi - self.lo
        self.gs = (dim / self.res + 1.0).astype(int)
        self.sp = dim / (self.gs - 1)
        self.shape0 = tuple(int(x) for x in self.gs)
        self.shape1 = tuple(int(x) + 1 for x in self.gs)

    def axes(self, lattice):
        if lattice == 0:
            return [self.lo[a] + np.arange(self.gs[a]) * self.sp[a] for a in range(3)]
        return [self.lo[a] + (np.arange(self.gs[a] + 1) - 0.5) * self.sp[a] for a in range(3)]

    @property
    def points(self) -> int:
        return int(np.prod(self.shape0) + np.prod(self.shape1))


def _coarse_terms(skin, grid, t, c, band):
    """Exact terms on the coarse lattice lo + (2 m - 2) sp (every other lattice-0 point, one
    extra layer around): (lower bound of min(a, b), upper bound of min(a, b), upper bound of
    t - |sd|, r capped at 8 sp), each (Mx, My, Mz); far from the skin (beyond ``band``) only
    the upper bounds hold."""
    sp = grid.sp
    M = (grid.gs + 1) // 2 + 3
    ax = [grid.lo[a] + (2 * np.arange(M[a]) - 2) * sp[a] for a in range(3)]
    P = np.stack(np.meshgrid(*ax, indexing="ij"), axis=-1).reshape(-1, 3)
    d0, _ = skin.cent_tree.query(P, k=1, distance_upper_bound=band, workers=2)
    near = np.isfinite(d0)
    far_value = -(band - t - skin.tri_rmax)
    lo_ab = np.full(len(P), -np.inf)
    hi_ab = np.full(len(P), far_value)
    hi_ud = np.full(len(P), far_value)
    rc = np.full(len(P), 8.0 * float(sp.max()))
    if near.any():
        a, b, r = skin.terms(P[near], t, c, 8.0 * float(sp.max()))
        lo_ab[near] = hi_ab[near] = np.minimum(a, b)
        hi_ud[near] = t - np.abs(t - b)  # t - |sd|
        rc[near] = r
    shape = tuple(int(x) for x in M)
    return lo_ab.reshape(shape), hi_ab.reshape(shape), hi_ud.reshape(shape), rc.reshape(shape)


def _field_coarse_to_fine(skin, grid, lattice, t, c, rim_cap, band, coarse, progress, p0, p1):
    """Field values on a fine lattice (flat, C order), exact only where it matters.

    Away from the rim min(a, b) is 1-Lipschitz (a signed distance), so at a fine point p and
    the 8 corners P of its coarse cell, max(lo(P) - |p - P|) <= min(a, b)(p) <= min(hi(P) +
    |p - P|); everywhere f <= t - |sd|, and the unsigned distance is 1-Lipschitz.  Where these
    prove |f(p)| > one grid spacing (the signed bounds only where the foot is at least 8
    spacings from the rim at every corner: near an open border the sign of sd jumps, and the
    rim term is not Lipschitz in concave spots), no marching-tetrahedra edge at p crosses the
    surface and the bound stands in for the value; elsewhere the field is evaluated exactly.
    Returns (values (shape + 2) with one layer of -1 around, number evaluated exactly)."""
    lo_ab, hi_ab, hi_ud, rc = coarse
    sp = grid.sp
    spm = float(sp.max())
    off = 0.0 if lattice == 0 else -0.5
    shape = grid.shape0 if lattice == 0 else grid.shape1
    ax = grid.axes(lattice)
    mm, d2 = [], []
    for a in range(3):
        u = np.arange(shape[a]) + off + 2.0          # in fine spacings from the coarse origin
        m = np.floor(u / 2.0).astype(int)
        fr = u - 2.0 * m                               # in [0, 2)
        mm.append(m)
        d2.append(np.stack([(fr * sp[a]) ** 2, ((2.0 - fr) * sp[a]) ** 2]))  # (2, n): corner 0 / 1
    padded = np.full(tuple(x + 2 for x in shape), -1.0)  # one layer of -1 around: see _level_set_fast
    out = padded[1:-1, 1:-1, 1:-1]
    slab = max(1, int(1_000_000 // max(shape[1] * shape[2], 1)))
    n_exact = 0
    for i0 in range(0, shape[0], slab):
        i1 = min(shape[0], i0 + slab)
        L = np.full((i1 - i0, shape[1], shape[2]), -np.inf)
        U = np.full((i1 - i0, shape[1], shape[2]), np.inf)
        R = np.full((i1 - i0, shape[1], shape[2]), np.inf)
        Ud = np.full((i1 - i0, shape[1], shape[2]), np.inf)
        for dx in (0, 1):
            for dy in (0, 1):
                for dz in (0, 1):
                    ix = np.ix_(mm[0][i0:i1] + dx, mm[1] + dy, mm[2] + dz)
                    dist = np.sqrt(d2[0][dx, i0:i1][:, None, None] + d2[1][dy][None, :, None]
                                   + d2[2][dz][None, None, :])
                    np.maximum(L, lo_ab[ix] - dist, out=L)
                    np.minimum(U, hi_ab[ix] + dist, out=U)
                    np.minimum(R, rc[ix], out=R)
                    np.minimum(Ud, hi_ud[ix] + dist, out=Ud)
        far_rim = R >= 8.0 * spm - 1e-9
        pos = (L > spm) & far_rim
        neg = ((U < -spm) & far_rim) | (Ud < -spm)
        vals = np.where(pos, np.minimum(L, rim_cap), np.minimum(np.where(far_rim, U, np.inf), Ud))
        exact = ~(pos | neg)
        if exact.any():
            ii, jj, kk = np.nonzero(exact)
            P = np.stack([ax[0][i0 + ii], ax[1][jj], ax[2][kk]], axis=1)
            vals[exact] = skin.field(P, t, c, rim_cap)
            n_exact += len(P)
        out[i0:i1] = vals
        _progress(progress, p0 + (p1 - p0) * i1 / shape[0], "distance field")
    return padded, n_exact


def _level_set_fast(grid, f0, f1):
    """Manifold.level_set with the cheapest lookup callback (about half the time of a rounding,
    lattice-testing lookup; tests/test_core_shell.py checks they give the same mesh): f0, f1 the lattices padded by one layer of -1, and w = (x - lo) / sp + 1.25 gives
    int(w) = i + 1 on lattice 0 (frac 0.25) and int(w) = i on lattice 1 (frac 0.75), so three
    truncations and one comparison find the value."""
    n0 = tuple(x + 2 for x in grid.shape0)
    n1 = tuple(x + 2 for x in grid.shape1)
    if f0.shape != n0 or f1.shape != n1:
        raise ValueError("_level_set_fast wants the padded lattices of _field_coarse_to_fine")
    # flat float views of the numpy arrays: indexing them is as cheap as an array('d'), no copy
    F0 = memoryview(np.ascontiguousarray(f0)).cast("B").cast("d")
    F1 = memoryview(np.ascontiguousarray(f1)).cast("B").cast("d")
    s0y, s0z = n0[1] * n0[2], n0[2]
    s1y, s1z = n1[1] * n1[2], n1[2]
    o1 = s1y + s1z + 1
    ix, iy, iz = (float(1.0 / x) for x in grid.sp)
    bx, by, bz = (float(1.25 - lo / sp) for lo, sp in zip(grid.lo, grid.sp))

    def f(x, y, z):
        a = x * ix + bx
        i = int(a)
        j = int(y * iy + by)
        k = int(z * iz + bz)
        if a - i > 0.5:
            return F1[i * s1y + j * s1z + k + o1]
        return F0[i * s0y + j * s0z + k]

    return m3.Manifold.level_set(f, list(grid.lo) + list(grid.hi), grid.res, 0.0, -1.0)


def _tight_box(skin, t, res):
    """(lo, hi) (3,): box of the skin and of its vertices and triangle corners moved by t along
    their vertex / face normals, grown by 3 voxels."""
    P = np.concatenate([skin.V, skin.V + t * skin.vn] + [skin.V[skin.F[:, j]] + t * skin.fn for j in range(3)])
    return P.min(axis=0) - 3 * res, P.max(axis=0) + 3 * res


#: mm: `Manifold.simplify` merges the mesher's triangles that are coplanar (and edges collinear)
#: to this; a micrometre also merged triangles across the skin's folds (docs/design/solid.md)
COPLANAR_TOL_MM = 1e-7

MESHERS = ("cubes", "level_set")  #: libigl's marching cubes on one lattice; manifold3d's level set on two


def _solid_on_grid(skin, grid, t, c, progress, stats, mesher: str = "cubes"):
    """The field on the grid and its zero surface (a Manifold).

    mesher "cubes": the field on lattice 0 only, meshed by `marching.marching_manifold`;
    "level_set": on both lattices of manifold3d's body-centred grid, meshed by
    `Manifold.level_set` (the slower peer the shell benchmark measures beside it)."""
    if mesher not in MESHERS:
        raise ValueError(f"mesher must be one of {MESHERS}, got {mesher!r}")
    T0 = time.process_time()
    rim_cap = 3.0 * float(grid.sp.max())
    band = t + 3.0 * float(grid.sp.max()) + skin.tri_rmax
    lattices = (0, 1) if mesher == "level_set" else (0,)
    p_mid = 0.55 if mesher == "level_set" else 0.45
    if mesher == "cubes":
        band_level = field_narrow_band(skin, grid, t, c, rim_cap, progress, 0.05, p_mid)
        n_exact = band_level.evaluated_total
        cubes, corner_values, _ = band_level.cubes()
        del band_level
        fields = [corner_values]
    else:
        coarse = _coarse_terms(skin, grid, t, c, band)
        step = (p_mid - 0.05) / len(lattices)
        fields, n_exact = [], 0
        for i, lattice in enumerate(lattices):
            f, n = _field_coarse_to_fine(skin, grid, lattice, t, c, rim_cap, band, coarse, progress,
                                         0.05 + i * step, 0.05 + (i + 1) * step)
            fields.append(f)
            n_exact += n
        del coarse
    stats["exact_points"] = stats.get("exact_points", 0) + n_exact
    stats["grid_points"] = stats.get("grid_points", 0) + sum(
        int(np.prod(grid.shape0 if lattice == 0 else grid.shape1)) for lattice in lattices)
    if mesher == "cubes":
        stats["crossing_cubes"] = len(cubes)
    if not any(np.max(f, initial=-1.0) > 0 for f in fields):
        raise BolusError("the region is too small for this resolution: no voxel lies inside the shell; choose a "
                         "finer resolution or a larger region")
    stats["field_s"] = stats.get("field_s", 0.0) + time.process_time() - T0
    _progress(progress, p_mid, "marching cubes" if mesher == "cubes" else "level set")
    T1 = time.process_time()
    if mesher == "cubes":
        V, F = marching_cubes_on(cubes, fields[0], grid.lo, grid.sp)
    else:
        M = _level_set_fast(grid, *fields)
    del fields
    stats["level_set_s"] = stats.get("level_set_s", 0.0) + time.process_time() - T1
    if mesher == "cubes":
        M = to_manifold(V, F, "the marched solid")
        del V, F, cubes  # before the merge below copies the solid: the peak of the whole shell
    # the triangles the mesher leaves in one plane (a face of the skin and its offset: most of a
    # coarse skin's solid) merged before anything else reads them
    M = M.simplify(COPLANAR_TOL_MM)
    if mesher == "cubes" and skin.rim == "strip":
        _progress(progress, p_mid + 0.1, "sharp creases")
        T1 = time.process_time()
        V, F, figures = sharpen_creases(skin, *from_manifold(M), t, c, rim_cap, float(grid.sp.max()))
        stats.update(figures)
        stats["creases_s"] = stats.get("creases_s", 0.0) + time.process_time() - T1
        M = to_manifold(V, F, "the marched solid")
    stats["mesher"] = mesher
    if str(M.status()).split(".")[-1] != "NoError" or M.is_empty():
        raise BolusError(f"the volume step failed ({mesher}: {M.status()}); try a coarser resolution")
    return M
