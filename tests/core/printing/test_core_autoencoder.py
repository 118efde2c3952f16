"""core.autoencoder: the stacked sparse auto-encoder (eqs. 3-15..3-21, Algorithm 6-1)."""
import numpy as np
import pytest

from bolus_addon.core.printing.autoencoder import (
    AutoEncoder,
    StackedAutoEncoder,
    ae_cost_grad,
    init_autoencoder,
    kl_divergence,
    pack,
    reconstruction_error,
    sigmoid,
    train_autoencoder,
    train_stacked,
    unpack,
)
from bolus_addon.core.errors import BolusError


def feature_rows(n: int, seed: int = 0) -> np.ndarray:
    """(n, 90) rows in [0,1] shaped like per-triangle print features of 30-triangle sub-graphs:
    three features per triangle driven by four hidden factors, a little noise, and the
    triangles after a random count of 20..30 zero-padded."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.0, 1.0, (n, 4))
    t = np.linspace(0.0, 1.0, 30)
    f1 = z[:, [0]] * np.sin(np.pi * t * (1.0 + 2.0 * z[:, [1]])) ** 2
    f2 = z[:, [2]] + 0.3 * np.cos(2.0 * np.pi * t + 6.0 * z[:, [3]])
    f3 = (t < z[:, [1]]) * z[:, [3]]
    X = np.stack([f1, f2, f3], axis=2).reshape(n, 90) + rng.normal(0.0, 0.02, (n, 90))
    X[np.arange(90)[None, :] >= 3 * rng.integers(20, 31, n)[:, None]] = 0.0
    return np.clip(X, 0.0, 1.0)


def _check_gradient(theta, X, h, lam, rho, beta, n_pick=6, seed=0):
    d = X.shape[1]
    cost, grad = ae_cost_grad(theta, X, h, lam, rho, beta)
    assert np.isfinite(cost) and grad.shape == theta.shape
    # coordinates from every block: W1, b1, W2, b2
    edges = np.cumsum([0, h * d, h, d * h, d])
    rng = np.random.default_rng(seed)
    picks = np.concatenate([rng.choice(np.arange(a, b), size=min(n_pick, b - a), replace=False)
                            for a, b in zip(edges[:-1], edges[1:])])
    eps = 1e-4
    for i in picks:
        e = np.zeros_like(theta)
        e[i] = eps
        up, down = ae_cost_grad(theta + e, X, h, lam, rho, beta)[0], ae_cost_grad(theta - e, X, h, lam, rho, beta)[0]
        num = (up - down) / (2 * eps)
        rel = abs(num - grad[i]) / max(abs(num), abs(grad[i]), 1e-8)
        assert rel < 1e-5, (i, num, grad[i], rel)
    return cost


@pytest.mark.parametrize("sparse", [False, True])
def test_gradient_matches_central_differences(sparse):
    d, h, N = 7, 5, 20
    rng = np.random.default_rng(3)
    X = rng.uniform(0.0, 1.0, (N, d))
    theta = pack(init_autoencoder(d, h, 1)) + rng.normal(0.0, 0.4, 2 * d * h + d + h)  # biases non-zero too
    rho, beta = (0.05, 5.0) if sparse else (None, 0.0)
    cost = _check_gradient(theta, X, h, 0.004, rho, beta)
    plain = ae_cost_grad(theta, X, h, 0.004)[0]
    assert (cost > plain + 1e-3) if sparse else cost == plain
    # a second point with saturated-ish hidden units (rho_hat far from rho) and a larger decay
    theta2 = theta.copy()
    unpack(theta2, d, h).b1[:] = np.linspace(-4.0, 4.0, h)
    _check_gradient(theta2, X, h, 0.05, rho, beta, seed=1)


def test_weight_decay_is_on_weights_only():
    d, h, N = 4, 3, 10
    X = np.random.default_rng(0).uniform(0.0, 1.0, (N, d))
    ae = init_autoencoder(d, h, 0)
    theta = pack(ae)
    base = ae_cost_grad(theta, X, h, 0.0)[0]
    W = float((ae.W1 ** 2).sum() + (ae.W2 ** 2).sum())
    assert ae_cost_grad(theta, X, h, 0.5)[0] == pytest.approx(base + 0.5 * W, rel=1e-12)
    ae.b1[:] = 3.0  # biases change the reconstruction but add no decay
    t3 = pack(ae)
    assert ae_cost_grad(t3, X, h, 0.5)[0] - ae_cost_grad(t3, X, h, 0.0)[0] == pytest.approx(0.5 * W, rel=1e-12)


def test_kl_is_zero_at_the_target_and_positive_elsewhere():
    rho = 0.05
    assert np.all(kl_divergence(rho, np.full(6, rho)) == 0.0)
    assert np.all(kl_divergence(rho, np.array([0.01, 0.1, 0.5, 0.9])) > 0.0)
    # build a net whose every hidden unit has mean activation exactly rho: W1 = 0, b1 = logit(rho)
    d, h, N = 6, 4, 15
    X = np.random.default_rng(2).uniform(0.0, 1.0, (N, d))
    ae = init_autoencoder(d, h, 0)
    ae.W1[:] = 0.0
    ae.b1[:] = np.log(rho / (1.0 - rho))
    assert np.allclose(ae.encode(X).mean(axis=0), rho, rtol=0, atol=1e-15)
    theta = pack(ae)
    plain, g_plain = ae_cost_grad(theta, X, h, 0.004)
    sparse, g_sparse = ae_cost_grad(theta, X, h, 0.004, rho=rho, beta=5.0)
    assert sparse == pytest.approx(plain, abs=1e-12)
    assert np.allclose(g_sparse, g_plain, atol=1e-10)  # the KL term is at its minimum
    ae.b1[:] = 0.0  # rho_hat = 0.5
    theta = pack(ae)
    assert ae_cost_grad(theta, X, h, 0.004, rho=rho, beta=5.0)[0] > ae_cost_grad(theta, X, h, 0.004)[0] + 1.0


def test_layerwise_training_lowers_held_back_error_every_layer():
    X = feature_rows(300, seed=4)
    train, held = X[:200], X[200:]
    sizes, iters = (120, 50, 20), (120, 80, 80)
    H_train, H_held = train, held
    d = X.shape[1]
    for k, h in enumerate(sizes):
        ae, info = train_autoencoder(H_train, h, sparse=(k == 0), max_iter=iters[k], rng=10 + k)
        start = init_autoencoder(d, h, 10 + k)  # the same random start train_autoencoder used
        assert np.array_equal(pack(start), pack(init_autoencoder(d, h, np.random.default_rng(10 + k))))
        before, after = reconstruction_error(start, H_held), reconstruction_error(ae, H_held)
        assert after < 0.5 * before, (k, before, after)
        assert info["cost_end"] < info["cost_start"] and info["iterations"] >= 1
        assert info["sparse"] == (k == 0) and info["seconds"] > 0.0
        H_train, H_held, d = ae.encode(H_train), ae.encode(H_held), h
    # the sparse first layer: mean activation near rho, and it beats predicting the training mean
    ae1, _ = train_autoencoder(train, 120, max_iter=120, rng=10)
    assert abs(ae1.encode(train).mean() - 0.05) < 0.02
    mean_err = 0.5 * float(((held - train.mean(axis=0)) ** 2).sum(axis=1).mean())
    assert reconstruction_error(ae1, held) < 0.8 * mean_err


def test_stack_is_deterministic_for_a_fixed_rng_and_reports_progress():
    X = feature_rows(120, seed=5)
    seen = []
    a, infos = train_stacked(X, sizes=(12, 6, 3), max_iter=(15, 10, 10), rng=7,
                             progress=lambda f, text: seen.append((f, text)))
    b, _ = train_stacked(X, sizes=(12, 6, 3), max_iter=(15, 10, 10), rng=7)
    c, _ = train_stacked(X, sizes=(12, 6, 3), max_iter=(15, 10, 10), rng=8)
    assert a.sizes == (90, 12, 6, 3) and len(infos) == 3
    assert [i["sparse"] for i in infos] == [True, False, False]  # Algorithm 6-1: sparsity on layer 1 only
    for la, lb, lc in zip(a.layers, b.layers, c.layers):
        assert np.array_equal(pack(la), pack(lb))
        assert not np.array_equal(pack(la), pack(lc))
    assert np.array_equal(a.encode(X), b.encode(X)) and a.encode(X).shape == (120, 3)
    fractions = [f for f, _ in seen]
    assert fractions[0] == 0.0 and fractions[-1] == 1.0
    assert all(0.0 <= f <= 1.0 for f in fractions) and fractions == sorted(fractions)
    assert a.meta["sizes"] == [90, 12, 6, 3] and a.meta["rng"] == 7 and a.meta["data"]["rows"] == 120


def test_encode_chains_the_encoders():
    X = feature_rows(40, seed=6)
    layers = [init_autoencoder(90, 8, 0), init_autoencoder(8, 5, 1), init_autoencoder(5, 2, 2)]
    for i, ae in enumerate(layers):
        ae.b1[:] = 0.1 * (i + 1)
    sae = StackedAutoEncoder(layers, {})
    H = X
    for ae in layers:
        H = 1.0 / (1.0 + np.exp(-(H @ ae.W1.T + ae.b1)))
    assert np.allclose(sae.encode(X), H, rtol=0, atol=1e-14)
    assert np.allclose(sigmoid(np.array([-800.0, 0.0, 800.0])), [0.0, 0.5, 1.0])


def test_save_load_round_trip(tmp_path):
    X = feature_rows(60, seed=7)
    sae, _ = train_stacked(X, sizes=(10, 6, 4), max_iter=8, rng=1)
    sae.meta["data"]["source"] = "synthetic rows"
    path = tmp_path / "sae.npz"
    sae.save(path)
    back = StackedAutoEncoder.load(path)
    assert back.sizes == (90, 10, 6, 4) and back.meta == sae.meta
    assert np.array_equal(back.encode(X), sae.encode(X))
    with np.load(path, allow_pickle=False) as z:
        assert sorted(z.files) == sorted([f"{n}_{k}" for k in range(3) for n in ("W1", "b1", "W2", "b2", "lo", "span")]
                                         + ["meta"])
        assert all(z[n].dtype == np.float64 for n in z.files if n != "meta")
    # a path without the .npz suffix is written as given
    other = tmp_path / "model.sae"
    sae.save(other)
    assert other.is_file() and np.array_equal(StackedAutoEncoder.load(other).encode(X), sae.encode(X))


def test_load_refuses_missing_corrupt_and_wrong_files(tmp_path):
    with pytest.raises(BolusError, match="no auto-encoder file"):
        StackedAutoEncoder.load(tmp_path / "none.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"this is not a zip file at all" * 10)
    with pytest.raises(BolusError, match="not a readable"):
        StackedAutoEncoder.load(junk)
    good = tmp_path / "good.npz"
    StackedAutoEncoder([init_autoencoder(5, 3, 0), init_autoencoder(3, 2, 1)], {"a": 1}).save(good)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[:200])
    with pytest.raises(BolusError):
        StackedAutoEncoder.load(cut)

    def write(name, **arrays):
        p = tmp_path / name
        with open(p, "wb") as f:
            np.savez(f, **arrays)
        return p

    a, b = init_autoencoder(5, 3, 0), init_autoencoder(3, 2, 1)
    layer = {"W1_0": a.W1, "b1_0": a.b1, "W2_0": a.W2, "b2_0": a.b2}
    meta = np.array('{"x": 1}')
    with pytest.raises(BolusError, match="expected"):
        StackedAutoEncoder.load(write("shape.npz", **{**layer, "W2_0": a.W2.T, "meta": meta}))
    c = init_autoencoder(4, 2, 1)
    with pytest.raises(BolusError, match="takes 4 inputs"):
        StackedAutoEncoder.load(write("chain.npz", **layer, W1_1=c.W1, b1_1=c.b1, W2_1=c.W2, b2_1=c.b2, meta=meta))
    with pytest.raises(BolusError, match="lacks b2_1"):
        StackedAutoEncoder.load(write("lacks.npz", **layer, W1_1=b.W1, b1_1=b.b1, W2_1=b.W2, meta=meta))
    with pytest.raises(BolusError, match="meta"):
        StackedAutoEncoder.load(write("nometa.npz", **layer))
    with pytest.raises(BolusError, match="no layers"):
        StackedAutoEncoder.load(write("empty.npz", meta=meta))
    with pytest.raises(BolusError, match="NaN"):
        StackedAutoEncoder.load(write("nan.npz", **{**layer, "b1_0": np.full(3, np.nan), "meta": meta}))
    with pytest.raises(BolusError, match="unexpected"):
        StackedAutoEncoder.load(write("extra.npz", **layer, W1_7=b.W1, meta=meta))
    assert StackedAutoEncoder.load(write("ok.npz", **layer, meta=meta)).sizes == (5, 3)


@pytest.mark.parametrize("bad, match", [
    (np.full((30, 90), np.nan), "NaN"),
    (np.linspace(0.0, 1.0, 90), "2-D"),
    (np.full((30, 90), 1.5), r"\[0, 1\]"),
    (np.full((30, 90), -0.1), r"\[0, 1\]"),
    (np.full((3, 90), 0.5), "at least"),
    ([["a", "b"]], "numeric"),
])
def test_bad_input_is_refused(bad, match):
    with pytest.raises(BolusError, match=match):
        train_stacked(bad, sizes=(4, 2), max_iter=2)
    with pytest.raises(BolusError, match=match):
        train_autoencoder(bad, 4, max_iter=2)
    if np.ndim(bad) != 2 or np.shape(bad)[0] >= 10:
        with pytest.raises(BolusError):
            StackedAutoEncoder([init_autoencoder(90, 4, 0)], {}).encode(bad)


def test_bad_settings_are_refused():
    X = feature_rows(30)
    for kwargs in ({"rho": 0.0}, {"rho": 1.0}, {"beta": -1.0}, {"lam": -0.1}, {"max_iter": (5, 5)},
                   {"sizes": (4, 0)}, {"lam": (0.1, 0.2)}):
        with pytest.raises(BolusError):
            train_stacked(X, **{"sizes": (4, 2, 1), "max_iter": 2, **kwargs})
    with pytest.raises(BolusError, match="features"):
        StackedAutoEncoder([init_autoencoder(90, 4, 0)], {}).encode(X[:, :80])
    with pytest.raises(BolusError, match="theta"):
        unpack(np.zeros(10), 3, 2)
    assert isinstance(unpack(pack(init_autoencoder(3, 2, 0)), 3, 2), AutoEncoder)


def test_input_scaling_keeps_layers_2_and_3_from_collapsing():
    """The module docstring's 'input scaling': without it, the seed's decay on every layer collapses layers
    2 and 3 to constant codes (code_std ~ 0, the same pf for every row); with it (the default) every layer
    keeps lam = 0.004 and varies, and encode() applies the stored scaling."""
    X = feature_rows(300, seed=4)
    plain, infos = train_stacked(X, max_iter=150, rng=0, scale_inputs=False)
    assert infos[0]["code_std"] > 0.02
    assert infos[1]["code_std"] < 1e-3 and infos[2]["code_std"] < 1e-3
    assert plain.encode(X).std(axis=0).mean() < 1e-3 and plain.scales == []
    kept, infos = train_stacked(X, max_iter=150, rng=0)
    assert all(i["code_std"] > 0.01 for i in infos) and kept.meta["lam"] == [0.004] * 3
    assert kept.encode(X).std(axis=0).mean() > 0.01
    # every layer's training input spans [0, 1] column by column (constant columns stay constant)
    for inp in kept.layer_inputs(X):
        span = inp.max(axis=0) - inp.min(axis=0)
        assert inp.min() >= -1e-12 and inp.max() <= 1 + 1e-12
        assert np.all((np.abs(span - 1.0) < 1e-9) | (span < 1e-12))
    # a per-layer decay is still accepted
    per_layer, _ = train_stacked(X, lam=(0.004, 0.001, 0.001), max_iter=5, rng=0)
    assert per_layer.meta["lam"] == [0.004, 0.001, 0.001]
