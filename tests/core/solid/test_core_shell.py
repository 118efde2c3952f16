"""core.shell: the bolus solid on a skin region.  bpy-free; coarse
resolutions (1.5-2 mm) keep the file fast -- speed figures live in bench/."""
import array
import math

import numpy as np
import manifold3d as m3
import pytest

from bolus_addon.core.solid.distance_field import SkinDistance
from bolus_addon.core.errors import BolusError
from bolus_addon.core.solid.shell import check_shell_request, make_shell
from bolus_addon.core.solid.manifold import (
    SIDE_INNER,
    SIDE_OUTER,
    SIDE_RIM,
    closed_report,
    ray_thickness,
    to_manifold,
)
from meshgen import degenerate_variants, grid, grid_with_holes, height_field, icosphere, ring_surface


def hemisphere(R=60.0, nlat=24, na=72, inward=False):
    """Open hemisphere z >= 0 of radius R (rim at z = 0), normals outward (or inward)."""
    th = np.linspace(np.pi / 2, 0, nlat + 1)[:-1]
    V, F, _ = ring_surface(np.stack([R * np.sin(th), R * np.cos(th)], 1), na=na, pole=True)
    V[-1] = [0.0, 0.0, R]
    return (V, F[:, ::-1].copy()) if inward else (V, F)


def sockets_face(n=40, size=120.0):
    """Synthetic face: a 22 mm nose ridge and two 9 mm deep eye sockets on a gently curved sheet
    (normals +z, away from the 'body')."""
    def z(x, y):
        nose = 22.0 * np.exp(-((x / 9.0) ** 2 + ((y + 5) / 22.0) ** 2))
        eyes = -9.0 * (np.exp(-(((x - 30) / 11.0) ** 2 + ((y - 22) / 9.0) ** 2))
                       + np.exp(-(((x + 30) / 11.0) ** 2 + ((y - 22) / 9.0) ** 2)))
        return nose + eyes - 0.004 * (x ** 2 + y ** 2)
    return height_field(z, n, n, size)


@pytest.fixture(scope="module")
def cap_shell():
    V, F = hemisphere()
    return V, F, make_shell(V, F, 10.0, 0.0, 2.0)


def test_cap_closed_manifold_genus0(cap_shell):
    _, _, sh = cap_shell
    rep = closed_report(sh.V, sh.F)
    assert rep["closed"] and rep["components"] == 1 and rep["genus"] == 0
    to_manifold(sh.V, sh.F)  # manifold3d accepts it as is
    assert rep["volume_mm3"] == pytest.approx(sh.volume_mm3, rel=1e-9) and sh.volume_mm3 > 0
    assert sh.holes == 0 and sh.side.dtype == np.int8 and len(sh.side) == len(sh.F)
    assert set(np.unique(sh.side)) == {SIDE_INNER, SIDE_OUTER, SIDE_RIM}


def test_cap_volume_within_one_percent(cap_shell):
    _, _, sh = cap_shell
    exact = 2.0 / 3.0 * math.pi * (70.0 ** 3 - 60.0 ** 3)
    assert abs(sh.volume_mm3 / exact - 1) < 0.01


def only_on(sh, side):
    """Vertices all of whose faces are of this side (not on the edge to another side)."""
    other = np.zeros(len(sh.V), dtype=bool)
    other[sh.F[sh.side != side].ravel()] = True
    return np.setdiff1d(np.unique(sh.F[sh.side == side]), np.nonzero(other)[0])


def test_cap_inner_face_on_the_skin_and_outer_at_thickness(cap_shell):
    V, F, sh = cap_shell
    r = np.linalg.norm(sh.V, axis=1)
    inner = only_on(sh, SIDE_INNER)
    outer = only_on(sh, SIDE_OUTER)
    skin = SkinDistance(V, F)
    d_in = skin.nearest(sh.V[inner])[0]
    assert d_in.max() <= sh.resolution / 2
    away = sh.V[outer][:, 2] > 2 * sh.resolution
    assert np.abs(r[outer][away] - 70.0).max() < 0.1 * sh.resolution + 0.1
    # the rim is the annulus swept by the border normals (the faceted cap's border normals
    # tilt up by half a ring step, 1.9 degrees: z <= 10 tan(1.9 deg) = 0.33, plus the voxel rounding)
    rim = only_on(sh, SIDE_RIM)
    assert np.abs(sh.V[rim][:, 2]).max() < 0.33 + sh.resolution / 2


def test_cap_ray_thickness_within_5_percent(cap_shell):
    _, _, sh = cap_shell
    assert 9.5 <= sh.thickness_min <= sh.thickness_mean <= sh.thickness_max <= 10.5
    # independent rays: from the cap (away from the rim), radially outward
    rng = np.random.default_rng(1)
    u = rng.normal(size=(300, 3))
    u[:, 2] = np.abs(u[:, 2]) + 0.6
    u /= np.linalg.norm(u, axis=1)[:, None]
    d = ray_thickness(sh.V, sh.F, 60.0 * u, u, 40.0)
    assert np.all(np.abs(d - 10.0) < 0.5)


def test_bowl_no_fold_no_thin_spot():
    """Concave side of a sphere (R 30, t 10): a normal push would fold; the true-distance shell
    stays closed and at least 0.95 t thick along the inner face's normals."""
    V, F = hemisphere(30.0, nlat=16, na=48, inward=True)
    sh = make_shell(V, F, 10.0, 0.0, 1.5)
    rep = closed_report(sh.V, sh.F)
    assert rep["closed"] and rep["components"] == 1 and rep["genus"] == 0
    assert sh.thickness_min >= 0.95 * 10.0
    # inner face of the bowl's shell is the sphere, outer face the sphere of radius 20
    outer = np.unique(sh.F[sh.side == SIDE_OUTER])
    r = np.linalg.norm(sh.V[outer], axis=1)
    assert np.median(np.abs(r - 20.0)) < 0.1


def test_sockets_face_no_self_intersection_no_thin_spot():
    V, F = sockets_face()
    sh = make_shell(V, F, 10.0, 0.0, 2.0)
    rep = closed_report(sh.V, sh.F)
    assert rep["closed"] and rep["components"] == 1 and rep["genus"] == 0
    assert sh.thickness_min >= 0.95 * 10.0
    # a self-intersecting solid has points of its outer face closer than t to the skin: none here
    skin = SkinDistance(V, F)
    d, foot, _, _ = skin.nearest(sh.V[only_on(sh, SIDE_OUTER)])
    away = skin.rim_tree.query(foot)[0] > sh.resolution  # the rim corner is rounded by a voxel
    assert np.abs(d[away] - 10.0).max() < 0.1 * sh.resolution


def test_hole_kept_open():
    V, F = grid_with_holes(12, 12, 120.0, holes=((4, 4, 8, 8),))  # 40 x 40 mm hole in the middle
    sh = make_shell(V, F, 8.0, 0.0, 2.0)
    rep = closed_report(sh.V, sh.F)
    assert sh.holes == 1 and rep["closed"] and rep["components"] == 1 and rep["genus"] == 1
    d = ray_thickness(sh.V, sh.F, [[60.0, 60.0, -5.0], [20.0, 20.0, -5.0]], [[0, 0, 1.0], [0, 0, 1.0]], 30.0)
    assert np.isinf(d[0])                      # straight through the hole
    assert d[1] == pytest.approx(5.0, abs=0.2)  # into the material next to it


def test_narrow_curved_hole_cut_through():
    """A hole of 2 x 20 mm (narrower than the 4 mm the level set resolves at 2 mm voxels) in a
    curved sheet: the cutter still opens it, and a warning names it."""
    V, F = grid_with_holes(60, 12, 120.0, holes=((29, 4, 30, 6),))
    V[:, 2] = -0.004 * ((V[:, 0] - 60) ** 2 + (V[:, 1] - 60) ** 2)
    sh = make_shell(V, F, 8.0, 0.0, 2.0)
    rep = closed_report(sh.V, sh.F)
    assert rep["closed"] and rep["genus"] == 1
    assert any("hole 1" in w for w in sh.warnings)
    z = -0.004 * (1.0 ** 2 + 10.0 ** 2)
    assert np.isinf(ray_thickness(sh.V, sh.F, [[59.0, 50.0, z - 3]], [[0, 0, 1.0]], 30.0))[0]


def test_clearance_moves_the_inner_face_out():
    V, F = grid(6, 6, 60.0)
    sh = make_shell(V, F, 8.0, 2.0, 1.5)
    inner = np.unique(sh.F[sh.side == SIDE_INNER])
    outer = np.unique(sh.F[sh.side == SIDE_OUTER])
    mid = lambda ix: ix[np.all((sh.V[ix, :2] > 5) & (sh.V[ix, :2] < 55), axis=1)]
    np.testing.assert_allclose(sh.V[mid(inner), 2], 2.0, atol=1e-6)
    np.testing.assert_allclose(sh.V[mid(outer), 2], 8.0, atol=1e-6)
    assert sh.thickness_mean == pytest.approx(6.0, abs=0.05)
    # the mesher cuts each of the two creases along the 240 mm rim (rim wall with inner and outer
    # face) by a chamfer of at most half a voxel square: at most 240 * res^2 in all
    assert 0 <= 60 * 60 * 6.0 - sh.volume_mm3 <= 240 * 1.5 ** 2


def test_others_collision_names_the_spot():
    V, F = hemisphere(30.0, nlat=12, na=36)
    # the rest of the skin: a sheet 5 mm above the pole, inside the 10 mm shell
    Vo, Fo = grid(4, 4, 20.0)
    Vo = Vo + [-10.0, -10.0, 35.0]
    with pytest.raises(BolusError, match=r"run into the rest of the skin near \(.*\) mm"):
        make_shell(V, F, 10.0, 0.0, 2.0, others=(Vo, Fo))
    # 15 mm above: no collision
    sh = make_shell(V, F, 10.0, 0.0, 2.0, others=(Vo + [0, 0, 10.0], Fo))
    assert closed_report(sh.V, sh.F)["closed"]


@pytest.mark.parametrize("t, c, res, says", [
    (0.0, 0.0, 0.5, "thickness must be above 0"),
    (-3.0, 0.0, 0.5, "thickness must be above 0"),
    (60.0, 0.0, 0.5, "above 50 mm: choose"),
    (float("nan"), 0.0, 0.5, "finite"),
    (10.0, -1.0, 0.5, "clearance must be 0 mm or more"),
    (10.0, 10.0, 0.5, "clearance 10 mm must be smaller than the thickness"),
    (10.0, 0.0, 0.0, "resolution must be above 0 mm"),
    (10.0, 0.0, 3.0, "too coarse .* choose a resolution of 2.5 mm or finer"),
    (5.0, 3.0, 1.0, "too coarse for a wall of 2 mm .* 0.5 mm or finer"),
    ("a", 0.0, 0.5, "must be a number"),
])
def test_bad_request(t, c, res, says):
    with pytest.raises(BolusError, match=says):
        check_shell_request(t, c, res)
    with pytest.raises(BolusError, match=says):
        make_shell(*grid(2, 2, 10.0), t, c, res)


def test_no_area_closed_and_flipped_regions():
    with pytest.raises(BolusError, match="no area"):
        check_shell_request(10.0, 0.0, 0.5, area_mm2=0.0)
    with pytest.raises(BolusError, match="closed surface"):
        make_shell(*icosphere(2, 40.0), 5.0, 0.0, 1.0)
    V, F = grid(4, 4, 40.0)
    F[3] = F[3, ::-1]
    with pytest.raises(BolusError, match="not consistently oriented.*Recalculate"):
        make_shell(V, F, 5.0, 0.0, 1.0)
    with pytest.raises(BolusError, match="0 triangle"):
        make_shell(np.zeros((0, 3)), np.zeros((0, 3), dtype=int), 5.0, 0.0, 1.0)


def test_region_of_two_islands_gives_two_whole_pieces():
    """Two hemispheres 200 mm apart in one region: each island's rim is its own outer loop (not
    a hole of the other, whose channel would cut the second bolus away); two closed pieces,
    each of the analytic shell volume, and a warning that says so."""
    V, F = hemisphere(nlat=12, na=36)
    VV = np.r_[V, V + [200.0, 0.0, 0.0]]
    FF = np.r_[F, F + len(V)]
    sh = make_shell(VV, FF, 10.0, 0.0, 2.0)
    assert sh.holes == 0
    assert any("2 separate pieces" in w for w in sh.warnings)
    assert not any("removed" in w for w in sh.warnings)
    exact = 2.0 / 3.0 * math.pi * (70.0 ** 3 - 60.0 ** 3)
    vols = sorted(p.volume() for p in to_manifold(sh.V, sh.F).decompose())
    assert len(vols) == 2 and all(abs(v / exact - 1) < 0.03 for v in vols)  # the facets of 36 sectors


def test_too_many_grid_points_refused_with_a_choice():
    V, F = grid(2, 2, 2000.0)
    with pytest.raises(BolusError, match=r"million voxel faces.*choose a resolution of [0-9.]+ mm or coarser"):
        make_shell(V, F, 10.0, 0.0, 0.5)
    with pytest.raises(BolusError, match=r"million grid points.*choose a resolution of [0-9.]+ mm or coarser"):
        make_shell(V, F, 10.0, 0.0, 0.5, mesher="level_set")


BASE = height_field(lambda x, y: 0.002 * (x ** 2 + y ** 2), nx=6, ny=6, size=50.0)


@pytest.mark.parametrize("name", sorted(degenerate_variants(*BASE)))
def test_degenerate_input(name):
    V, F, says = degenerate_variants(*BASE)[name]
    if says is None:  # the needle: sound, a closed solid
        sh = make_shell(V, F, 5.0, 0.0, 1.25)
        rep = closed_report(sh.V, sh.F)
        assert rep["closed"] and np.isfinite(sh.V).all() and sh.volume_mm3 > 0
        return
    with pytest.raises(BolusError, match=says):
        make_shell(V, F, 5.0, 0.0, 1.25)


def test_progress_reports_stages():
    seen = []
    make_shell(*grid(4, 4, 40.0), 5.0, 0.0, 1.25, progress=lambda f, s: seen.append((f, s)))
    fr = [f for f, _ in seen]
    assert fr == sorted(fr) and fr[0] == 0.0 and fr[-1] == 1.0
    texts = {s for _, s in seen}
    assert {"distance field", "marching cubes", "checks"} <= texts


def curled_sheet(na=6, ny=12):
    """A sheet (z = 0, normals up) whose edge curls under (half a cylinder of radius 3 mm at
    x = 40) and runs back to x = 30 at z = -6, where its border ends: near that folded border
    the sign of the distance jumps between lattice points."""
    top = np.stack([np.arange(0.0, 40.0, 2.0), np.zeros(20)], 1)
    ang = np.linspace(np.pi / 2, -np.pi / 2, na + 1)
    curl = np.stack([40.0 + 3.0 * np.cos(ang), -3.0 + 3.0 * np.sin(ang)], 1)
    under = np.stack([np.arange(38.0, 29.0, -2.0), np.full(5, -6.0)], 1)
    prof = np.concatenate([top, curl, under])
    ys = np.linspace(0.0, 40.0, ny + 1)
    V = np.array([[x, y, z] for x, z in prof for y in ys])
    n = ny + 1
    F = []
    for i in range(len(prof) - 1):
        for j in range(ny):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            F += [[a, b, c], [a, c, d]]
    return V, np.array(F)


def test_field_bounds_agree_with_the_exact_field_at_a_folded_border():
    """Regression: the coarse-to-fine field trusted the Lipschitz bound of the SIGNED distance
    near an open border, where the sign jumps (ICT face's mouth corners at 1 mm: 4 lattice
    points on the wrong side).  Every lattice point must carry the exact field's sign."""
    import bolus_addon.core.solid.shell as S

    V, F = curled_sheet()
    t, c, res = 5.0, 0.0, 1.0
    skin = SkinDistance(V, F)
    g = S._Grid(V.min(axis=0) - t - 3 * res, V.max(axis=0) + t + 3 * res, res)
    rim_cap, band = 3 * g.sp.max(), t + 3 * g.sp.max() + skin.tri_rmax
    coarse = S._coarse_terms(skin, g, t, c, band)
    for lattice in (0, 1):
        f, n_exact = S._field_coarse_to_fine(skin, g, lattice, t, c, rim_cap, band, coarse, None, 0, 1)
        f = f[1:-1, 1:-1, 1:-1].ravel()  # drop the padding
        P = np.stack(np.meshgrid(*g.axes(lattice), indexing="ij"), -1).reshape(-1, 3)
        exact = skin.field(P, t, c, rim_cap)
        assert n_exact < len(P)
        assert np.array_equal(f > 0, exact > 0)


def test_narrow_band_field_is_exact_on_every_crossing_cube():
    """The levelled narrow band (core.solid.narrow_band) at the folded border of the curled
    sheet: every lattice point carries the exact field's sign (stored or guessed), every cube the
    exact surface crosses is handed to the mesher with its eight corners at the exact value,
    and far fewer points were evaluated or stored than the lattice has."""
    import bolus_addon.core.solid.shell as S
    from bolus_addon.core.solid.marching import CUBE_CORNERS, crossing_cubes
    from bolus_addon.core.solid.narrow_band import field_narrow_band

    V, F = curled_sheet()
    for t, c, res in ((5.0, 0.0, 0.5), (6.0, 1.0, 1.0)):
        skin = SkinDistance(V, F)
        g = S._Grid(V.min(axis=0) - t - 3 * res, V.max(axis=0) + t + 3 * res, res)
        rim_cap = 3 * g.sp.max()
        level = field_narrow_band(skin, g, t, c, rim_cap)
        f = level.dense()
        P = np.stack(np.meshgrid(*g.axes(0), indexing="ij"), -1).reshape(-1, 3)
        exact = skin.field(P, t, c, rim_cap).reshape(f.shape)
        assert np.array_equal(f > 0, exact > 0)
        want = crossing_cubes(np.pad(exact > 0, 1)) - 1
        cubes, vals, ex = level.cubes()
        key = lambda c: set(map(tuple, c.tolist()))
        assert len(want) > 100 and key(cubes) == key(want) and ex.all()
        corner = cubes[:, None, :] + CUBE_CORNERS[None]
        inl = np.all((corner >= 0) & (corner < np.array(f.shape)), axis=2)
        assert np.allclose(vals[inl], exact[tuple(corner[inl].T)], atol=1e-9, rtol=0)
        assert np.all(vals[~inl] == -1.0)
        assert level.evaluated_total < 0.5 * f.size and level.count < level.map.size


def test_hole_on_a_curved_region_cuts_only_its_channel():
    """A hole wrapping 60 degrees around a cylinder of radius 30 mm (a far from planar loop, like
    a nostril rim): the channel follows the surface's normals, so the shell stays one piece
    with one through-hole and the material beside the hole is kept (a prism along the loop's
    mean normal cuts the neighbouring shell away at the sides)."""
    from meshgen import cylinder_piece
    V, F = cylinder_piece(radius=30.0, angle=np.pi, length=100.0, na=24, nl=20)
    C = V[F].mean(axis=1)
    nrm = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    if np.einsum("ij,ij->", nrm[:, :2], C[:, :2]) < 0:
        F = F[:, ::-1].copy()
    ia, il = np.divmod(np.arange(len(F)) % (24 * 20), 20)
    keep = ~((ia >= 8) & (ia < 16) & (il >= 8) & (il < 12))
    from bolus_addon.core.mesh.topology import submesh
    Fk, ids = submesh(F, keep)
    V, F = V[ids], Fk
    sh = make_shell(V, F, 8.0, 0.0, 2.0)
    rep = closed_report(sh.V, sh.F)
    assert sh.holes == 1 and rep["closed"] and rep["components"] == 1 and rep["genus"] == 1
    mid = np.pi / 2  # the hole spans 60..120 degrees, z 40..60
    u = np.array([np.cos(mid), np.sin(mid), 0.0])
    assert np.isinf(ray_thickness(sh.V, sh.F, [25.0 * u + [0, 0, 50.0]], [u], 30.0))[0]
    # beside the hole (at 50 degrees, 10 degrees from its edge) the wall is whole
    w = np.array([np.cos(np.radians(50)), np.sin(np.radians(50)), 0.0])
    d = ray_thickness(sh.V, sh.F, [25.0 * w + [0, 0, 50.0]], [w], 30.0)
    assert d[0] == pytest.approx(5.0, abs=0.3)
    assert sh.thickness_min >= 0.95 * 8.0


def ict_region(centre, radius):
    """Whole triangles of the example face (cm -> mm) within radius of centre."""
    from pathlib import Path

    from bolus_addon.core.mesh.objfile import load_obj
    from bolus_addon.core.mesh.topology import submesh
    V, F, _ = load_obj(Path(__file__).resolve().parents[3] / "assets" / "ict_face_narrow.obj", 10.0)
    keep = np.all(np.linalg.norm(V[F] - np.asarray(centre), axis=2) < radius, axis=1)
    Fr, ids = submesh(F, keep)
    return V[ids], Fr


def test_shell_arrays_read_back_unchanged():
    """Regression: the level set's output held coincident vertices that manifold3d collapses
    when the arrays are read back (as the part cutter does), pinching off crumbs: the nose
    tip's shell read back as 2 pieces and 4 triangles fewer.  The shell's arrays must be a
    fixed point of to_manifold / from_manifold."""
    V, F = ict_region([0.0, 0.91, 130.88], 15.0)  # the nose tip
    sh = make_shell(V, F, 6.0, 0.0, 1.5)
    M = to_manifold(sh.V, sh.F)
    assert M.num_tri() == len(sh.F) and len(M.decompose()) == 1
    assert closed_report(sh.V, sh.F)["components"] == 1


def test_mouth_corner_region_builds():
    """The folded mouth corner of the example face (where the sign of the distance jumps)."""
    V, F = ict_region([-14.9, -34.5, 108.2], 20.0)
    sh = make_shell(V, F, 10.0, 0.0, 1.0)
    assert closed_report(sh.V, sh.F)["closed"] and np.isfinite(sh.thickness_min)


def test_thickness_rays_skip_inner_vertices_without_a_normal():
    """Regression: where the inner faces around a vertex cancel (a crease folded flat; seen at
    the mouth corner of the example face before the read-back clean-up) the ray direction was
    zero and ray_thickness refused the whole measurement ("direction 1082 is zero")."""
    import bolus_addon.core.solid.shell as S
    from meshgen import box

    skin = SkinDistance(*grid(10, 10, 100.0))
    Vb, Fb = box((20.0, 20.0, 10.0), n=2)
    Vb = Vb + [40.0, 40.0, 0.0]
    pillow = np.array([[44.0, 44.0, 5.0], [45.0, 44.0, 5.0], [44.0, 45.0, 5.0]])  # off every ray's path
    V = np.r_[Vb, pillow]
    F = np.r_[Fb, [[len(Vb), len(Vb) + 1, len(Vb) + 2], [len(Vb), len(Vb) + 2, len(Vb) + 1]]]
    C = V[F].mean(axis=1)
    side = np.where(C[:, 2] < 1e-9, SIDE_INNER, SIDE_OUTER).astype(np.int8)
    side[-2:] = SIDE_INNER  # the pillow's two faces: normals cancel at its three vertices
    th, rays, _ = S._measure_thickness(skin, to_manifold(Vb, Fb), V, F, side, 10.0, 0.0, 1.0)
    # 9 vertices with a normal and 10 triangle centroids (8 of the bottom, the pillow's 2; the one
    # of those facing up meets the top 5 mm away)
    assert rays["rays"] == 19 and rays["outer"] == 18
    assert np.isclose(th, 10.0).sum() == 17


def _checked_level_set(grid, f0, f1):
    """Manifold.level_set with a checked lookup (rounding, lattice test, count of calls off the
    lattices) on the padded lattices: the reference for shell_grid._level_set_fast (test only).  Returns (M, misses)."""
    F0 = array.array("d", np.ascontiguousarray(f0[1:-1, 1:-1, 1:-1]).tobytes())
    F1 = array.array("d", np.ascontiguousarray(f1[1:-1, 1:-1, 1:-1]).tobytes())
    n0, n1 = grid.shape0, grid.shape1
    s0y, s0z = n0[1] * n0[2], n0[2]
    s1y, s1z = n1[1] * n1[2], n1[2]
    lx, ly, lz = (float(x) for x in grid.lo)
    ix, iy, iz = (float(1.0 / x) for x in grid.sp)
    a0, b0, c0 = n0
    a1, b1, c1 = n1
    miss = [0]

    def f(x, y, z):
        u = (x - lx) * ix
        v = (y - ly) * iy
        w = (z - lz) * iz
        ru = round(u)
        rv = round(v)
        rw = round(w)
        if abs(u - ru) < 1e-4 and abs(v - rv) < 1e-4 and abs(w - rw) < 1e-4:
            if 0 <= ru < a0 and 0 <= rv < b0 and 0 <= rw < c0:
                return F0[ru * s0y + rv * s0z + rw]
            return -1.0
        u += 0.5
        v += 0.5
        w += 0.5
        ru = round(u)
        rv = round(v)
        rw = round(w)
        if abs(u - ru) < 1e-4 and abs(v - rv) < 1e-4 and abs(w - rw) < 1e-4:
            if 0 <= ru < a1 and 0 <= rv < b1 and 0 <= rw < c1:
                return F1[ru * s1y + rv * s1z + rw]
            return -1.0
        miss[0] += 1
        return -1.0

    M = m3.Manifold.level_set(f, list(grid.lo) + list(grid.hi), grid.res, 0.0, -1.0)
    return M, miss[0]


def test_fast_lookup_matches_the_checked_lookup():
    """The level set's lookup callback (three truncations) returns exactly the precomputed
    lattice values: same mesh as a lookup that rounds, tests the lattice and counts misses."""
    import bolus_addon.core.solid.shell as S
    from bolus_addon.core.solid.manifold import from_manifold

    V, F = hemisphere(30.0, nlat=8, na=24)
    t, c, res = 6.0, 0.0, 1.5
    skin = SkinDistance(V, F)
    g = S._Grid(V.min(axis=0) - t - 3 * res, V.max(axis=0) + t + 3 * res, res)
    rim_cap, band = 3 * g.sp.max(), t + 3 * g.sp.max() + skin.tri_rmax
    coarse = S._coarse_terms(skin, g, t, c, band)
    f0, _ = S._field_coarse_to_fine(skin, g, 0, t, c, rim_cap, band, coarse, None, 0, 1)
    f1, _ = S._field_coarse_to_fine(skin, g, 1, t, c, rim_cap, band, coarse, None, 0, 1)
    M_ref, misses = _checked_level_set(g, f0, f1)
    V1, F1 = from_manifold(M_ref)
    V2, F2 = from_manifold(S._level_set_fast(g, f0, f1))
    assert misses == 0 and len(F1) > 1000
    assert np.array_equal(V1, V2) and np.array_equal(F1, F2)


def test_solid_touching_the_first_box_is_built_again_on_the_full_box(monkeypatch):
    """The level set first runs in the skin's box swept along its normals; a solid that touches
    that box (cut flat by it) is rebuilt on the full box: same solid as the full box gives."""
    import bolus_addon.core.solid.shell as S

    V, F = hemisphere(30.0, nlat=8, na=24)
    ref = make_shell(V, F, 6.0, 0.0, 1.5)
    assert "box_retry" not in ref.stats
    monkeypatch.setattr(S, "_tight_box", lambda skin, t, res: (skin.V.min(axis=0), skin.V.max(axis=0)))
    sh = make_shell(V, F, 6.0, 0.0, 1.5)
    assert sh.stats.get("box_retry") is True
    assert sh.volume_mm3 == pytest.approx(ref.volume_mm3, rel=1e-3)
    assert closed_report(sh.V, sh.F)["closed"]


def dome_band(R=12.0, top_deg=35.0):
    """Hemisphere R (rim at z = 0) with the faces above polar angle top_deg removed: the cut
    follows whole faces, so the top border zigzags and is longer than the rim."""
    V, F = hemisphere(R, nlat=12, na=48)
    keep = V[F].mean(axis=1)[:, 2] < R * np.cos(np.radians(top_deg))
    from bolus_addon.core.mesh.topology import submesh
    Fk, ids = submesh(F, keep)
    return V[ids], Fk


def test_outer_loop_is_the_one_enclosing_most_area():
    """Regression: the outer border was taken as the longest loop; a dome band's zigzag top
    (96 vertices, longer than the 48-vertex rim) became the outer border and the rim a 'hole'
    that the cutter carved away (H5's dome: 37 mm^3 removed)."""
    V, F = dome_band()
    skin = SkinDistance(V, F)
    assert len(skin.loops) == 2
    assert np.abs(V[skin.loops[0], 2]).max() < 1e-9            # the rim at z = 0 is the outer loop
    assert skin.loop_lengths[1] > skin.loop_lengths[0]           # although the top is longer


@pytest.mark.parametrize("res", [1.0, 0.5])
def test_dome_with_a_smooth_top_hole_has_genus_one(res):
    """A dome band (R 12 mm, t 4 mm) whose top hole is cut along a ring: one solid with one hole
    through it.  (Cut along whole faces instead, the border zigzags in teeth smaller than a
    voxel: the rim wall is pleated and the level set leaves tiny tunnels there, genus 13 at 1 mm
    -- see the module docstring.)"""
    th = np.radians(np.linspace(90.0, 35.0, 12))
    V, F, _ = ring_surface(np.stack([12.0 * np.sin(th), 12.0 * np.cos(th)], 1), na=48, pole=False)
    sh = make_shell(V, F, 4.0, 0.0, res)
    rep = closed_report(sh.V, sh.F)
    assert sh.holes == 1 and rep["closed"] and rep["components"] == 1 and rep["genus"] == 1
    top = np.linalg.norm(sh.V[:, :2], axis=1) < 12.0 * np.sin(np.radians(35.0)) - 2 * res
    assert not top.any()  # nothing above the hole: it goes through


# ---------------------------------------------------------------- saw-tooth borders and the topology check
def _zigzag_dome():
    """A dome R 12 mm with its top cut away along whole triangles: the hole's border is a saw of
    triangles with two border edges (H5's repro, genus 13 at 1 mm before the ears were dropped)."""
    phi = np.linspace(0.0, 0.5 * math.pi, 13)[:-1]
    V, F, _ = ring_surface(np.c_[12.0 * np.cos(phi), 12.0 * np.sin(phi)], na=48, pole=True)
    P = V[F]
    N = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    if (np.einsum("ij,ij->i", N, P.mean(1)) < 0).mean() > 0.5:
        F = F[:, ::-1]
    keep = V[F].mean(axis=1)[:, 2] < 12.0 * math.cos(math.radians(35.0))
    used, inv = np.unique(F[keep], return_inverse=True)
    return V[used], inv.reshape(-1, 3)


def _border_edges_per_face(F):
    e = np.sort(np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    _, inv, cnt = np.unique(e, axis=0, return_inverse=True, return_counts=True)
    return (cnt[inv.ravel()] == 1).reshape(-1, 3).sum(axis=1)


def test_drop_border_ears_removes_the_saw_and_keeps_the_loops():
    from bolus_addon.core.mesh.boundary import boundary_loops
    from bolus_addon.core.solid.shell import drop_border_ears

    V, F = _zigzag_dome()
    assert (_border_edges_per_face(F) >= 2).sum() == 48  # one tooth per sector
    F2, dropped = drop_border_ears(F)
    assert dropped == 48 and len(F2) == len(F) - 48
    assert (_border_edges_per_face(F2) < 2).all()
    assert len(boundary_loops(F2)) == len(boundary_loops(F)) == 2
    # a smooth border (no ears) is left as it is
    F3, none = drop_border_ears(F2)
    assert none == 0 and np.array_equal(F3, F2)


@pytest.mark.parametrize("res", [1.0, 0.5])
def test_saw_tooth_hole_border_gives_one_tunnel(res):
    """The dome with the saw-tooth hole gives one solid of genus 1: either the mesher leaves no
    tunnel at the teeth, or the tunnels are found (topology check) and the shell is made again
    without the teeth, which a warning names."""
    V, F = _zigzag_dome()
    s = make_shell(V, F, 4.0, 0.0, res)
    r = closed_report(s.V, s.F)
    assert r["closed"] and r["components"] == 1 and r["genus"] == 1, r
    assert s.holes == 1 and not any("tunnel" in w for w in s.warnings), s.warnings
    dropped = s.stats.get("border_teeth_dropped", 0)
    assert dropped in (0, 48)
    assert (dropped == 48) == any("48 teeth" in w for w in s.warnings), s.warnings


def test_topology_warning_counts_extra_tunnels():
    """A disk region thickened should be a ball (Euler characteristic 2): a torus (0) is one
    tunnel too many, two balls (4) one piece too many; the ball itself is not warned."""
    from bolus_addon.core.mesh.boundary import surface_type
    from bolus_addon.core.solid.shell import _topology_warnings

    Vd, Fd = grid(6, 6)
    skin = SkinDistance(Vd, Fd)
    assert surface_type(Vd, Fd)["euler_characteristic"] == 1
    ball = m3.Manifold.sphere(5.0, 32)
    torus = m3.Manifold.revolve(m3.CrossSection.circle(1.0, 16).translate([4.0, 0.0]), 32)
    two = m3.Manifold.sphere(1.0, 16) + m3.Manifold.sphere(1.0, 16).translate([5.0, 0.0, 0.0])
    assert _topology_warnings(skin, ball) == []
    (w,) = _topology_warnings(skin, torus)
    assert "1 more tunnel" in w and "Euler characteristic 0, 2 expected" in w
    (w,) = _topology_warnings(skin, two)
    assert "1 fewer tunnel" in w and "Euler characteristic 4, 2 expected" in w


def _cube_with_fanned_top(apex):
    """A 10 mm cube whose top face is fanned from the vertex ``apex`` (3,) (the tiny or flat
    triangles marching cubes leaves near a lattice point): (V, F)."""
    import manifold3d as m3

    from bolus_addon.core.solid.manifold import from_manifold

    V, F = from_manifold(m3.Manifold.cube([10.0, 10.0, 10.0]))
    top = [i for i, f in enumerate(F) if np.all(V[f, 2] == 10.0)]
    ring = list(np.nonzero(V[:, 2] == 10.0)[0])
    c = len(V)
    V = np.vstack([V, apex])
    ring = sorted(ring, key=lambda v: np.arctan2(V[v, 1] - 5, V[v, 0] - 5))  # counter-clockwise seen from +z
    F = np.vstack([np.delete(F, top, axis=0), [[ring[k], ring[(k + 1) % 4], c] for k in range(4)]])
    return V, F


def test_clean_collapses_short_edges_and_the_mesher_merges_coplanar_fans():
    """Cleaning collapses a vertex closer than SLIVER_TOL_MM to a corner (a sliver) and keeps a
    vertex a hair off the plane but far from every other (merging such near-planar fans to a
    micrometre also merged triangles across the skin's folds, and the tilted ones crossed each
    other); the mesher's coplanar merge (COPLANAR_TOL_MM) takes a fan that lies in its plane and
    keeps the hair-off one; the volume stays."""
    from bolus_addon.core.solid.manifold import from_manifold, to_manifold
    from bolus_addon.core.solid.grid import COPLANAR_TOL_MM
    from bolus_addon.core.solid.shell_checks import SLIVER_TOL_MM, _clean

    cases = {"flat": ([5.0, 5.0, 10.0], 9, 8), "sliver": ([SLIVER_TOL_MM / 10, 0.0, 10.0], 8, 8),
             "tent": ([5.0, 5.0, 10.0 + SLIVER_TOL_MM / 10], 9, 9)}
    for name, (apex, cleaned, merged) in cases.items():
        V, F = _cube_with_fanned_top(apex)
        M = to_manifold(V, F)
        assert M.num_vert() == 9, name
        M2, V2, F2, dropped, pieces = _clean(M)
        assert len(V2) == cleaned and pieces == 1 and not dropped, name
        # the tent's pyramid over the 10 x 10 mm top stays; the welded sliver's corner moves to
        # the mean of the two, 5e-5 mm
        tent = 100.0 * (apex[2] - 10.0) / 3.0
        assert M2.volume() == pytest.approx(1000.0 + tent, abs=1e-3), name
        assert len(from_manifold(M.simplify(COPLANAR_TOL_MM))[0]) == merged, name


@pytest.mark.parametrize("name", ["makehuman_elbow_patch.obj", "makehuman_knee_patch.obj"])
def test_a_sleeve_keeps_both_ends_open_and_whole(name, monkeypatch):
    """A ring of skin round an elbow or a knee: its two loops span about the same membrane and
    the skin stands across it (mean |n . m| under ACROSS_COS), so both are ends, not holes: the sleeve is one closed ring (genus 1) of the full wall, its
    volume about area x thickness.  Taking the far end for a hole (the rule for a loop the
    outer one dwarfs) cuts a channel through the sleeve and loses material."""
    from paths import data_mesh
    from bolus_addon.core.mesh.objfile import load_obj
    import bolus_addon.core.solid.distance_field as DF

    V, F, _ = load_obj(data_mesh(name), 100.0)  # dm -> mm
    skin = SkinDistance(V, F)
    assert len(skin.loops) == 2 and len(skin.end_loops) == 1 and not skin.hole_loops
    t, res = 8.0, 2.0
    sh = make_shell(V, F, t, 0.0, res, time_limit_s=0)
    rep = closed_report(sh.V, sh.F)
    assert sh.holes == 0 and rep["closed"] and rep["components"] == 1 and rep["genus"] == 1
    assert 0.85 * skin.area * t < sh.volume_mm3 < 1.3 * skin.area * t
    monkeypatch.setattr(DF, "HOLE_FRACTION", 1e9)  # every loop but the outer one a hole
    cut = make_shell(V, F, t, 0.0, res, time_limit_s=0)
    assert cut.holes == 1 and cut.volume_mm3 < 0.99 * sh.volume_mm3


def test_thickness_mean_stays_between_min_and_max():
    # eleven equal rays: numpy's pairwise sum puts their mean one ulp below each of them
    th = np.full(11, 1.0000000128746032)
    assert th.mean() < th.min()  # the rounding the figures must not show
    from bolus_addon.core.solid.shell import _thickness_figures
    warnings: list = []
    tmin, tmean, tmax = _thickness_figures(th, {"rays": 11, "outer": 11}, np.zeros(3), 1.0, warnings)
    assert tmin <= tmean <= tmax
    assert tmean == pytest.approx(1.0000000128746032, abs=1e-15)
    assert warnings == []
