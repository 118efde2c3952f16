"""The rim wall as a ruled strip (core.solid.rim_wall) and the shell made with it
(make_shell(rim="strip")): rulings, folds, the signed distance, closedness, and a smoother rim."""
from __future__ import annotations

import numpy as np
import pytest

from bolus_addon.core.mesh.crossings import crossing_pairs
from bolus_addon.core.solid.distance_field import SkinDistance
from bolus_addon.core.solid.manifold import SIDE_RIM, closed_report
from bolus_addon.core.solid.rim_wall import _folded_columns, smoothed_border_normals, unfolded_rulings
from bolus_addon.core.solid.shell import make_shell
from meshgen import grid
from paths import import_bench


def _circle(n=120, radius=40.0):
    a = 2 * np.pi * np.arange(n) / n
    return np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros(n)], axis=1)


def test_smoothing_keeps_unit_rulings_across_the_loop_and_evens_out_noise():
    P = _circle()
    rng = np.random.default_rng(3)
    N = np.tile([0.0, 0.0, 1.0], (len(P), 1)) + 0.2 * rng.standard_normal((len(P), 3))
    S = smoothed_border_normals(P, N, sigma=4.0)
    assert np.allclose(np.linalg.norm(S, axis=1), 1.0)
    T = np.roll(P, -1, axis=0) - np.roll(P, 1, axis=0)
    assert np.abs(np.einsum("ij,ij->i", S, T / np.linalg.norm(T, axis=1)[:, None])).max() < 1e-9
    # neighbouring rulings turn far less than the noisy ones
    step = lambda M: np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", M, np.roll(M, 1, axis=0)), -1, 1)))
    raw = N / np.linalg.norm(N, axis=1)[:, None]
    assert step(S).mean() < 0.25 * step(raw).mean()


def test_rulings_that_cross_are_unfolded():
    # upright rulings round a circle but for six that lean towards each other by 60 degrees (a
    # dent in the skin at the border): they cross a few mm up, the strip folds there; after
    # unfolding no column folds and the rulings far from the dent stay upright
    P = _circle(120, 40.0)
    N = np.tile([0.0, 0.0, 1.0], (len(P), 1))
    T = np.roll(P, -1, axis=0) - P
    T /= np.linalg.norm(T, axis=1)[:, None]
    for i, sign in zip(range(40, 46), (1, 1, 1, -1, -1, -1)):
        N[i] = 0.5 * N[i] + sign * 0.866 * T[i]
    assert len(_folded_columns(P, N, 1.0, 15.0)) > 0
    U = unfolded_rulings(P, N, 1.0, 15.0)
    assert len(_folded_columns(P, U, 1.0, 15.0)) == 0
    assert np.allclose(np.linalg.norm(U, axis=1), 1.0)
    assert np.allclose(U[:20], [0.0, 0.0, 1.0]) and np.allclose(U[80:], [0.0, 0.0, 1.0])


def test_strip_distance_is_signed_towards_the_region():
    V, F = grid(20, 20, 100.0)
    skin = SkinDistance(V, F, rim="strip")
    wall = skin.wall(10.0, 1.5)
    c = V.mean(axis=0)
    inside = np.array([c + [0.0, 0.0, 5.0], [3.0, 50.0, 4.0]])   # above the region, 3 mm from its x = 0 edge
    outside = np.array([[-3.0, 50.0, 4.0], [50.0, 104.0, 2.0]])  # beyond the x = 0 and y = 100 edges
    s_in, _ = wall.signed(inside)
    s_out, _ = wall.signed(outside)
    assert np.all(s_in > 0) and np.all(s_out < 0)
    assert s_in[1] == pytest.approx(3.0, abs=1e-6) and s_out[0] == pytest.approx(-3.0, abs=1e-6)


def test_rim_must_be_known():
    V, F = grid(4, 4, 40.0)
    with pytest.raises(ValueError, match="rim must be one of"):
        SkinDistance(V, F, rim="round")


def test_strip_rim_shell_is_closed_and_smoother_than_the_faces_rim():
    """The demo's nose region at 0.5 mm: the faces rule creases the wall at every border vertex
    (the planes normal to the border faces), the strip runs along the smoothed normals."""
    sb = import_bench("shell_bench")
    region = sb.example_region()
    V, F = region["V"], region["F"]
    shells = {rim: make_shell(V, F, 10.0, 0.0, 0.5, rim=rim) for rim in ("faces", "strip")}
    p95 = {}
    for rim, S in shells.items():
        rep = closed_report(S.V, S.F)
        assert rep["closed"], (rim, rep)
        assert S.warnings == [], (rim, S.warnings)
        # no triangle of the wall crosses another, with the positions as an STL file holds them
        assert len(crossing_pairs(S.V, S.F, np.nonzero(S.side == SIDE_RIM)[0], float32=True)) == 0, rim
        res = sb.rim_residuals(S.V, S.F, S.side == SIDE_RIM)
        assert len(res) > 5000
        p95[rim] = float(np.percentile(res, 95))
    assert shells["strip"].volume_mm3 == pytest.approx(shells["faces"].volume_mm3, rel=0.02)
    assert p95["strip"] < 0.5 * p95["faces"], p95
    assert shells["strip"].stats["crease_edges_split"] > 0
