"""Stacked sparse auto-encoder in numpy/scipy (seed 3.4, eqs. 3-15..3-21; 6.4.2, Algorithm 6-1).

One auto-encoder G(X) ~ X (eq. 3-15) with encoder W1 (h,d), b1 (h,) and decoder W2 (d,h), b2 (d,):

* code h = g1(W1 x + b1) (eq. 3-16), output y = g2(W2 h + b2) (eqs. 3-17, 3-18), g1 = g2 = the
  logistic sigmoid; rows of X are samples, so in code H = g1(X W1^T + b1) (N,h) and
  Y = g2(H W2^T + b2) (N,d);
* cost C = 1/(2N) sum_n ||y_n - x_n||^2 + lam (sum W1^2 + sum W2^2) (eq. 3-19);
* sparse cost C_s = C + beta sum_i KL(rho || rho_hat_i) (eqs. 3-20, 3-21), rho_hat_i the mean
  activation of hidden unit i over the N samples;
* a stack (Algorithm 6-1) is trained greedily: layer 1 on X with C_s (line 2), layer k+1 on the
  codes of layer k with the plain C (lines 7 and 12); the last layer's codes are the hidden
  features pf of eq. 3-14.  The seed's sizes: 90 -> 120 -> 50 -> 20, lam 0.004, rho 0.05, beta 5;
* each layer minimised by L-BFGS-B with the analytic gradient, its inputs scaled to [0, 1] over
  the training rows (``scale_inputs``; lo and span kept for `StackedAutoEncoder.encode`).

Every array is float64.  Bad input raises `BolusError`; randomness comes from `rng`.

Design notes: docs/design/printing.md.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import scipy
from scipy.optimize import minimize
from threadpoolctl import threadpool_limits

from ..errors import BolusError
from ..rng import as_rng

MIN_ROWS = 10  # fewer samples than this are refused for training
_EPS = 1e-12  # rho_hat is kept inside [eps, 1 - eps] in the KL term (only reached at a saturated unit)


def sigmoid(z) -> np.ndarray:
    """The logistic function 1 / (1 + exp(-z)), elementwise, without overflow; same shape as z.

    Computed as (1 + tanh(z/2)) / 2 (about 3x faster than scipy's expit here; absolute error ~1e-16)."""
    out = np.multiply(np.asarray(z, dtype=np.float64), 0.5)
    np.tanh(out, out=out)
    out += 1.0
    out *= 0.5
    return out


@dataclass
class AutoEncoder:
    """One auto-encoder (eqs. 3-16..3-18): W1 (h,d) encoder, b1 (h,), W2 (d,h) decoder, b2 (d,)."""

    W1: np.ndarray
    b1: np.ndarray
    W2: np.ndarray
    b2: np.ndarray

    @property
    def n_in(self) -> int:
        return int(self.W1.shape[1])

    @property
    def n_hidden(self) -> int:
        return int(self.W1.shape[0])

    def encode(self, X) -> np.ndarray:
        """The codes h = sigmoid(X W1^T + b1) (eq. 3-16): X (N,d) -> (N,h)."""
        X = _check_rows(X, self.n_in, "encode", unit=False, min_rows=1)
        return sigmoid(X @ self.W1.T + self.b1)

    def reconstruct(self, X) -> np.ndarray:
        """The output Y = sigmoid(h W2^T + b2) (eqs. 3-17, 3-18): X (N,d) -> (N,d)."""
        return sigmoid(self.encode(X) @ self.W2.T + self.b2)


def _check_rows(X, d: int | None, what: str, unit: bool, min_rows: int) -> np.ndarray:
    """X as a 2-D finite float64 array (N,d) with N >= min_rows, values in [0,1] if `unit`."""
    try:
        X = np.asarray(X, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise BolusError(f"{what}: the data is not a numeric array ({exc})") from None
    if X.ndim != 2:
        raise BolusError(f"{what}: the data must be a 2-D array (samples x features), got shape {X.shape}")
    if d is not None and X.shape[1] != d:
        raise BolusError(f"{what}: rows have {X.shape[1]} features, the auto-encoder takes {d}")
    if X.shape[1] < 1:
        raise BolusError(f"{what}: rows have no features")
    if X.shape[0] < min_rows:
        raise BolusError(f"{what}: {X.shape[0]} rows, at least {min_rows} are needed")
    if not np.all(np.isfinite(X)):
        raise BolusError(f"{what}: the data has NaN or infinite values")
    if unit and X.size and (X.min() < 0.0 or X.max() > 1.0):
        raise BolusError(f"{what}: values must lie in [0, 1] (sigmoid output), found {X.min():.4g} .. {X.max():.4g};"
                         " scale the features first")
    return X


def pack(ae: AutoEncoder) -> np.ndarray:
    """theta (P,) = [W1.ravel(), b1, W2.ravel(), b2], P = 2 h d + h + d."""
    return np.concatenate([ae.W1.ravel(), ae.b1.ravel(), ae.W2.ravel(), ae.b2.ravel()]).astype(np.float64)


def unpack(theta, d: int, h: int) -> AutoEncoder:
    """The auto-encoder of a flat theta (P,) for d inputs and h hidden units (copies nothing: views)."""
    theta = np.asarray(theta, dtype=np.float64)
    P = 2 * h * d + h + d
    if theta.ndim != 1 or theta.size != P:
        raise BolusError(f"theta has shape {theta.shape}, {P} values are needed for d={d}, h={h}")
    i = 0
    W1 = theta[i:i + h * d].reshape(h, d)
    i += h * d
    b1 = theta[i:i + h]
    i += h
    W2 = theta[i:i + d * h].reshape(d, h)
    i += d * h
    b2 = theta[i:i + d]
    return AutoEncoder(W1, b1, W2, b2)


def kl_divergence(rho: float, rho_hat) -> np.ndarray:
    """KL(rho || rho_hat_i) of eq. 3-21, elementwise over rho_hat (h,); zero where rho_hat == rho."""
    r = np.clip(np.asarray(rho_hat, dtype=np.float64), _EPS, 1.0 - _EPS)
    return rho * np.log(rho / r) + (1.0 - rho) * np.log((1.0 - rho) / (1.0 - r))


def ae_cost_grad(theta, X, hidden: int, lam: float, rho: float | None = None, beta: float = 0.0):
    """Cost and exact gradient of one auto-encoder on X (N,d) at theta (P,) (see `pack`).

    C = 1/(2N) sum_n ||y_n - x_n||^2 + lam (sum W1^2 + sum W2^2) (eq. 3-19); the weight decay is on
    the weights W1, W2 only, not on the biases (the seed's D(theta) is ambiguous, and a decay on the
    hidden biases fights the sparsity target).  With `rho` given and beta > 0 the sparse cost adds
    beta sum_i KL(rho || rho_hat_i) (eqs. 3-20, 3-21), rho_hat (h,) the mean code over the N rows.
    Returns (cost: float, grad: (P,) ndarray).
    """
    X = np.asarray(X, dtype=np.float64)
    N, d = X.shape
    h = int(hidden)
    ae = unpack(theta, d, h)
    H = sigmoid(X @ ae.W1.T + ae.b1)  # (N,h)
    Y = sigmoid(H @ ae.W2.T + ae.b2)  # (N,d)
    R = Y - X
    cost = 0.5 * float(np.einsum("ij,ij->", R, R)) / N
    cost += lam * (float(np.einsum("ij,ij->", ae.W1, ae.W1)) + float(np.einsum("ij,ij->", ae.W2, ae.W2)))
    # d3 = dC/dZ2 = R Y (1 - Y) / N  (N,d), in place
    d3 = R
    d3 *= Y
    np.subtract(1.0, Y, out=Y)
    d3 *= Y
    d3 /= N
    gW2 = d3.T @ H
    gW2 += (2.0 * lam) * ae.W2
    gb2 = d3.sum(axis=0)
    dH = d3 @ ae.W2  # dC/dH (N,h)
    if rho is not None and beta > 0.0:
        rho_hat = H.mean(axis=0)
        cost += beta * float(kl_divergence(rho, rho_hat).sum())
        r = np.clip(rho_hat, _EPS, 1.0 - _EPS)
        dH += (beta / N) * (-rho / r + (1.0 - rho) / (1.0 - r))
    # d2 = dC/dZ1 = dH H (1 - H)  (N,h), in place
    d2 = dH
    d2 *= H
    np.subtract(1.0, H, out=H)
    d2 *= H
    gW1 = d2.T @ X
    gW1 += (2.0 * lam) * ae.W1
    gb1 = d2.sum(axis=0)
    return cost, np.concatenate([gW1.ravel(), gb1, gW2.ravel(), gb2])


def init_autoencoder(d: int, h: int, rng=None) -> AutoEncoder:
    """Random start: W1 (h,d) then W2 (d,h) uniform in +-sqrt(6/(d+h+1)) from `rng`, biases zero."""
    if int(d) < 1 or int(h) < 1:
        raise BolusError(f"an auto-encoder needs at least one input and one hidden unit (d={d}, h={h})")
    d, h = int(d), int(h)
    gen = as_rng(rng)
    r = np.sqrt(6.0 / (d + h + 1))
    W1 = gen.uniform(-r, r, size=(h, d))
    W2 = gen.uniform(-r, r, size=(d, h))
    return AutoEncoder(W1, np.zeros(h), W2, np.zeros(d))


def _check_settings(lam: float, rho: float, beta: float) -> None:
    if not (np.isfinite(lam) and lam >= 0.0):
        raise BolusError(f"the weight decay lam must be >= 0, got {lam}")
    if not (np.isfinite(beta) and beta >= 0.0):
        raise BolusError(f"the sparsity weight beta must be >= 0, got {beta}")
    if not (np.isfinite(rho) and 0.0 < rho < 1.0):
        raise BolusError(f"the sparsity target rho must lie strictly between 0 and 1, got {rho}")


def train_autoencoder(X, hidden: int, lam: float = 0.004, rho: float = 0.05, beta: float = 5.0, sparse: bool = True,
                      max_iter: int = 400, rng=0, progress: Callable[[float, str], None] | None = None):
    """Train one auto-encoder on X (N,d), rows in [0,1], with `hidden` units (Algorithm 6-1, lines 1-3).

    Minimises C_s (eq. 3-20) if `sparse`, else C (eq. 3-19), with L-BFGS-B and the exact gradient
    from a random start (`init_autoencoder`).  `progress(fraction, text)` is called after every
    iteration.  Returns (AutoEncoder, info) with info = {iterations, evaluations, cost_start,
    cost_end, seconds, converged, message, rows, n_in, hidden, sparse, code_std}; code_std, the
    codes' standard deviation over the rows averaged over the units, near 0 means the layer has
    collapsed to constant codes (the weight decay won over the reconstruction).
    """
    X = _check_rows(X, None, "auto-encoder training", unit=True, min_rows=MIN_ROWS)
    if int(hidden) < 1:
        raise BolusError(f"the auto-encoder needs at least one hidden unit, got {hidden}")
    if int(max_iter) < 1:
        raise BolusError(f"max_iter must be at least 1, got {max_iter}")
    _check_settings(lam, rho, beta)
    N, d = X.shape
    h = int(hidden)
    sp_rho, sp_beta = (rho, beta) if sparse else (None, 0.0)
    theta0 = pack(init_autoencoder(d, h, rng))
    t0 = time.perf_counter()

    def fun(theta):
        return ae_cost_grad(theta, X, h, lam, sp_rho, sp_beta)

    cost_start = fun(theta0)[0]
    count = [0]

    def callback(*_):
        count[0] += 1
        if progress is not None:
            progress(min(count[0] / max_iter, 1.0), f"auto-encoder {d}->{h}: iteration {count[0]}")

    # one BLAS thread: on this 2-core class of machine the products are too small to gain from
    # threads, and a fixed thread count keeps the result bit-identical for a fixed rng
    with threadpool_limits(1, user_api="blas"):
        res = minimize(fun, theta0, jac=True, method="L-BFGS-B", callback=callback,
                       options={"maxiter": int(max_iter), "maxfun": 4 * int(max_iter) + 20})
    theta = np.asarray(res.x, dtype=np.float64)
    cost_end = float(res.fun)
    if not np.isfinite(cost_end) or not np.all(np.isfinite(theta)):
        raise BolusError("auto-encoder training diverged (non-finite weights); check the data's scaling")
    ae = unpack(theta.copy(), d, h)
    info = {
        "iterations": int(res.nit), "evaluations": int(res.nfev), "cost_start": float(cost_start),
        "cost_end": cost_end, "seconds": time.perf_counter() - t0, "converged": bool(res.success),
        "message": str(res.message), "rows": int(N), "n_in": int(d), "hidden": h, "sparse": bool(sparse),
        "code_std": float(ae.encode(X).std(axis=0).mean()),
    }
    return ae, info


def reconstruction_error(ae: AutoEncoder, X) -> float:
    """Mean over the rows of 1/2 ||y_n - x_n||^2 (the data term of eq. 3-19) for X (N,d)."""
    X = _check_rows(X, ae.n_in, "reconstruction error", unit=False, min_rows=1)
    R = ae.reconstruct(X) - X
    return 0.5 * float(np.einsum("ij,ij->", R, R)) / X.shape[0]


@dataclass
class StackedAutoEncoder:
    """Auto-encoders chained by their encoders (Figure 3-3); `meta`: settings, data, versions (JSON-able)."""

    layers: list[AutoEncoder]
    meta: dict = field(default_factory=dict)
    #: per layer (lo (d_k,), span (d_k,)): its input is rescaled to (x - lo) / span first (module doc,
    #: "input scaling"); empty: no rescaling (files written before the scaling)
    scales: list = field(default_factory=list)

    @property
    def sizes(self) -> tuple[int, ...]:
        """(inputs, hidden of layer 1, ..., hidden of the last), e.g. (90, 120, 50, 20)."""
        if not self.layers:
            return ()
        return (self.layers[0].n_in,) + tuple(ae.n_hidden for ae in self.layers)

    def encode(self, X) -> np.ndarray:
        """The hidden features pf (eq. 3-14): X (N,d) through every encoder -> (N, last size)."""
        if not self.layers:
            raise BolusError("the stacked auto-encoder has no layers")
        return self.layer_inputs(X, codes=True)[-1]

    def layer_inputs(self, X, codes: bool = False) -> list[np.ndarray]:
        """The (rescaled) input of every layer for X (N,d): a list of (N, d_k); with ``codes`` the
        last layer's codes appended (the hidden features pf)."""
        if not self.layers:
            raise BolusError("the stacked auto-encoder has no layers")
        H = _check_rows(X, self.layers[0].n_in, "stacked auto-encoder", unit=True, min_rows=1)
        out = []
        for k, ae in enumerate(self.layers):
            if self.scales:
                lo, span = self.scales[k]
                H = (H - lo) / span
            out.append(H)
            H = sigmoid(H @ ae.W1.T + ae.b1)
        return out + [H] if codes else out

    def save(self, path) -> None:
        """Write a .npz: W1_k, b1_k, W2_k, b2_k (float64) for every layer k and `meta` as a JSON string."""
        arrays = {}
        for k, ae in enumerate(self.layers):
            for name in ("W1", "b1", "W2", "b2"):
                arrays[f"{name}_{k}"] = np.asarray(getattr(ae, name), dtype=np.float64)
            if self.scales:
                arrays[f"lo_{k}"], arrays[f"span_{k}"] = (np.asarray(a, dtype=np.float64) for a in self.scales[k])
        try:
            meta = json.dumps(self.meta, sort_keys=True)
        except (TypeError, ValueError) as exc:
            raise BolusError(f"the auto-encoder's meta data cannot be written as JSON ({exc})") from None
        arrays["meta"] = np.array(meta)
        try:
            with open(path, "wb") as f:
                np.savez(f, **arrays)
        except OSError as exc:
            raise BolusError(f"cannot write the auto-encoder to {path}: {exc}") from None

    @classmethod
    def load(cls, path) -> StackedAutoEncoder:
        """Read a file written by `save`; BolusError if it is missing, not such a file, or inconsistent."""
        path = Path(path)
        if not path.is_file():
            raise BolusError(f"no auto-encoder file at {path}")
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except Exception as exc:  # zipfile, pickle and format errors of a damaged file  # noqa: BLE001
            raise BolusError(f"{path.name} is not a readable auto-encoder file ({type(exc).__name__}: {exc})") from None
        bad = f"{path.name} is not a valid auto-encoder file"
        if "meta" not in data or data["meta"].dtype.kind != "U" or data["meta"].ndim != 0:
            raise BolusError(f"{bad}: the meta data is missing")
        try:
            meta = json.loads(str(data["meta"]))
        except ValueError as exc:
            raise BolusError(f"{bad}: the meta data is not JSON ({exc})") from None
        if not isinstance(meta, dict):
            raise BolusError(f"{bad}: the meta data is not a dictionary")
        layers, scales = [], []
        d = None
        k = 0
        while f"W1_{k}" in data:
            try:
                W1, b1, W2, b2 = (data[f"{n}_{k}"] for n in ("W1", "b1", "W2", "b2"))
            except KeyError as exc:
                raise BolusError(f"{bad}: layer {k} lacks {exc.args[0]}") from None
            if W1.ndim != 2:
                raise BolusError(f"{bad}: layer {k}'s encoder has shape {W1.shape}")
            h, dk = W1.shape
            if d is not None and dk != d:
                raise BolusError(f"{bad}: layer {k} takes {dk} inputs, layer {k - 1} gives {d}")
            for name, arr, shape in (("W1", W1, (h, dk)), ("b1", b1, (h,)), ("W2", W2, (dk, h)), ("b2", b2, (dk,))):
                if arr.shape != shape or arr.dtype.kind != "f":
                    raise BolusError(f"{bad}: layer {k}'s {name} has shape {arr.shape} ({arr.dtype}), "
                                     f"expected {shape} (float)")
                if not np.all(np.isfinite(arr)):
                    raise BolusError(f"{bad}: layer {k}'s {name} has NaN or infinite values")
            if h < 1 or dk < 1:
                raise BolusError(f"{bad}: layer {k} is empty")
            layers.append(AutoEncoder(*(np.asarray(a, dtype=np.float64) for a in (W1, b1, W2, b2))))
            if f"lo_{k}" in data or f"span_{k}" in data:
                lo, span = data.get(f"lo_{k}"), data.get(f"span_{k}")
                if lo is None or span is None or lo.shape != (dk,) or span.shape != (dk,) \
                        or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(span)) and np.all(span > 0)):
                    raise BolusError(f"{bad}: layer {k}'s input scaling is incomplete or not {dk} finite "
                                     "numbers with positive spans")
                scales.append((np.asarray(lo, dtype=np.float64), np.asarray(span, dtype=np.float64)))
            d = h
            k += 1
        if not layers:
            raise BolusError(f"{bad}: it holds no layers")
        if scales and len(scales) != len(layers):
            raise BolusError(f"{bad}: {len(scales)} of its {len(layers)} layers have an input scaling")
        known = {"meta"} | {f"{n}_{i}" for i in range(k) for n in ("W1", "b1", "W2", "b2", "lo", "span")}
        extra = [n for n in data if n not in known]
        if extra:
            raise BolusError(f"{bad}: unexpected arrays {sorted(extra)}")
        return cls(layers, meta, scales)


def train_stacked(X, sizes: Sequence[int] = (120, 50, 20), lam: float | Sequence[float] = 0.004, rho: float = 0.05,
                  beta: float = 5.0, max_iter: int | Sequence[int] = (400, 400, 400), rng=0,
                  progress: Callable[[float, str], None] | None = None, scale_inputs: bool = True):
    """Greedy layer-wise training of a stack (Algorithm 6-1) on X (N,d), rows in [0,1].

    Layer 1 (sizes[0] hidden units) minimises the sparse C_1s (eq. 3-20, line 2); every further
    layer minimises the plain C_k (eq. 3-19, lines 7 and 12) on the codes of the layer before.  The
    layers' random starts are drawn one after another from one generator `rng`.  `lam` and `max_iter`:
    one number for every layer or one per layer.  `progress(fraction, text)`, fraction in [0,1] over the
    whole stack (each layer weighted by its inputs x hidden x iterations).
    Returns (StackedAutoEncoder, [info per layer]) (see `train_autoencoder`).
    """
    X = _check_rows(X, None, "auto-encoder training", unit=True, min_rows=MIN_ROWS)
    sizes = tuple(int(s) for s in np.atleast_1d(sizes))
    if not sizes or min(sizes) < 1:
        raise BolusError(f"sizes must list at least one layer of at least one unit, got {sizes}")
    iters = np.atleast_1d(max_iter).astype(int)
    if iters.size == 1:
        iters = np.repeat(iters, len(sizes))
    if iters.size != len(sizes):
        raise BolusError(f"max_iter gives {iters.size} values for {len(sizes)} layers")
    lams = np.atleast_1d(np.asarray(lam, dtype=np.float64))
    if lams.size == 1:
        lams = np.repeat(lams, len(sizes))
    if lams.size != len(sizes):
        raise BolusError(f"lam gives {lams.size} values for {len(sizes)} layers")
    for lam_k in lams:
        _check_settings(float(lam_k), rho, beta)
    gen = as_rng(rng)
    dims = (X.shape[1],) + sizes
    weights = np.array([dims[k] * dims[k + 1] * iters[k] for k in range(len(sizes))], dtype=np.float64)
    starts = np.concatenate([[0.0], np.cumsum(weights)]) / weights.sum()
    layers, infos, scales = [], [], []
    H = X
    for k, h in enumerate(sizes):
        if scale_inputs:  # module doc, "input scaling": every input column spans [0, 1] on the training rows
            lo = H.min(axis=0)
            span = H.max(axis=0) - lo
            span = np.where(span > 1e-12, span, 1.0)
            scales.append((lo, span))
            H = (H - lo) / span
        def report(frac, text, k=k):
            if progress is not None:
                progress(float(starts[k] + frac * (starts[k + 1] - starts[k])),
                         f"layer {k + 1}/{len(sizes)}: {text}")
        report(0.0, "start")
        ae, info = train_autoencoder(H, h, lam=float(lams[k]), rho=rho, beta=beta, sparse=(k == 0),
                                     max_iter=int(iters[k]), rng=gen, progress=report)
        layers.append(ae)
        infos.append(info)
        H = ae.encode(H)
    if progress is not None:
        progress(1.0, "stacked auto-encoder trained")
    meta = {
        "sizes": list(dims), "lam": [float(v) for v in lams], "rho": float(rho), "beta": float(beta),
        "sparse_layers": [1], "scale_inputs": bool(scale_inputs),
        "max_iter": [int(i) for i in iters], "rng": rng if isinstance(rng, int) else None,
        "iterations": [i["iterations"] for i in infos], "cost_end": [i["cost_end"] for i in infos],
        "seconds": [round(i["seconds"], 3) for i in infos], "code_std": [i["code_std"] for i in infos],
        "data": {"rows": int(X.shape[0]), "features": int(X.shape[1]), "mean": float(X.mean()),
                 "nonzero_fraction": float(np.count_nonzero(X) / X.size)},
        "versions": {"numpy": np.__version__, "scipy": scipy.__version__, "format": 1},
        "seed": "eqs. 3-15..3-21, Algorithm 6-1",
    }
    return StackedAutoEncoder(layers, meta, scales), infos
