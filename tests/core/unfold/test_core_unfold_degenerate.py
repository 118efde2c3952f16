"""Degenerate input to every public function of the unfolding core:
coincident vertices, collinear (zero-area) and needle triangles, NaN/inf, non-manifold
edges, vertices in no triangle, bad positions.  Each gives a `BolusError` naming the
problem and where, or a sound (finite, documented) result."""
import numpy as np
import pytest
from meshgen import degenerate_variants, grid, height_field

from bolus_addon.core.errors import BolusError
from bolus_addon.core.unfold.initial_unfolding import conformal_unfolding, initial_unfolding
from bolus_addon.core.unfold.measures import curvature_sums, length_area_errors, polygon_area_error, polygon_errors
from bolus_addon.core.unfold.overlap import signed_areas
from bolus_addon.core.unfold.refine import refine_lengths_l1
from bolus_addon.core.unfold.relax import relax_explicit, relax_lbfgs
from bolus_addon.core.unfold.springs import build_springs, spring_energy
from bolus_addon.core.mesh.topology import MeshTopology
from bolus_addon.core.unfold.unfold import assemble_pattern, iter_unfold_patches, unfold_patch


def _bowl():
    """A gently curved 8 x 8 patch; triangle 0's edge (a, b) lies on the boundary (y = min),
    so meshgen's needle triangle hangs off the boundary and the mesh stays a manifold disk."""
    return height_field(lambda x, y: (x**2 + y**2) / 300.0, nx=8, ny=8)


V0, F0 = _bowl()
VARIANTS = degenerate_variants(V0, F0)
REFUSED = [k for k, v in VARIANTS.items() if v[2] is not None]


def _topo_calls(V, F):
    return {
        "unfold_patch": lambda: unfold_patch(V, F),
        "unfold_patch greedy, no relaxation": lambda: unfold_patch(V, F, start="greedy", relax=False),
        "iter_unfold_patches": lambda: list(iter_unfold_patches(V, F, np.zeros(len(F), dtype=int))),
        "initial_unfolding": lambda: initial_unfolding(MeshTopology(V, F)),
        "conformal_unfolding": lambda: conformal_unfolding(MeshTopology(V, F)),
        "build_springs": lambda: build_springs(MeshTopology(V, F)),
        "curvature_sums": lambda: curvature_sums(MeshTopology(V, F)),
    }


@pytest.mark.parametrize("case", REFUSED)
@pytest.mark.parametrize("call", list(_topo_calls(V0, F0)))
def test_degenerate_patches_are_refused_by_name(case, call):
    """coincident / collinear: 'zero-area triangle ... (vertices i, j, k)'; nan / inf: 'vertex
    c'; nonmanifold: 'non-manifold edge ... between vertices p and q'."""
    V, F, say = VARIANTS[case]
    with pytest.raises(BolusError, match=say) as info:
        _topo_calls(V, F)[call]()
    msg = str(info.value)
    if case in ("coincident", "collinear"):
        a, b = F[-1][:2]  # the added triangle is named with its corners
        assert f"triangle {len(F) - 1} (vertices {a}, {b}" in msg
    if case == "nonmanifold":
        p, q = sorted(F[-1][:2].tolist())
        assert f"between vertices {p} and {q}" in msg


def test_needle_triangle_unfolds_soundly():
    """A 0.01 degree needle on the boundary: finite springs and starts, a flip-free pattern
    with the figures of the patch without it (the needle adds almost no length or area)."""
    V, F, _ = VARIANTS["needle"]
    topo = MeshTopology(V, F)
    springs = build_springs(topo)
    assert np.isfinite(springs.stiffness).all() and np.isfinite(springs.rest).all()
    for UV in (initial_unfolding(topo), conformal_unfolding(topo)):
        assert np.isfinite(UV).all()
    u = unfold_patch(V, F)
    base = unfold_patch(V0, F0)
    assert np.isfinite(u.UV).all() and u.flipped == 0 and u.overlaps == 0 and not u.warnings
    assert (signed_areas(u.UV, u.F) > 0).all()
    assert u.EL == pytest.approx(base.EL, abs=0.002) and u.EA == pytest.approx(base.EA, abs=0.002)
    dd = curvature_sums(topo)
    assert np.isfinite(dd).all() and dd == pytest.approx(curvature_sums(MeshTopology(V0, F0)))


def _pattern_for(V, F):
    """A flat pattern of the sound bowl with the extra vertices of a variant placed on it."""
    UV = conformal_unfolding(MeshTopology(V0, F0))
    extra = len(V) - len(V0)
    return np.r_[UV, UV[F0[0, 1]] + np.zeros((extra, 2))]


@pytest.mark.parametrize("case", ["coincident", "collinear", "needle", "nonmanifold"])
def test_measures_are_sound_on_degenerate_triangles(case):
    """EL / EA (eqs. 3-30, 3-31) are sums: a zero-area, needle or third triangle on an edge is
    measured like any other and the result is finite; a zero-area source triangle adds
    nothing to sum A0, so laid on a zero-area pattern triangle it leaves EA unchanged."""
    V, F, _ = VARIANTS[case]
    UV = _pattern_for(V, F)
    el, ea = length_area_errors(V, F, UV)
    assert np.isfinite([el, ea]).all() and el > 0 and ea > 0
    per = polygon_errors(V, F.ravel(), UV, F.ravel(), np.full(len(F), 3))[None]
    assert per[:2] == (pytest.approx(el, rel=1e-12), pytest.approx(ea, rel=1e-12))
    if case == "coincident":  # the new vertex sits on b in 3D, and on b in the pattern
        assert ea == pytest.approx(length_area_errors(V0, F0, UV[: len(V0)])[1], rel=1e-12)


@pytest.mark.parametrize("case", ["coincident", "collinear"])
def test_polygon_area_ratio_of_a_zero_area_polygon_is_refused_by_name(case):
    V, F, _ = VARIANTS[case]
    UV = _pattern_for(V, F)
    with pytest.raises(BolusError, match=rf"no area .*polygon {len(F) - 1}\b"):
        polygon_area_error(V, F.ravel(), UV, F.ravel(), np.full(len(F), 3))
    ok = polygon_area_error(V0, F0.ravel(), UV[: len(V0)], F0.ravel(), np.full(len(F0), 3))
    assert np.isfinite(ok).all()


@pytest.mark.parametrize("case", ["nan", "inf"])
def test_measures_refuse_non_finite_skin_and_pattern(case):
    V, F, say = VARIANTS[case]
    UV = _pattern_for(V0, F0)
    for call in (lambda: length_area_errors(V, F, UV),
                 lambda: polygon_errors(V, F.ravel(), UV, F.ravel(), np.full(len(F), 3)),
                 lambda: polygon_area_error(V, F.ravel(), UV, F.ravel(), np.full(len(F), 3))):
        with pytest.raises(BolusError, match=say):
            call()
    bad = UV.copy()
    bad[7, 1] = np.nan if case == "nan" else -np.inf
    for call in (lambda: length_area_errors(V0, F0, bad),
                 lambda: polygon_errors(V0, F0.ravel(), bad, F0.ravel(), np.full(len(F0), 3))):
        with pytest.raises(BolusError, match=r"pattern has 1 non-finite .*vertex 7"):
            call()


def test_measures_refuse_no_area_and_wrong_shapes():
    V, F = grid(3, 3)
    with pytest.raises(BolusError, match="no area"):
        length_area_errors(np.zeros_like(V), F, V[:, :2])
    with pytest.raises(BolusError, match=r"shape \(16, 2\)"):
        length_area_errors(V, F, V[:5, :2])
    with pytest.raises(BolusError, match="outside the vertex array"):
        length_area_errors(V, np.r_[F, [[0, 1, 99]]], V[:, :2])


def test_vertices_in_no_triangle():
    """unfold_patch leaves them out (vert_origin in the caller's indices); the starts, which
    take a topology, refuse them by name (the conformal system would be singular)."""
    V, F = _bowl()
    Vx = np.r_[[[500.0, 500.0, 0.0]], V]  # vertex 0 in no triangle
    u = unfold_patch(Vx, F + 1)
    ref = unfold_patch(V, F)
    np.testing.assert_array_equal(u.vert_origin, ref.vert_origin + 1)
    np.testing.assert_allclose(u.UV, ref.UV, atol=1e-9)
    for start in (conformal_unfolding, initial_unfolding):
        with pytest.raises(BolusError, match=r"1 vertex\(es\) in no triangle, e.g. vertex 0"):
            start(MeshTopology(Vx, F + 1))


def test_minimisers_refuse_bad_positions_by_name():
    V, F = grid(6, 6)
    topo = MeshTopology(V, F)
    springs = build_springs(topo)
    UV = V[:, :2].copy()
    UV[3] = [np.nan, 0.0]
    kappa = topo.edge_face_count.astype(float)
    for call in (lambda: relax_lbfgs(UV, springs), lambda: relax_explicit(UV, springs, np.ones(len(V))),
                 lambda: refine_lengths_l1(UV, springs, kappa)):
        with pytest.raises(BolusError, match=r"non-finite .*vertex 3"):
            call()
    with pytest.raises(BolusError, match=r"n >= 49"):
        relax_lbfgs(V[:5, :2], springs)
    with pytest.raises(BolusError, match="positive"):
        relax_explicit(V[:, :2], springs, np.zeros(len(V)))
    e, g = spring_energy(V[:, :2].ravel(), springs, len(V))  # the flat grid is the rest state
    assert e == pytest.approx(0.0, abs=1e-20) and np.abs(g).max() < 1e-9


def test_unfold_patch_refuses_small_empty_and_unknown():
    V, F = grid(3, 3)
    with pytest.raises(BolusError, match="too small"):
        unfold_patch(V, F[:2])
    with pytest.raises(BolusError, match="too small"):
        unfold_patch(V, np.zeros((0, 3), dtype=int))
    with pytest.raises(BolusError, match="unknown start"):
        unfold_patch(V, F, start="magic")
    with pytest.raises(BolusError, match=r"triangles must be an \(m, 3\) array"):
        unfold_patch(V, F[:, :2])
    with pytest.raises(BolusError, match=r"0 triangle\(s\); at least 1"):
        build_springs(MeshTopology(V, np.zeros((0, 3), dtype=int)))


def test_assemble_refuses_mismatched_patches():
    V, F = grid(4, 4)
    labels = np.zeros(len(F), dtype=int)
    u = unfold_patch(V, F)
    with pytest.raises(BolusError, match="nothing to lay out"):
        assemble_pattern(F, -np.ones(len(F), dtype=int), [])
    with pytest.raises(BolusError, match="2 unfolded patches for 1 patch labels"):
        assemble_pattern(F, labels, [u, u])
    with pytest.raises(BolusError, match="patch labels for"):
        assemble_pattern(F, labels[:-1], [u])
    with pytest.raises(BolusError, match="patch labels for"):
        list(iter_unfold_patches(V, F, labels[:-1]))
