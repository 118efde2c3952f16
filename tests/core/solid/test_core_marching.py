"""The sparse marching-cubes mesher on fields with known surfaces (closed, genus, volume, placement)."""
import numpy as np
import pytest

from bolus_addon.core.solid.manifold import closed_report, from_manifold
from bolus_addon.core.solid.marching import crossing_cubes, marching_cubes, marching_manifold


def _lattice(origin, spacing, shape):
    ax = [origin[a] + np.arange(shape[a]) * spacing[a] for a in range(3)]
    return np.meshgrid(*ax, indexing="ij")


def test_ellipsoid_is_closed_and_holds_its_volume_on_an_anisotropic_lattice():
    o, sp = np.array([-20.0, -15.0, -25.0]), np.array([0.5, 0.4, 0.6])
    X, Y, Z = _lattice(o, sp, (80, 80, 90))
    a, b, c = 12.0, 8.0, 15.0
    f = 1 - ((X - 2) / a) ** 2 - ((Y + 1) / b) ** 2 - ((Z - 3) / c) ** 2
    M = marching_manifold(f, o, sp)
    V, F = from_manifold(M)
    rep = closed_report(V, F)
    assert rep["closed"] and rep["components"] == 1 and rep["genus"] == 0
    assert M.volume() == pytest.approx(4 / 3 * np.pi * a * b * c, rel=0.005)  # outward: positive volume
    # every vertex on the ellipsoid within the chord error of the lattice
    r = np.sqrt(((V[:, 0] - 2) / a) ** 2 + ((V[:, 1] + 1) / b) ** 2 + ((V[:, 2] - 3) / c) ** 2)
    assert np.abs(r - 1).max() * b < 0.05


def test_torus_has_genus_one_and_a_corner_on_the_surface_is_no_problem():
    o, sp = np.array([-16.0, -16.0, -6.0]), np.array([0.5, 0.5, 0.5])
    X, Y, Z = _lattice(o, sp, (65, 65, 25))
    f = 4.0 - np.sqrt((np.sqrt(X ** 2 + Y ** 2) - 10.0) ** 2 + Z ** 2)
    f[32, 12, 12] = 0.0  # lattice points exactly on the surface (this one and those at z = 0, |x| or |y| = 14)
    V, F = marching_cubes(f, o, sp)
    rep = closed_report(V, F)
    assert rep["closed"] and rep["genus"] == 1
    assert marching_manifold(f, o, sp).volume() == pytest.approx(2 * np.pi ** 2 * 10 * 16, rel=0.01)


def test_only_cubes_with_both_signs_are_marched():
    inside = np.zeros((5, 5, 5), dtype=bool)
    inside[2, 2, 2] = True
    cubes = crossing_cubes(inside, chunk=2)
    assert len(cubes) == 8 and {tuple(c) for c in cubes} == {(i, j, k) for i in (1, 2) for j in (1, 2) for k in (1, 2)}
    V, F = marching_cubes(np.full((4, 4, 4), -1.0), np.zeros(3), np.ones(3))
    assert V.shape == (0, 3) and F.shape == (0, 3)
    assert marching_manifold(np.full((4, 4, 4), -1.0), np.zeros(3), np.ones(3)).is_empty()
