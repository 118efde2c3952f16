"""Clustering the rows of a spectral embedding (seed 3.2 step 4 and 6.2; eqs. 3-8, 6-36).

The one clustering step of both spectral segmentations: `spectral.segment` (vertex
rows of U, k-means by default) and `print_segmentation.print_segmentation` (face rows
of U or U' = F^-1/2 U, a Gaussian mixture by default, each row weighted by its face's
area for ABcut).

Before clustering the rows are centred, constant columns (the trivial eigenvector) are
dropped and the embedding is scaled to unit RMS: a unit-norm eigenvector of n entries
has entries of about 1/sqrt(n), so without this the mixture's covariance floor
``REG_COVAR`` would mean something different on every mesh size.  k-means labels do
not depend on this scaling.

``REG_COVAR = 1e-6`` (scikit-learn's default), relative to the unit-RMS embedding: it
keeps a cluster's covariance invertible when its rows lie on a line or a point (a
patch whose embedding is flat) and is a millionth of the spread, so it moves no
boundary.  The two callers used 1e-9 (segment, on the raw U) and 1e-6 (print, on the
scaled U) before; measured on the print and segment tests and bench/print_bench.py,
both values give the same labels on the scaled embedding (the README's figures).
"""
from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from ..errors import BolusError
from ..rng import as_rng

__all__ = ["METHODS", "REG_COVAR", "KMEANS_RESTARTS", "KMEANS_THREADS", "GMM_RESTARTS", "WEIGHTED_DRAWS", "standardise_rows",
           "cluster_rows"]

METHODS = ("kmeans", "gmm")
REG_COVAR = 1e-6  #: covariance floor of the Gaussian mixture, relative to the unit-RMS embedding (module doc)
KMEANS_RESTARTS = 4  #: k-means++ restarts: the best of 4 was stable on every test mesh
#: above this many rows k-means++ and its restarts run on this many rows drawn at random, and
#: Lloyd's iterations from the best centres then run on every row (nefertiti, 35k vertices:
#: 0.36 s -> 0.06 s, the same patches on 99.9 % of the triangles, as a second seed gives)
KMEANS_SAMPLE = 12_000
#: OpenMP/BLAS threads of k-means: at a few columns and up to a million rows a Lloyd pass is
#: memory-bound, and on a 2-core machine with other work running two threads waited on each
#: other (12k rows, k = 3, 4 restarts: 0.04-0.15 s on one thread, 0.08-0.90 s on two)
KMEANS_THREADS = 1
GMM_RESTARTS = 3  #: mixture restarts: the best likelihood of 3 was stable on every test mesh
WEIGHTED_DRAWS = (4096, 50_000)  #: area-weighted resample for the mixture: max(rows, 4096), at most 50,000


def standardise_rows(U) -> np.ndarray:
    """U (n,d) centred, without constant columns, scaled to unit RMS -> (n,d') (module doc)."""
    U = np.asarray(U, dtype=np.float64)
    X = U - U.mean(axis=0)
    sd = X.std(axis=0)
    X = X[:, sd > 1e-9 * max(float(sd.max()) if sd.size else 0.0, 1e-300)]
    if X.shape[1] == 0:
        return X if U.shape[1] == 0 else np.zeros((len(U), 1))
    return X / (np.sqrt((X**2).mean()) or 1.0)


def cluster_rows(U, k: int, method: str = "kmeans", rng=None, weights=None) -> np.ndarray:
    """Cluster the rows of a spectral embedding U (n,d) into k labels (n,) int64.

    method "kmeans" (scikit-learn KMeans, k-means++ seeding, ``KMEANS_RESTARTS``; on more
    than ``KMEANS_SAMPLE`` unweighted rows seeded on a random sample of them) or
    "gmm" (GaussianMixture, full covariances, ``GMM_RESTARTS``, ``REG_COVAR``).
    weights (n,) >= 0, optional: how much each row counts (face areas for ABcut):
    k-means takes them as sample weights, the mixture is fitted on rows drawn with
    probability proportional to them and then labels every row.  Deterministic for a
    fixed ``rng``.
    """
    from sklearn.cluster import KMeans
    from sklearn.mixture import GaussianMixture

    if method not in METHODS:
        raise BolusError(f"unknown clustering method {method!r}; use 'kmeans' or 'gmm'")
    U = np.asarray(U, dtype=np.float64)
    if U.ndim != 2 or not np.isfinite(U).all():
        raise BolusError(f"the spectral embedding must be a finite (n, d) array (NaN or infinite entries, "
                         f"or shape {U.shape})")
    X = standardise_rows(U)
    n = len(X)
    if not 1 <= int(k) <= n:
        raise BolusError(f"cannot make {k} clusters of {n} rows")
    w = None
    if weights is not None:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (n,) or not np.isfinite(w).all() or (w < 0).any() or not w.sum() > 0:
            raise BolusError(f"row weights must be {n} finite numbers >= 0 with a positive sum")
        w = w / w.sum()
    rng = as_rng(rng)
    if method == "kmeans":
        seed = int(rng.integers(0, 2**31 - 1))
        sw = None if w is None else w * n
        if n > KMEANS_SAMPLE and w is None:
            pick = np.random.default_rng(seed).choice(n, KMEANS_SAMPLE, replace=False)
            with threadpool_limits(KMEANS_THREADS):
                centres = KMeans(n_clusters=k, n_init=KMEANS_RESTARTS, random_state=seed).fit(X[pick]).cluster_centers_
            km = KMeans(n_clusters=k, init=centres, n_init=1, random_state=seed)
        else:
            km = KMeans(n_clusters=k, n_init=KMEANS_RESTARTS, random_state=seed)
        with threadpool_limits(KMEANS_THREADS):
            return km.fit_predict(X, sample_weight=sw).astype(np.int64)
    fit_rows = X
    if w is not None:
        draws = int(min(max(n, WEIGHTED_DRAWS[0]), WEIGHTED_DRAWS[1]))
        fit_rows = X[rng.choice(n, size=draws, p=w)]
    seed = int(rng.integers(0, 2**31 - 1))
    gm = GaussianMixture(n_components=k, covariance_type="full", n_init=GMM_RESTARTS, random_state=seed,
                         reg_covar=REG_COVAR)
    return gm.fit(fit_rows).predict(X).astype(np.int64)
