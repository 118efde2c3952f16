"""Minimisers of the spring energy (seed 3.5, eqs. 3-23..3-29): relax.py."""
import pytest
from meshgen import spherical_cap

from bolus_addon.core.unfold.initial_unfolding import initial_unfolding
from bolus_addon.core.unfold.relax import relax_explicit, relax_lbfgs
from bolus_addon.core.analysis.saliency import lumped_mass
from bolus_addon.core.unfold.springs import build_springs, spring_energy
from bolus_addon.core.mesh.topology import MeshTopology


def test_both_integrators_lower_the_same_energy():
    V, F = spherical_cap(100.0, 45.0, 3)
    topo = MeshTopology(V, F)
    springs = build_springs(topo)
    UV0 = initial_unfolding(topo)
    e0, _ = spring_energy(UV0.ravel(), springs, topo.n)
    masses = lumped_mass(V, F)
    _, _, e_explicit = relax_explicit(UV0, springs, masses, max_iter=3000)
    _, _, e_lbfgs = relax_lbfgs(UV0, springs)
    assert e_lbfgs < e0 and e_explicit < e0
    assert e_lbfgs <= e_explicit * (1 + 1e-6)  # the minimiser reaches at least as low


@pytest.fixture
def ticking_clock(monkeypatch):
    """relax.py's clock advances 1 s per reading: every iteration is "0.5 s later"."""
    from types import SimpleNamespace

    import bolus_addon.core.unfold.relax as relax_mod

    clock = iter(range(10**6))
    monkeypatch.setattr(relax_mod, "time", SimpleNamespace(perf_counter=lambda: float(next(clock))))


def test_progress_is_reported_inside_long_minimisations(ticking_clock):
    V, F = spherical_cap(100.0, 60.0, 4)
    topo = MeshTopology(V, F)
    springs = build_springs(topo)
    UV0 = initial_unfolding(topo) * 1.3  # far from rest: many iterations
    seen = []
    _, it, _ = relax_lbfgs(UV0, springs, max_iter=30, tol=0.0, progress=seen.append)
    assert it >= 5 and len(seen) >= it - 2
    assert all(0 < f <= 1 for f in seen) and seen == sorted(seen)


def test_relaxation_stops_when_asked():
    V, F = spherical_cap(100.0, 60.0, 3)
    topo = MeshTopology(V, F)
    springs = build_springs(topo)
    UV0 = initial_unfolding(topo) * 1.3
    asked = []
    _, it, _ = relax_lbfgs(UV0, springs, max_iter=500, tol=0.0, stop=lambda X, k: asked.append(k) or k >= 50)
    assert it == 50 and asked == [25, 50]


def test_explicit_integrator_reports_progress(ticking_clock):
    V, F = spherical_cap(100.0, 45.0, 2)
    topo = MeshTopology(V, F)
    seen = []
    relax_explicit(initial_unfolding(topo), build_springs(topo), lumped_mass(V, F), max_iter=1000, tol=0.0,
                   progress=seen.append)
    assert len(seen) >= 5 and seen == sorted(seen) and 0 < seen[0] and seen[-1] <= 1
