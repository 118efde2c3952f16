"""Skeletons compared: resampling, start rotations and ICP (eqs. 5-12..5-14), and the symmetric dissimilarity."""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import BolusError
from ..rng import as_rng
from .skeleton_graphs import (  # noqa: F401 (re-exported)
    CONTOUR_SAMPLES,
    FEATURE_DIMENSIONS,
    _finite_points,
    _symmetric,
    _weights_from_lengths,
    contour_graph,
    contour_samples,
    link_components,
    mesh_graph,
)

SAMPLES = 64  #: points per resampled skeleton


@dataclass
class Skeleton:
    """A feature skeleton (5.2.2) of s points in a d-dimensional feature space (d = 3)."""

    points: np.ndarray  #: (s,d) feature-space coordinates (rows of the embedding)
    edges: np.ndarray  #: (e,2) int64 pairs of point indices (a tree: e = s - 1)
    centre: int  #: index of the centre vertex v0's point
    kinds: tuple  #: (s,) 'centre', 'branch', 'rendezvous' or 'end'
    vertices: np.ndarray  #: (s,) int64 graph vertex (mesh vertex or contour pixel) of each point
    labels: np.ndarray  #: (n,) int64 set (GMM cluster, or part of a divided one) of every graph vertex

    @property
    def ends(self) -> np.ndarray:
        """Indices of the 'end' points."""
        return np.array([i for i, k in enumerate(self.kinds) if k == "end"], dtype=np.int64)

    @property
    def length(self) -> float:
        """Total length of the segments in the feature space."""
        if len(self.edges) == 0:
            return 0.0
        return float(np.linalg.norm(self.points[self.edges[:, 0]] - self.points[self.edges[:, 1]], axis=1).sum())


def resample(skel: Skeleton, count: int = SAMPLES) -> np.ndarray:
    """(count,d) points evenly spaced by length along the skeleton's segments (at the middles of count equal
    steps); a skeleton without length gives count copies of its centre."""
    count = int(count)
    if count < 1:
        raise BolusError(f"resample needs at least 1 point, got {count}")
    P = np.asarray(skel.points, dtype=np.float64)
    if len(skel.edges) == 0:
        return np.repeat(P[[skel.centre]], count, axis=0)
    a, b = P[skel.edges[:, 0]], P[skel.edges[:, 1]]
    seg = np.linalg.norm(b - a, axis=1)
    total = float(seg.sum())
    if total <= 0:
        return np.repeat(P[[skel.centre]], count, axis=0)
    cum = np.r_[0.0, np.cumsum(seg)]
    t = (np.arange(count) + 0.5) * total / count
    e = np.clip(np.searchsorted(cum, t, side="right") - 1, 0, len(seg) - 1)
    frac = np.where(seg[e] > 0, (t - cum[e]) / np.where(seg[e] > 0, seg[e], 1.0), 0.0)
    return a[e] + frac[:, None] * (b[e] - a[e])


def skeleton_samples(skel: Skeleton, count: int = SAMPLES) -> np.ndarray:
    """`resample`d points (count,d), centred at the centre point v0 and scaled to unit RMS radius about it."""
    S = resample(skel, count) - np.asarray(skel.points, dtype=np.float64)[skel.centre]
    rms = float(np.sqrt((S**2).sum(axis=1).mean()))
    return S / rms if rms > 0 else S


def start_rotations(count: int = 48, rng=0) -> np.ndarray:
    """(count,3,3) starting orientations for `icp`: the identity first, then the 24 rotations of the cube each
    followed by its mirror image (-R), then random rotations from ``rng`` (module doc)."""
    count = int(count)
    if count < 1:
        raise BolusError(f"icp needs at least 1 starting orientation, got {count}")
    rots = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            M = np.zeros((3, 3))
            M[np.arange(3), perm] = signs
            if np.linalg.det(M) > 0:
                rots.append(M)
    rots.sort(key=lambda M: (-np.trace(M), tuple(M.ravel())))  # identity first
    mats = [m for R in rots for m in (R, -R)]
    g = as_rng(rng)
    while len(mats) < count:
        q, rr = np.linalg.qr(g.standard_normal((3, 3)))
        q = q * np.sign(np.diag(rr))
        mats.append(q if np.linalg.det(q) > 0 else -q)
    return np.array(mats[:count])


def _kabsch(Y: np.ndarray, Z: np.ndarray, det: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched eq. 5-13: R (s,3,3) with det(R) = det (s,), T (s,3) minimising sum |R y_i + T - z_i|^2 for
    Y (n,3) and Z (s,n,3)."""
    my = Y.mean(axis=0)
    mz = Z.mean(axis=1)
    H = np.einsum("ni,snj->sij", Y - my, Z - mz[:, None, :])
    U, _, Vt = np.linalg.svd(H)
    V, Ut = Vt.transpose(0, 2, 1), U.transpose(0, 2, 1)
    d = np.sign(np.linalg.det(V @ Ut))
    d[d == 0] = 1.0
    Dg = np.ones((len(H), 1, 3))
    Dg[:, 0, 2] = d * det
    R = (V * Dg) @ Ut  # V diag(1, 1, d det) U^T
    T = mz - np.einsum("sij,j->si", R, my)
    return R, T


def icp(X, Y, iterations: int = 50, starts: int = 48, rng=0, tol: float = 1e-12):
    """Iterative closest points (eqs. 5-12..5-14): Y (n,3) moved onto X (m,3).

    From every orientation of `start_rotations` (``starts`` of them, translation matching the centroids) at
    once: pair each moved y_i with its closest x (Z, eq. 5-12), refit (R, T) to the pairs (eq. 5-13), at most
    ``iterations`` times or until no start's error moves by more than ``tol``.  Returns (R (3,3), T (3,),
    error) of the best start, error = RMS over i of |R y_i + T - z_i| (eq. 5-14) with z_i the closest x."""
    X = _finite_points(X, 3, "the points to match (X)")
    Y = _finite_points(Y, 3, "the points to move (Y)")
    if len(X) == 0 or len(Y) == 0:
        raise BolusError("icp needs at least one point in each set")
    if int(iterations) < 0:
        raise BolusError(f"iterations must be >= 0, got {iterations}")
    R = start_rotations(starts, rng)
    det = np.sign(np.linalg.det(R))
    T = X.mean(axis=0) - np.einsum("sij,j->si", R, Y.mean(axis=0))
    tree = cKDTree(X)
    s, n = len(R), len(Y)

    def pair(R, T):
        moved = np.einsum("sij,nj->sni", R, Y) + T[:, None, :]
        d, j = tree.query(moved.reshape(-1, 3))
        return np.sqrt((d.reshape(s, n) ** 2).mean(axis=1)), X[j.reshape(s, n)]

    err, Z = pair(R, T)
    for _ in range(int(iterations)):
        R_new, T_new = _kabsch(Y, Z, det)
        err_new, Z_new = pair(R_new, T_new)
        better = err_new <= err  # a start never gets worse (guards against round-off)
        R[better], T[better], Z[better] = R_new[better], T_new[better], Z_new[better]
        moved = float(np.abs(err - np.where(better, err_new, err)).max())
        err = np.where(better, err_new, err)
        if moved <= tol:
            break
    b = int(np.argmin(err))
    return R[b], T[b], float(err[b])


def dissimilarity(a, b, count: int = SAMPLES, iterations: int = 50, starts: int = 48) -> float:
    """Symmetric dissimilarity of two skeletons (module doc, 5.3): a and b are `Skeleton`s or their
    `skeleton_samples` (count,3); the mean of the RMS errors (eq. 5-14) of ICP a->b and b->a."""
    A = skeleton_samples(a, count) if isinstance(a, Skeleton) else _finite_points(a, 3, "skeleton samples")
    B = skeleton_samples(b, count) if isinstance(b, Skeleton) else _finite_points(b, 3, "skeleton samples")
    return 0.5 * (icp(A, B, iterations, starts)[2] + icp(B, A, iterations, starts)[2])
