"""Degenerate input to the public core functions of the analysis modules:
topology, saliency, piece_advice, remesh_maps.  Each broken mesh gives a BolusError
that names the problem and where, or a sound (finite) result.  The unfolding, cut-line,
pattern and print modules test theirs in their own test files."""
import numpy as np
import pytest

from bolus_addon.core.errors import BolusError
from bolus_addon.core.unfold.piece_advice import piece_advice
from bolus_addon.core.analysis.saliency import analyse, cotangent_stiffness, lumped_mass, smooth_for_analysis
from bolus_addon.core.mesh.topology import MeshTopology, check_mesh
from meshgen import degenerate_variants, height_field

BASE = height_field(lambda x, y: 0.002 * (x**2 + y**2), nx=8, ny=8)
CASES = degenerate_variants(*BASE)


@pytest.mark.parametrize("name", sorted(CASES))
def test_check_mesh(name):
    V, F, says = CASES[name]
    if says is None or says == "non-manifold":
        check_mesh(V, F)
        if says:
            with pytest.raises(BolusError, match=says):
                check_mesh(V, F, manifold=True)
        return
    with pytest.raises(BolusError, match=says):
        check_mesh(V, F)


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("smoothing", [0.0, 5.0])
def test_analyse(name, smoothing):
    V, F, says = CASES[name]
    if says in (None, "non-manifold"):
        res = analyse(V, F, smoothing)
        assert np.isfinite(res.varpi).all() and np.isfinite(res.sum_varpi)
        # the needle and the fin are boundary / non-manifold: flattenability 0 there (eq. 4-1)
        assert res.varpi[len(BASE[0]):].max(initial=0.0) == 0.0
        clean = analyse(*BASE, smoothing)
        assert res.sum_varpi <= clean.sum_varpi * 1.5 + 1e-9
        return
    with pytest.raises(BolusError, match=says):
        analyse(V, F, smoothing)


@pytest.mark.parametrize("name", sorted(CASES))
def test_cotangent_stiffness_and_lumped_mass(name):
    V, F, says = CASES[name]
    if says in (None, "non-manifold"):
        K = cotangent_stiffness(V, F)
        assert np.isfinite(K.data).all()
        np.testing.assert_allclose(np.asarray(K.sum(axis=1)).ravel(), 0.0, atol=1e-6 * abs(K).max())
        M = lumped_mass(V, F)
        assert np.isfinite(M).all() and M.min() >= 0
        return
    with pytest.raises(BolusError, match=says):
        cotangent_stiffness(V, F)
    if says == "zero-area":  # zero-area triangles add no mass: sound
        M = lumped_mass(V, F)
        np.testing.assert_allclose(M.sum(), MeshTopology(*BASE).areas.sum(), rtol=1e-12)
    else:
        with pytest.raises(BolusError, match=says):
            lumped_mass(V, F)


@pytest.mark.parametrize("name", sorted(CASES))
def test_piece_advice(name):
    V, F, says = CASES[name]
    if says in (None, "non-manifold"):
        adv = piece_advice(V, F, EL=0.05)
        assert np.isfinite(adv.excess_rad) and np.isfinite(adv.deficit_rad)
        return
    with pytest.raises(BolusError, match=says):
        piece_advice(V, F, EL=0.05)


def test_smoothing_scale_refused():
    topo = MeshTopology(*BASE)
    for bad in (-1.0, np.nan, np.inf):
        with pytest.raises(BolusError, match="smoothing scale"):
            smooth_for_analysis(topo, bad)
