"""The fast paths of the unfolding's inner loop give the same numbers as the plain ones
(speed on hard patches without changing any pattern)."""
import numpy as np
import pytest
import scipy.sparse as sp
from meshgen import height_field, spherical_cap

from bolus_addon.core.unfold.relax import FACTOR_EPS
from bolus_addon.core.unfold.springs import (
    Springs,
    _laplacian_general,
    area_terms,
    build_springs,
    laplacian_with_shift,
    spring_energy,
    stiffness_laplacian,
)
from bolus_addon.core.mesh.topology import MeshTopology


def _same_csc(A, B):
    assert A.format == B.format == "csc"
    np.testing.assert_array_equal(A.indptr, B.indptr)
    np.testing.assert_array_equal(A.indices, B.indices)
    np.testing.assert_array_equal(A.data, B.data)  # bit for bit, not approximately


def _springs_variants():
    V, F = spherical_cap(100.0, 60.0, 3)
    base = build_springs(MeshTopology(V, F))
    rng = np.random.default_rng(0)
    nt = base.n_tension
    out = {"as built": base.stiffness}
    st = base.stiffness.copy()
    st[nt:] = 0.0  # the refinement: crossed springs off (explicit zeros in the COO path)
    out["crossed off"] = st
    out["random"] = base.stiffness * rng.uniform(0.1, 10.0, len(base.stiffness))
    st = rng.uniform(0.0, 1.0, len(base.stiffness))
    st[::7] = 0.0
    out["some zero"] = st
    return base, len(V), out


@pytest.mark.parametrize("which", ["as built", "crossed off", "random", "some zero"])
def test_laplacian_pattern_path_equals_scipy_path(which):
    base, n, variants = _springs_variants()
    s = Springs(base.ends, base.rest, variants[which], base.n_tension, base.contour_edges, base.contour_rest,
                base.contour_stiffness)
    _same_csc(stiffness_laplacian(s, n), _laplacian_general(s, n))
    # relax's preconditioner: K + eps I with eps from K's diagonal
    K = _laplacian_general(s, n)
    eps = FACTOR_EPS * float(np.abs(K.diagonal()).mean())
    shifted, diag = laplacian_with_shift(s, n, lambda d: FACTOR_EPS * float(np.abs(d).mean()))
    _same_csc(shifted, (K + eps * sp.identity(n, format="csc")).tocsc())
    np.testing.assert_array_equal(np.abs(diag), np.abs(K.diagonal()))


def test_three_springs_on_one_pair_take_the_general_path():
    """Their sum depends on its order, so the pattern path steps aside (and gives the same K)."""
    ends = np.array([[0, 1], [1, 0], [0, 1], [1, 2], [2, 0]])
    c = np.array([0.1, 0.2, 0.3000000000000001, 1.0, 2.0])
    s = Springs(ends, np.ones(5), c, 5, np.zeros((0, 8), dtype=np.int64), np.zeros(0), np.zeros(0))
    _same_csc(stiffness_laplacian(s, 3), _laplacian_general(s, 3))
    assert s.__dict__["_lap"][2] is None  # no pattern: the general path was used


def test_energy_gathers_match_fancy_indexing():
    """spring_energy / area_terms gather with np.take: the same numbers as the sparse product
    and fancy indexing they replaced."""
    V, F = height_field(lambda x, y: (x * x - y * y) / 300.0, 12, 12, 100.0)
    topo = MeshTopology(V, F)
    s = build_springs(topo)
    n = topo.n
    x = np.random.default_rng(1).normal(size=2 * n) * 30.0
    e, g = spring_energy(x, s, n)
    Q = x.reshape(n, 2)
    B, BT = s._incidence_pair(n)
    d = B @ Q
    np.testing.assert_array_equal(d, Q[s.ends[:, 0]] - Q[s.ends[:, 1]])
    ell = np.sqrt(np.einsum("ij,ij->i", d, d))
    stretch = ell - s.rest
    e_ref = 0.5 * float(np.dot(s.stiffness, stretch * stretch))
    gs = (s.stiffness * stretch / np.maximum(ell, 1e-300))[:, None] * d
    W = s.contour_edges
    cs = ell[: s.n_tension][W].sum(axis=1) - s.contour_rest
    e_ref += 0.5 * float(np.dot(s.contour_stiffness, cs * cs))
    coef = np.bincount(W.ravel(), np.repeat(s.contour_stiffness * cs, W.shape[1]), minlength=s.n_tension)
    gs[: s.n_tension] += (coef / np.maximum(ell, 1e-300)[: s.n_tension])[:, None] * d[: s.n_tension]
    assert e == e_ref
    np.testing.assert_array_equal(g, np.asarray(BT @ gs).ravel())
    ea, ga = area_terms(x, topo.F, topo.areas, n, 100.0, np.ones(len(F)))
    a, b, c = Q[F[:, 0]], Q[F[:, 1]], Q[F[:, 2]]
    A = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    short = np.maximum(0.05 * topo.areas - A, 0.0)
    e2 = 0.5 * 100.0 * float(np.dot(short, short)) / float(np.mean(topo.areas))
    e2 += 0.5 * float(np.dot(np.ones(len(F)), (A - topo.areas) ** 2))
    assert ea == pytest.approx(e2, rel=1e-15)
    assert np.isfinite(ga).all()


def test_refinement_springs_share_the_end_caches():
    """refine_lengths_l1 builds springs of another stiffness on the same ends: they reuse the
    caches that depend on the ends only (and the laplacian is still the right one)."""
    V, F = spherical_cap(100.0, 45.0, 3)
    s = build_springs(MeshTopology(V, F))
    n = len(V)
    stiffness_laplacian(s, n)
    s.incidence(n)
    other = s.share_end_caches(Springs(s.ends, s.rest, s.stiffness * 2.0, s.n_tension, s.contour_edges,
                                       s.contour_rest, s.contour_stiffness))
    assert other.__dict__["_lap"] is s.__dict__["_lap"] and other.__dict__["_incidence"] is s.__dict__["_incidence"]
    _same_csc(stiffness_laplacian(other, n), _laplacian_general(other, n))
    stranger = s.share_end_caches(Springs(s.ends.copy(), s.rest, s.stiffness, s.n_tension, s.contour_edges,
                                          s.contour_rest, s.contour_stiffness))
    assert "_lap" not in stranger.__dict__  # other ends: nothing shared


def _plain_two_loop(g, S, Y, apply_h0, apply_k):
    """The two-loop recursion written out on (n,2) arrays, H0 = gamma K^-1 (Nocedal & Wright, Alg. 7.4)."""
    q = g.copy()
    alphas = []
    for s_, y_ in zip(reversed(S), reversed(Y)):
        rho = 1.0 / np.vdot(y_, s_)
        a_ = rho * np.vdot(s_, q)
        alphas.append((a_, rho))
        q = q - a_ * y_
    r = apply_h0(q)
    if S:
        r = r * (np.vdot(S[-1], apply_k(S[-1])) / np.vdot(Y[-1], S[-1]))
    for (a_, rho), s_, y_ in zip(reversed(alphas), S, Y):
        b_ = rho * np.vdot(y_, r)
        r = r + (a_ - b_) * s_
    return -r


@pytest.mark.parametrize("pairs", [0, 1, 8])
def test_two_loop_on_flat_views_gives_the_plain_recursions_numbers(pairs):
    """relax._two_loop (flat views, Python floats, gamma and y.s kept per pair): bit for bit the plain loop."""
    from bolus_addon.core.unfold.relax import _preconditioner, _two_loop

    V, F = spherical_cap(100.0, 45.0, 3)
    s = build_springs(MeshTopology(V, F))
    n = len(V)
    apply_h0, apply_k = _preconditioner(s, n, True, None)
    rng = np.random.default_rng(3)
    S = [rng.normal(size=(n, 2)) for _ in range(pairs)]
    Y = [s_ + 0.1 * rng.normal(size=(n, 2)) for s_ in S]
    g = rng.normal(size=(n, 2))
    SY = [float(np.vdot(s_, y_)) for s_, y_ in zip(S, Y)]
    gamma = float(np.vdot(S[-1], apply_k(S[-1]))) / SY[-1] if S else 1.0
    np.testing.assert_array_equal(_two_loop(g, S, Y, apply_h0, gamma, SY), _plain_two_loop(g, S, Y, apply_h0, apply_k))
