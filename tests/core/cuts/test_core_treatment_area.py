"""core.treatment_area / core.geodesic / core.visibility: the treatment area around a point."""
from __future__ import annotations

import numpy as np
import pytest

import meshgen
from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.geodesic import closest_point_on_mesh, geodesic_distance
from bolus_addon.core.mesh.topology import MeshTopology, face_areas
from bolus_addon.core.cuts.treatment_area import cavity_faces, treatment_area
from bolus_addon.core.cuts.visibility import openness


def plane(n=60, size=120.0, jitter=0.3):
    V, F = meshgen.grid(n, n, size=size, jitter=jitter, rng=1)
    return V - [size / 2, size / 2, 0.0], F


def pocket(depth=20.0, r_hole=6.0, R=70.0, na=48):
    """A flat plate (z = 0, normals +z) with a round pocket of radius r_hole and the given depth
    at the origin (a nostril-like blind hole).  Returns V, F, in_pocket (m,) bool faces below z = 0."""
    prof = [(r, 0.0) for r in np.linspace(R, r_hole, 22)]
    prof += [(r_hole, z) for z in np.linspace(0.0, -depth, 14)[1:]]
    prof += [(r, -depth) for r in np.linspace(r_hole, 1.5, 4)[1:]]
    V, F, _ = meshgen.ring_surface(np.array(prof), na=na, pole=False)
    V = np.vstack([V, [0.0, 0.0, -depth]])
    last = (len(prof) - 1) * na
    F = np.vstack([F, [[last + j, last + (j + 1) % na, len(V) - 1] for j in range(na)]])
    if np.cross(V[F[0, 1]] - V[F[0, 0]], V[F[0, 2]] - V[F[0, 0]])[2] < 0:  # plate normals +z
        F = F[:, ::-1]
    return V, F, V[F].mean(axis=1)[:, 2] < -1e-9


def border_vertices(a):
    """Vertices on the border of the selected area (not on the input mesh's border)."""
    topo = MeshTopology(a.V, a.F[a.selected])
    return np.nonzero(topo.boundary_vertices)[0]


# ------------------------------------------------------------------ distance
def test_distance_on_a_plane_is_exact():
    V, F = plane()
    q, f, _ = closest_point_on_mesh(V, F, [0.3, 0.2, 5.0])
    assert np.allclose(q, [0.3, 0.2, 0.0])
    d = geodesic_distance(V, F, q, f)
    exact = np.linalg.norm(V - q, axis=1)
    assert np.abs(d - exact).max() < 1e-6


def test_distance_on_a_sphere_cap_against_great_circles():
    V, F = meshgen.spherical_cap(100.0, 60.0, 5)
    q, f, _ = closest_point_on_mesh(V, F, [1.0, 2.0, 101.0])
    d = geodesic_distance(V, F, q, f, max_mm=60.0)
    u = V / np.linalg.norm(V, axis=1)[:, None]
    exact = 100.0 * np.arccos(np.clip(u @ (q / np.linalg.norm(q)), -1, 1))
    near = exact < 50.0
    assert np.abs(d[near] - exact[near]).max() < 0.1  # 3.8 mm triangles
    assert np.isinf(d[exact > 62.0]).all()  # beyond max_mm: not reached


def test_distance_is_inf_on_another_piece():
    V, F = plane(10, 50.0, 0.0)
    V2 = np.vstack([V, V + [0, 0, 10.0]])
    F2 = np.vstack([F, F + len(V)])
    d = geodesic_distance(V2, F2, V[F[0]].mean(axis=0), 0)
    assert np.isfinite(d[: len(V)]).all() and np.isinf(d[len(V):]).all()


# ---------------------------------------------------------------- the area
def test_area_on_a_plane_is_a_disk_with_a_smooth_border():
    V, F = plane()
    r = 30.0
    a = treatment_area(V, F, [1.0, -2.0, 3.0], r, exclude_cavities=False)
    p = np.array([1.0, -2.0, 0.0])
    assert np.allclose(a.source_point, p) and a.centre_distance_mm == pytest.approx(3.0)
    assert a.area_mm2 == pytest.approx(np.pi * r * r, rel=0.01)
    b = border_vertices(a)
    dist = np.linalg.norm(a.V[b] - p, axis=1)
    # the level line: every border vertex at the radius (a staircase of whole faces is off by up to an edge, 2 mm);
    # a cut point snapped onto a vertex (no slivers) moves by at most a quarter of a 2-3 mm edge along it
    assert np.abs(dist - r).max() < 0.25
    assert np.quantile(np.abs(dist - r), 0.9) < 0.05
    new = b[b >= len(V)]
    assert len(new) > 0.8 * len(b)  # the border runs through the faces, on new vertices
    assert np.abs(np.linalg.norm(a.V[new] - p, axis=1) - r).max() < 0.05  # chord: d is linear along an edge
    # new vertices lie on the surface, inside their parent triangle
    assert np.abs(a.V[len(V):, 2]).max() < 1e-12
    assert np.allclose((a.vw[:, :, None] * V[a.vsrc]).sum(axis=1), a.V)
    assert a.holes == 0 and a.cavity_area_mm2 == 0.0 and a.warnings == []


def test_faces_away_from_the_border_are_unchanged():
    V, F = plane()
    a = treatment_area(V, F, [0.0, 0.0, 0.0], 25.0, exclude_cavities=False)
    np.testing.assert_array_equal(a.V[: len(V)], V)
    kept = ~a.split
    assert kept.sum() > 0.9 * len(F)
    C = V[F].mean(axis=1)
    # every input face whose corners are all farther than an edge (2 mm) from the circle is kept as it was
    far = np.abs(np.linalg.norm(V[F], axis=2) - 25.0).min(axis=1) > 2.5
    assert not a.split[far].any()
    unchanged_rows = np.isin(a.parent, np.nonzero(~a.split)[0])
    np.testing.assert_array_equal(a.F[unchanged_rows], F[a.parent[unchanged_rows]])
    assert np.all(np.linalg.norm(C[a.parent[a.selected]], axis=1) < 25.0 + 2.0)


def test_area_on_a_sphere_cap():
    R, r = 100.0, 40.0
    V, F = meshgen.spherical_cap(R, 60.0, 5)
    a = treatment_area(V, F, [0.0, 0.0, 120.0], r, exclude_cavities=False, max_cursor_mm=25.0)
    exact = 2 * np.pi * R * R * (1 - np.cos(r / R))  # the spherical cap of geodesic radius r
    assert a.area_mm2 == pytest.approx(exact, rel=0.01)
    b = border_vertices(a)
    u = a.V[b] / np.linalg.norm(a.V[b], axis=1)[:, None]
    src = a.source_point / np.linalg.norm(a.source_point)
    assert np.abs(R * np.arccos(np.clip(u @ src, -1, 1)) - r).max() < 0.3


# ------------------------------------------------------------------ cavities
def test_a_pocket_is_a_cavity_and_a_hole_of_the_area():
    V, F, in_pocket = pocket()
    a = treatment_area(V, F, [20.0, 0.0, 0.0], 45.0)
    assert a.holes == 1
    assert a.cavity_area_mm2 > 0 and 0 < a.cavity_fraction < 0.2
    C = a.V[a.F].mean(axis=1)
    # nothing deep in the pocket is selected, nothing on the plate is a cavity
    assert not (a.selected & (C[:, 2] < -10.0)).any()
    assert not (a.cavity & (C[:, 2] > -1e-9)).any()
    deep = (C[:, 2] < -10.0) & (a.distance[a.F].max(axis=1) < 45.0)  # the far side of the bottom is beyond r
    assert deep.sum() > 500 and a.cavity[deep].all()
    # the cavity border is cut through the faces: new vertices on the pocket's wall (radius 6)
    b = border_vertices(a)
    wall = b[a.V[b, 2] < -1e-9]
    assert len(wall) >= 24
    assert np.abs(np.linalg.norm(a.V[wall, :2], axis=1) - 6.0).max() < 0.02  # on the 48-gon tube's faces
    # without cavities the pocket's faces within the radius are in the area
    a2 = treatment_area(V, F, [20.0, 0.0, 0.0], 45.0, exclude_cavities=False)
    assert a2.holes == 0 and (a2.selected & (a2.V[a2.F].mean(axis=1)[:, 2] < -5.0)).any()


def test_openness_of_a_plane_and_a_pocket():
    V, F, in_pocket = pocket()
    front, back = openness(V, F)
    A = face_areas(V, F)
    plate = ~in_pocket & (np.linalg.norm(V[F].mean(axis=1)[:, :2], axis=1) > 15.0)
    assert front[plate].min() > 0.9  # the open plate sees (nearly) the whole sky
    assert (A[in_pocket] * front[in_pocket]).sum() / A[in_pocket].sum() < 0.25
    cav = cavity_faces(V, F)
    assert not cav[plate].any() and cav[in_pocket].sum() > 0.5 * in_pocket.sum()


def test_a_closed_surface_wound_inside_out_is_measured_on_its_open_side():
    """A closed box with inward normals: every face's front sees only the inside (openness 0);
    the back is taken as the outside, with a warning, and nothing is a cavity."""
    V, F = meshgen.box((60.0, 60.0, 60.0), n=8)
    F = F if np.cross(V[F[0, 1]] - V[F[0, 0]], V[F[0, 2]] - V[F[0, 0]]) @ (V[F[0]].mean(0) - V.mean(0)) < 0 \
        else F[:, ::-1]  # inward
    a = treatment_area(V, F, V[F[0]].mean(axis=0), 20.0)
    assert a.cavity_area_mm2 == 0.0 and a.area_mm2 > 0
    assert any("normals point into the body" in w for w in a.warnings)


def test_warnings_at_the_mesh_border_and_for_a_small_mesh():
    V, F = plane(20, 60.0, 0.0)
    a = treatment_area(V, F, [25.0, 0.0, 0.0], 20.0, exclude_cavities=False)
    assert any("reaches the border of the mesh" in w for w in a.warnings)
    b = treatment_area(V, F, [0.0, 0.0, 0.0], 100.0, exclude_cavities=False)
    assert b.selected.all() and not b.split.any() and b.area_mm2 == pytest.approx(3600.0)
    assert any("whole connected surface lies within 100 mm" in w for w in b.warnings)


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("radius", [0.0, -5.0, np.nan, np.inf])
def test_bad_radius(radius):
    V, F = plane(10, 50.0, 0.0)
    with pytest.raises(BolusError, match="radius must be a positive"):
        treatment_area(V, F, [0, 0, 0], radius)


def test_centre_far_from_the_surface():
    V, F = plane(10, 50.0, 0.0)
    with pytest.raises(BolusError, match=r"the centre \(3D cursor\) is 100.0 mm from the nearest point"):
        treatment_area(V, F, [0, 0, 100.0], 45.0)


def test_area_of_no_faces():
    V, F = plane(10, 50.0, 0.0)
    with pytest.raises(BolusError, match="no face lies within 0.01 mm"):
        treatment_area(V, F, V[F[50, 0]], 0.01, exclude_cavities=False)


def test_bad_centre():
    V, F = plane(10, 50.0, 0.0)
    with pytest.raises(BolusError, match="centre must be a finite 3D point"):
        treatment_area(V, F, [0, np.nan, 0], 10.0)


def test_degenerate_meshes():
    V, F = plane(12, 60.0, 0.0)
    centre = V[F[0]].mean(axis=0)
    for name, (V2, F2, must) in meshgen.degenerate_variants(V, F).items():
        if must is None:
            a = treatment_area(V2, F2, centre, 10.0)
            assert np.isfinite(a.V).all() and a.area_mm2 > 0, name
            with pytest.raises(BolusError):
                treatment_area(V2, F2, centre, 10.0, max_cursor_mm=-1.0)
        else:
            with pytest.raises(BolusError, match=must):
                treatment_area(V2, F2, centre, 10.0)
            if name == "nonmanifold":  # the distance itself is sound there (the front crosses the edge)
                assert np.isfinite(geodesic_distance(V2, F2, centre, 0)[: len(V)]).all()
            else:
                with pytest.raises(BolusError, match=must):
                    geodesic_distance(V2, F2, centre, 0)
            if name in ("nan", "inf", "coincident", "collinear"):
                with pytest.raises(BolusError, match=must):
                    cavity_faces(V2, F2)
            if name in ("nan", "inf"):
                with pytest.raises(BolusError, match=must):
                    openness(V2, F2)
                with pytest.raises(BolusError, match=must):
                    closest_point_on_mesh(V2, F2, centre)


def test_defects_far_from_the_area_do_not_matter():
    """A zero-area triangle and a non-manifold fin 50 mm away from a 10 mm area: computed as without them;
    the same defects near the cursor are refused naming the mesh's own vertex indices."""
    V, F = plane(30, 120.0, 0.0)
    far = int(np.argmin(np.linalg.norm(V[F].mean(axis=1) - [50.0, 0.0, 0.0], axis=1)))  # interior, x ~ 50 mm
    a, b, c = (int(x) for x in F[far])
    n = len(V)
    V2 = np.vstack([V, V[a][None], V[a] + [0.0, 0.0, 4.0]])
    F2 = np.vstack([F, [[a, b, n]], [[a, b, n + 1]]])  # zero-area (coincident), and a third face on edge a-b
    ref = treatment_area(V, F, [-20.0, 0.0, 0.0], 10.0)
    got = treatment_area(V2, F2, [-20.0, 0.0, 0.0], 10.0)
    assert got.area_mm2 == pytest.approx(ref.area_mm2, rel=1e-12)
    with pytest.raises(BolusError, match=f"zero-area.*vertices {a}, {b}, {n}"):
        treatment_area(V2, F2, V[a] + [-2.0, 0.0, 0.0], 10.0)
    with pytest.raises(BolusError, match="non-manifold edge"):
        treatment_area(V2, np.vstack([F, [[a, b, n + 1]]]), V[a] + [-2.0, 0.0, 0.0], 10.0)


def test_openness_of_zero_area_and_needle_triangles_is_sound():
    V, F = plane(12, 60.0, 0.0)
    for name in ("coincident", "collinear", "needle"):
        V2, F2, _ = meshgen.degenerate_variants(V, F)[name]
        front, back = openness(V2, F2)
        assert np.isfinite(front).all() and np.isfinite(back).all()
        assert front[len(F):].tolist() == [1.0] * (len(F2) - len(F)) or name == "needle"
        assert front[: len(F)].min() > 0.9  # the plane around them stays open
