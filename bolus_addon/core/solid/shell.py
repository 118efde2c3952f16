"""The bolus shell: a closed printable solid of chosen thickness on a skin region (seed 1.1).

`make_shell` takes a skin region V (n,3) mm, F (m,3) (open, normals pointing away from the body),
the thickness t, clearance c and voxel size res (mm), and returns a `Shell`: V, F, the SIDE_* of
each face, the volume (mm^3), the ray thickness figures (mm) and warnings.

The solid is the positive set of the one-sided distance field of `distance_field.SkinDistance`,
f = min(sd - c, t - sd, r): inner face at c, outer face at the true distance t from the skin, rim
wall swept along the border normals; `grid` samples the field and meshes its zero surface,
closed and manifold by construction.  Every border loop but the outer one is a hole: it gets
the rim wall in the field and a cutter, its membrane swept along the channel directions from t
below to 2t above the skin (a union of convex hulls), subtracted with a manifold boolean.
Pieces under KEEP_PIECE_FRACTION of the largest are dropped (`shell_checks`); then the face
sides, the wall thickness (rays from the inner face), the topology and, given ``others``, the
collision with the rest of the skin are checked.  A border that zigzags along whole triangles
is built once more without its saw teeth.

Design notes: docs/design/solid.md.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

import manifold3d as m3

from .distance_field import SkinDistance
from ..budget import Deadline, budget_s, check_grid_budget, grid_resolution_for_budget
from ..errors import BolusError
from .grid import _coarse_terms, _field_coarse_to_fine, _Grid, _level_set_fast, _progress, _solid_on_grid, _tight_box
from .manifold import SIDE_INNER, SIDE_OUTER, SIDE_RIM, from_manifold, ray_thickness, to_manifold
from ..mesh.topology import as_mesh_arrays, check_mesh, misoriented_text
from .shell_checks import (  # noqa: F401 (re-exported)
    COLLISION_TOL_MM,
    KEEP_PIECE_FRACTION,
    _hole_cutter,
    _vertex_normals,
    _measure_thickness,
    _inside,
    _collision,
    drop_border_ears,
    _topology_warnings,
    _drop_crumbs,
    _clean,
)

__all__ = ["Shell", "check_shell_request", "make_shell", "MAX_THICKNESS_MM", "MAX_GRID_POINTS", "MAX_SKIN_CELLS"]

MAX_THICKNESS_MM = 50.0
#: voxels the wall (thickness - clearance) must span at least
MIN_VOXELS_ACROSS = 4
#: lattice points of the level-set peer's field (both of its lattices, dense) above which the
#: request is refused: about 11 bytes each at the peak (values, flags, masks)
MAX_GRID_POINTS = 120_000_000
#: marching cubes stores the field in bricks along the surface, so its memory follows the skin's
#: area in voxel faces (area / res^2), not the box: measured peak about 3.25 kB per face (the chest
#: wall, 1,284 cm2 at 0.5 mm: 514k faces, 1.67 GB, at the merge of the marched solid's coplanar
#: triangles); 600k keeps the peak within 2 GB (a flat 390 x 390 mm region at 0.5 mm)
MAX_SKIN_CELLS = 600_000


@dataclass
class Shell:
    """A closed, manifold, outward-wound bolus solid (mm)."""
    V: np.ndarray          # (n,3) float64
    F: np.ndarray          # (m,3) int64
    side: np.ndarray       # (m,) int8 SIDE_INNER / SIDE_OUTER / SIDE_RIM
    thickness: float
    clearance: float
    resolution: float
    volume_mm3: float
    thickness_min: float
    thickness_mean: float
    thickness_max: float
    holes: int
    warnings: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)   # figures for benchmarks: seconds per stage, grid points, ...


def _num(x, name):
    try:
        x = float(x)
    except (TypeError, ValueError):
        raise BolusError(f"{name} must be a number, got {x!r}") from None
    if not math.isfinite(x):
        raise BolusError(f"{name} must be a finite number, got {x}")
    return x


def check_shell_request(thickness, clearance, resolution, area_mm2=None) -> None:
    """Refuse a bad shell request with a `BolusError` that says what to choose.

    thickness (mm) in (0, 50]; clearance (mm) in [0, thickness); resolution (mm) > 0 and fine
    enough that the wall (thickness - clearance) spans at least 4 voxels; area_mm2 (the
    region's area) > 0 when given."""
    t = _num(thickness, "the thickness")
    c = _num(clearance, "the clearance")
    res = _num(resolution, "the resolution")
    if t <= 0:
        raise BolusError(f"the thickness must be above 0 mm, got {t:g} mm: a bolus is typically 5 to 20 mm thick")
    if t > MAX_THICKNESS_MM:
        raise BolusError(f"the thickness {t:g} mm is above {MAX_THICKNESS_MM:g} mm: choose 5 to 20 mm (a bolus "
                         "thicker than 50 mm is not a skin bolus)")
    if c < 0:
        raise BolusError(f"the clearance must be 0 mm or more, got {c:g} mm")
    if c >= t:
        raise BolusError(f"the clearance {c:g} mm must be smaller than the thickness {t:g} mm (the wall would "
                         "vanish): choose a clearance below the thickness, usually 0 to 1 mm")
    if res <= 0:
        raise BolusError(f"the resolution must be above 0 mm, got {res:g} mm: choose 0.5 mm (1.0 mm for a quick draft)")
    wall = t - c
    if res > wall / MIN_VOXELS_ACROSS:
        raise BolusError(
            f"the resolution {res:g} mm is too coarse for a wall of {wall:g} mm (thickness minus clearance): the "
            f"voxel grid needs at least {MIN_VOXELS_ACROSS} voxels across the wall to keep it closed and even; "
            f"choose a resolution of {wall / MIN_VOXELS_ACROSS:.3g} mm or finer")
    if area_mm2 is not None:
        a = _num(area_mm2, "the region's area")
        if a <= 0:
            raise BolusError("the region has no area: select the faces of the treatment area first")


def _fmt(p):
    return "(" + ", ".join(f"{x:.1f}" for x in p) + ") mm"


# ---------------------------------------------------------------------------- make_shell
def make_shell(V, F, thickness=10.0, clearance=0.0, resolution=0.5, *, others=None, progress=None,
               time_limit_s=None, mesher="cubes", rim="faces", _saw_retry=True) -> Shell:
    """A closed bolus solid on the skin region V (n,3) mm, F (m,3) (an open surface whose face
    normals point away from the body; the shell grows on that side).

    thickness: outer face at this true distance (mm) from the skin; clearance: inner face at
    this distance (mm, 0 = on the skin); resolution: voxel size (mm) of the field's lattice.
    others: (V2 (k,3), F2 (j,3)) the rest of the skin or None: `BolusError` naming the spot if
    the shell would run into it.  time_limit_s: the user's time limit (core.budget; None: the
    default budget, 0: none): a wall that cannot fit (its lower bound over the limit) is refused
    before the work, any other stops at the limit (`budget.TimeLimitReached`).
    Every border loop but the outer one (enclosing the most area seen along the region's mean
    normal) is a hole, kept open through the solid by a channel, unless its membrane spans about as
    much as the largest loop's (`distance_field.HOLE_FRACTION`): then it is an end, open like the
    outer rim (a sleeve's two ends).  mesher: "cubes" (marching cubes) or
    "level_set" (manifold3d's level set, the slower peer of the benchmarks; `grid.MESHERS`).
    rim: the rim wall's rule (`distance_field.RIMS`): "faces" (the planes normal to the border
    faces) or "strip" (a ruled strip along the smoothed border normals, with the marched creases
    made sharp by `creases.sharpen_creases`; smoother, slower: docs/design/solid.md).
    Returns a `Shell`.
    """
    check_shell_request(thickness, clearance, resolution)
    t, c, res = float(thickness), float(clearance), float(resolution)
    V, F = check_mesh(V, F, "the region", nondegenerate=True, manifold=True)
    _progress(progress, 0.0, "preparing the region")
    stats: dict = {}
    T0 = time.process_time()
    _check_size(V, F, t, c, res, others, time_limit_s, mesher)
    if _saw_retry:
        progress = Deadline(progress, budget_s(time_limit_s), "Make Bolus",
                            "choose a coarser resolution or select a smaller region")
    skin = SkinDistance(V, F, rim)
    check_shell_request(t, c, res, skin.area)
    _check_region(skin)
    warnings: list[str] = []
    M = _solid_in_box(skin, V, t, c, res, progress, stats, mesher)
    T1 = time.process_time()
    holes = skin.hole_loops  # ends (a sleeve's far end) stay open without a channel
    M = _cut_holes(skin, M, holes, t, res, progress, warnings)
    T2 = time.process_time()
    stats["holes_s"] = T2 - T1
    _progress(progress, 0.82, "cleaning up")
    M, Vo, Fo = _cleaned(M, warnings)
    T3 = time.process_time()
    stats["clean_s"] = T3 - T2
    _progress(progress, 0.86, "checks")
    side = _face_sides(skin, Vo, Fo, t, c, res)
    T4 = time.process_time()
    stats["sides_s"] = T4 - T3
    th, rays, spot = _measure_thickness(skin, M, Vo, Fo, side, t, c, res)
    stats["thickness_s"] = time.process_time() - T4
    stats["rays"] = rays
    tmin, tmean, tmax = _thickness_figures(th, rays, spot, t - c, warnings)
    topo_warnings = _topology_warnings(skin, M)
    if _saw_retry and topo_warnings and "more tunnel" in topo_warnings[0]:
        again = _again_without_teeth(V, F, t, c, res, others, progress, time_limit_s, mesher, rim)
        if again is not None:
            return again
    warnings += topo_warnings
    if others is not None:
        _progress(progress, 0.95, "collision with the rest of the skin")
        _check_collision(skin, others, t, c, res, M)
    stats["total_cpu_s"] = time.process_time() - T0
    stats["triangles"] = len(Fo)
    _progress(progress, 1.0, "done")
    return Shell(V=Vo, F=Fo, side=side, thickness=t, clearance=c, resolution=res, volume_mm3=float(M.volume()),
                 thickness_min=tmin, thickness_mean=tmean, thickness_max=tmax, holes=len(holes), warnings=warnings,
                 stats=stats)


def _check_size(V, F, t, c, res, others, time_limit_s, mesher="cubes") -> None:
    """Refuse, before any work, a region of over MAX_SKIN_CELLS voxel faces of skin (marching
    cubes), a grid (its box grown by t + 3 res, voxel res mm) of over MAX_GRID_POINTS points (the
    level set), or a region whose wall t - c mm is estimated to take longer than the
    time budget (`budget.check_grid_budget`); the message advises a resolution that fits both."""
    pad = t + 3 * res
    grid = _Grid(V.min(axis=0) - pad, V.max(axis=0) + pad, res)
    size = V.max(axis=0) - V.min(axis=0)
    area = 0.5 * float(np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum())
    read = len(F) + (0 if others is None else len(others[1]))  # triangles the operator reads and checks
    cells = area / res ** 2
    if mesher == "cubes" and cells > MAX_SKIN_CELLS:  # the resolution advised also fits the time budget
        coarse = max(res * (cells / MAX_SKIN_CELLS) ** 0.5,
                     grid_resolution_for_budget(area, t - c, res, read, time_limit_s)[2] or 0.0)
        raise BolusError(
            f"the region ({size[0]:.0f} x {size[1]:.0f} x {size[2]:.0f} mm, {area / 100:.0f} cm²) is "
            f"{cells / 1e6:.2g} million voxel faces of skin at {res:g} mm, more than the "
            f"{MAX_SKIN_CELLS / 1e6:.2g} million that fit in about 2 GB: choose a resolution of "
            f"{np.ceil(coarse * 100) / 100:.2g} mm or coarser, or a smaller region")
    points = grid.points
    if mesher != "cubes" and points > MAX_GRID_POINTS:  # the resolution advised also fits the time budget
        coarse = max(res * (points / MAX_GRID_POINTS) ** (1 / 3),
                     grid_resolution_for_budget(area, t - c, res, read, time_limit_s)[2] or 0.0)
        raise BolusError(
            f"the region ({size[0]:.0f} x {size[1]:.0f} x {size[2]:.0f} mm) needs {points / 1e6:.0f} million "
            f"grid points at {res:g} mm, more than the budget of {MAX_GRID_POINTS / 1e6:.0f} million: choose a "
            f"resolution of {coarse:.2g} mm or coarser, or a smaller region")
    check_grid_budget(area, t - c, res, MIN_VOXELS_ACROSS,  # refuse now, not after minutes
                      f"a {t - c:g} mm wall on the region ({size[0]:.0f} x {size[1]:.0f} x {size[2]:.0f} mm, "
                      f"{area / 100:.0f} cm²)", triangles=read, limit=time_limit_s)


def _solid_in_box(skin, V, t, c, res, progress, stats, mesher="cubes"):
    """The solid of the field (thickness t, clearance c, voxel res mm, `mesher`), first on a box
    around the skin swept t along its normals (`_tight_box`: about a third fewer grid points on a
    face); if the solid comes within a voxel of that box (a crease's normal cone reaching farther
    out), again on the full box (the region's box grown by t + 3 res; stats["box_retry"])."""
    pad = t + 3 * res
    lo, hi = _tight_box(skin, t, res)
    for attempt in (0, 1):
        if attempt:
            grid = _Grid(V.min(axis=0) - pad, V.max(axis=0) + pad, res)
            stats["box_retry"] = True
        else:
            grid = _Grid(np.maximum(lo, V.min(axis=0) - pad), np.minimum(hi, V.max(axis=0) + pad), res)
        M = _solid_on_grid(skin, grid, t, c, progress, stats, mesher)
        bb = np.asarray(M.bounding_box()).reshape(2, 3)
        if attempt or (np.all(bb[0] - grid.lo > grid.res) and np.all(grid.hi - bb[1] > grid.res)):
            break
    return M


def _cut_holes(skin, M, holes, t, res, progress, warnings):
    """The solid M with a channel cut through it for every hole loop of the region
    (`_hole_cutter`: the membrane swept from t + 2 res below to 2t + 2 res above the skin).
    A loop manifold3d refuses, or a hole narrower than 2 res (4 area / perimeter), is warned
    about; BolusError if the boolean fails."""
    if not holes:
        return M
    _progress(progress, 0.75, f"holes ({len(holes)})")
    cutters = []
    for i, loop in enumerate(holes):
        try:
            cut, area, perim = _hole_cutter(skin, loop, t + 2 * res, 2 * t + 2 * res, t)
        except Exception as exc:  # manifold3d refusing a strange loop: keep going, say so
            warnings.append(f"hole {i + 1} near {_fmt(skin.V[loop].mean(axis=0))} could not be cut through the "
                            f"bolus ({exc}); it may be closed over")
            continue
        if not cut.is_empty():
            cutters.append(cut)
        width = 4 * area / perim if perim > 0 else 0.0
        if width < 2 * res:
            warnings.append(f"hole {i + 1} near {_fmt(skin.V[loop].mean(axis=0))} is only about {width:.2g} mm "
                            f"across: it is cut through the bolus as a slit that narrow")
    if cutters:
        M = M - m3.Manifold.batch_boolean(cutters, m3.OpType.Add)
    if str(M.status()).split(".")[-1] != "NoError":
        raise BolusError(f"cutting the holes through the shell failed (manifold3d: {M.status()})")
    return M


def _cleaned(M, warnings):
    """`_clean` (crumbs under KEEP_PIECE_FRACTION dropped, arrays read back until stable):
    (M, Vo (n,3), Fo (m,3)), with warnings for the pieces dropped and for several pieces left."""
    M, Vo, Fo, dropped, pieces = _clean(M)
    crumbs = [v for v in dropped if v >= 0]
    voids = [-v for v in dropped if v < 0]  # a closed surface wound inward: an air pocket inside the solid
    if crumbs:
        warnings.append(f"{len(crumbs)} small piece(s) of {sum(crumbs):.3g} mm^3 in total, cut off by the hole "
                        "channels or thinner than the resolution, were removed")
    if voids:
        warnings.append(f"{len(voids)} air pocket(s) of {sum(voids):.3g} mm^3 in total enclosed inside the bolus "
                        "(where the skin folds under itself, e.g. behind an ear) were filled")
    if pieces > 1:
        warnings.append(f"the shell has {pieces} separate pieces (the region has parts farther apart than the "
                        "thickness)")
    return M, Vo, Fo


def _face_sides(skin, Vo, Fo, t, c, res) -> np.ndarray:
    """SIDE_* (m,) int8 of each face of Fo: the smallest of the field's three terms (sd - c,
    t - sd, r), taken at the vertices (half as many as faces) and averaged over each face;
    faces where no term is within res / 4 of 0 (the hole cutters' walls) are SIDE_RIM."""
    a, b, r = (x[Fo].mean(axis=1) for x in skin.terms(Vo, t, c, 3 * res))
    side = np.full(len(Fo), SIDE_RIM, dtype=np.int8)
    side[(a <= b) & (a <= r)] = SIDE_INNER
    side[(b < a) & (b <= r)] = SIDE_OUTER
    side[np.minimum(np.minimum(a, b), r) > 0.25 * res] = SIDE_RIM  # faces of the hole cutters
    return side


def _thickness_figures(th, rays, spot, wall, warnings) -> tuple[float, float, float]:
    """(min, mean, max) mm of the ray thicknesses th (k,) (NaN when none was measured), with
    warnings for a wall under 95 % of ``wall`` mm (at ``spot``) and for fewer than 95 % of the
    rays (`rays`: counts by what they met) reaching the outer face."""
    if len(th):
        tmin, tmax = float(th.min()), float(th.max())
        tmean = min(max(float(th.mean()), tmin), tmax)  # a sum's rounding can put the mean an ulp outside
        if tmin < 0.95 * wall:
            warnings.append(f"the wall is only {tmin:.2f} mm thick near {_fmt(spot)} (thickness {wall:g} mm asked)")
    else:
        tmin = tmean = tmax = float("nan")
        warnings.append("the thickness could not be measured: no ray from the inner face reached the outer face")
    if rays["rays"] and rays["outer"] < 0.95 * rays["rays"]:
        warnings.append(
            f"of {rays['rays']} rays from the inner face (along its normal) {rays['outer']} reached the outer face; "
            f"{rays['skin']} met the skin again across a valley or cavity the bolus fills (e.g. beside the nose), "
            f"{rays['wall']} left through the rim or a hole channel, {rays['none']} found no wall (creases): "
            "min / mean / max count the first kind only")
    return tmin, tmean, tmax


def _again_without_teeth(V, F, t, c, res, others, progress, time_limit_s, mesher="cubes", rim="faces"):
    """The shell made once more without the border's saw teeth (`drop_border_ears`: triangles
    with two border edges, whose pleated rim wall leaves tiny tunnels), its first warning naming
    them; None when the border has no teeth."""
    F2, ears = drop_border_ears(F)
    if not ears:
        return None
    _progress(progress, 0.5, f"again without the border's {ears} saw teeth")
    again = make_shell(V, F2, t, c, res, others=others, _saw_retry=False, time_limit_s=time_limit_s, mesher=mesher,
                       rim=rim,
                       progress=None if progress is None else (lambda f, text: progress(0.5 + 0.5 * f, text)))
    size = float(np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).max())
    again.warnings.insert(0, f"the region's border zigzags along whole triangles: its {ears} teeth (triangles "
                             f"with two border edges, up to {size:.1f} mm) are left out of the bolus so that "
                             "the rim closes without tiny tunnels; Select Treatment Area gives a smooth border")
    again.stats["border_teeth_dropped"] = ears
    return again


def _check_collision(skin, others, t, c, res, M) -> None:
    """BolusError naming the spot when skin points of others (V2, F2) lie inside the solid M."""
    n, depth, where = _collision(skin, others, t, c, res, M)
    if n:
        raise BolusError(
            f"the shell would run into the rest of the skin near {_fmt(where)} ({n} skin point(s), up to "
            f"{depth:.1f} mm deep inside the bolus): make the region smaller there or the bolus thinner")


def _check_region(skin):
    """The region must be open and consistently wound."""
    if not skin.loops:
        raise BolusError("the region is a closed surface: select the treatment area (an open part of the skin), "
                         "not the whole closed mesh")
    F = skin.F
    he = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    n = len(skin.V)
    key = np.minimum(he[:, 0], he[:, 1]) * n + np.maximum(he[:, 0], he[:, 1])
    fwd = (he[:, 0] < he[:, 1]).astype(np.int64)
    order = np.argsort(key, kind="stable")
    ks, fs = key[order], fwd[order]
    pair = ks[1:] == ks[:-1]
    bad = pair & (fs[1:] == fs[:-1])
    if bad.any():
        k = int(ks[1:][bad][0])
        raise BolusError(f"the region's faces are not consistently oriented ({misoriented_text(F)}; e.g. at the edge "
                         f"between vertices {k // n} and {k % n}): recalculate the normals (Mesh > Normals > "
                         "Recalculate Outside)")
