"""Island layout: minimum-area orientation and shelf packing, rigid motions only."""
import numpy as np
import pytest
from meshgen import grid

from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.geometry2d import cross2d
from bolus_addon.core.mesh.layout import orient_island, pack_islands, pack_transforms, rotate


def edge_lengths(UV, F):
    return np.linalg.norm(UV[F] - UV[np.roll(F, -1, axis=1)], axis=2)


def signed_areas(UV, F):
    a, b, c = UV[F[:, 0]], UV[F[:, 1]], UV[F[:, 2]]
    return 0.5 * cross2d(b - a, c - a)


def islands_fixture(seed=0):
    """Seven grids of different sizes, jittered, turned and moved at random: [(UV, F)]."""
    g = np.random.default_rng(seed)
    out = []
    for k, (nx, ny, sx, sy) in enumerate([(6, 3, 80, 30), (4, 4, 40, 40), (8, 2, 120, 15), (3, 5, 25, 60),
                                          (2, 2, 10, 10), (5, 5, 55, 45), (7, 3, 70, 20)]):
        V, F = grid(nx, ny, 1.0, jitter=0.25, rng=k)
        UV = rotate(V[:, :2] * [sx, sy], g.uniform(-np.pi, np.pi)) + g.uniform(-500, 500, 2)
        out.append((UV, F))
    return out


def test_orient_rotated_rectangle():
    R = np.array([[0.0, 0], [30, 0], [30, 10], [0, 10]])
    for turn in (0.3, -1.2, 2.5, np.pi / 2):
        out, angle = orient_island(rotate(R, turn) + [7, -3])
        size = np.ptp(out, axis=0)
        np.testing.assert_allclose(size, [30, 10], atol=1e-9)  # long side along x
        np.testing.assert_allclose(out, rotate(rotate(R, turn) + [7, -3], angle))
        assert -np.pi < angle <= np.pi
        assert np.isclose(np.sin(2 * (angle + turn)), 0, atol=1e-9)  # turned back by a multiple of pi/2


def test_orient_tall_island_lies_down_and_keeps_handedness():
    V, F = grid(2, 6, 1.0, jitter=0.2)
    UV = V[:, :2] * [10, 60]
    out, angle = orient_island(UV)
    w, h = np.ptp(out, axis=0)
    assert w >= h and w == pytest.approx(60, abs=1.0)
    np.testing.assert_allclose(edge_lengths(out, F), edge_lengths(UV, F), rtol=0, atol=1e-12)
    np.testing.assert_allclose(signed_areas(out, F), signed_areas(UV, F), rtol=0, atol=1e-10)  # no mirroring


def test_orient_finds_the_minimum_area_rectangle():
    P = np.random.default_rng(3).normal(size=(200, 2)) * [40, 9] @ np.array([[1, 0.4], [0, 1]])
    out, _ = orient_island(P)
    best = np.prod(np.ptp(out, axis=0))
    for a in np.linspace(0, np.pi / 2, 2001):
        assert np.prod(np.ptp(rotate(P, a), axis=0)) >= best * (1 - 1e-9)


def test_orient_degenerate_islands():
    out, angle = orient_island(np.array([[5.0, 5.0]]))
    np.testing.assert_array_equal(out, [[5, 5]])
    assert angle == 0
    seg = np.array([[0.0, 0], [3, 4], [6, 8]])  # collinear: laid along x
    out, _ = orient_island(seg)
    assert np.ptp(out[:, 1]) < 1e-12 and np.ptp(out[:, 0]) == pytest.approx(10)


def bbox_gap(a, b):
    """Separation of two axis-aligned boxes ((2,), (2,)) along the better axis (negative: overlap)."""
    (alo, ahi), (blo, bhi) = a, b
    return max(blo[0] - ahi[0], alo[0] - bhi[0], blo[1] - ahi[1], alo[1] - bhi[1])


@pytest.mark.parametrize("gap", [0.0, 10.0, 3.5])
def test_pack_keeps_gaps_and_distances(gap):
    data = islands_fixture()
    moved = pack_islands([UV for UV, _ in data], gap_mm=gap)
    assert len(moved) == len(data)
    boxes = [(M.min(axis=0), M.max(axis=0)) for M in moved]
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            assert bbox_gap(boxes[i], boxes[j]) >= gap - 1e-9, (i, j)
    allpts = np.concatenate(moved)
    assert allpts.min() >= 0
    np.testing.assert_allclose(allpts.min(axis=0), [0, 0], atol=1e-12)  # origin at the bottom-left
    for (UV, F), M in zip(data, moved):  # input order, rigid: every distance and the handedness kept
        assert M.shape == UV.shape
        np.testing.assert_allclose(edge_lengths(M, F), edge_lengths(UV, F), rtol=1e-12, atol=1e-12)
        D0 = np.linalg.norm(UV[:, None] - UV[None], axis=2)
        np.testing.assert_allclose(np.linalg.norm(M[:, None] - M[None], axis=2), D0, rtol=0, atol=1e-9)
        np.testing.assert_allclose(signed_areas(M, F), signed_areas(UV, F), rtol=1e-10)
        w, h = np.ptp(M, axis=0)
        assert w >= h - 1e-9


def test_pack_rows_respect_the_width():
    data = [UV for UV, _ in islands_fixture(1)]
    widest = max(np.ptp(orient_island(UV)[0][:, 0]) for UV in data)
    for width in (widest, 200.0, 1000.0):
        moved = pack_islands(data, gap_mm=5.0, max_row_width_mm=max(width, widest))
        assert np.concatenate(moved)[:, 0].max() <= max(width, widest) + 1e-9
    one_row = pack_islands(data, gap_mm=5.0, max_row_width_mm=1e6)
    assert np.ptp(np.array([M[:, 1].min() for M in one_row])) == 0  # all on the bottom row
    default = pack_islands(data, gap_mm=5.0)
    w, h = np.ptp(np.concatenate(default), axis=0)
    assert 0.73 < h / w < 0.99  # roughly square sheet, not a long strip (0.862 measured)


def test_pack_transforms_reproduce_the_packing():
    data = [UV for UV, _ in islands_fixture(2)]
    moved = pack_islands(data, gap_mm=7.0)
    for UV, M, (angle, t) in zip(data, moved, pack_transforms(data, gap_mm=7.0)):
        np.testing.assert_allclose(rotate(UV, angle) + t, M, atol=1e-9)


def test_pack_single_and_empty():
    assert pack_islands([]) == []
    UV = np.array([[10.0, 10], [20, 10], [10, 40]])
    (M,) = pack_islands([UV])
    np.testing.assert_allclose(M.min(axis=0), 0, atol=1e-12)


def test_pack_rejects_bad_input():
    with pytest.raises(BolusError):
        pack_islands([np.zeros((3, 3))])
    with pytest.raises(BolusError):
        pack_islands([np.zeros((0, 2))])
    with pytest.raises(BolusError):
        pack_islands([np.array([[0.0, np.nan]])])
    with pytest.raises(BolusError):
        pack_islands([np.zeros((3, 2))], gap_mm=-1)
    with pytest.raises(BolusError):
        pack_islands([np.zeros((3, 2))], max_row_width_mm=0)


# ------------------------------------------------------------------ print parts on the plate
from bolus_addon.core.mesh.layout import centre_on_plate, plate_layout  # noqa: E402
from bolus_addon.core.printing.orientation import rotation_to_z  # noqa: E402


def _parts(seed=0):
    rng = np.random.default_rng(seed)
    parts = [rng.standard_normal((60, 3)) * s + o for s, o in
             (([30, 10, 5], [100, 0, 0]), ([5, 40, 8], [0, -50, 20]), ([12, 12, 12], [0, 0, 0]))]
    dirs = rng.standard_normal((3, 3))
    return parts, [rotation_to_z(d) for d in dirs], dirs / np.linalg.norm(dirs, axis=1, keepdims=True)


def test_plate_layout_keeps_build_direction_up_rests_on_plate_and_separates_parts():
    parts, rots, dirs = _parts()
    placed = plate_layout(parts, rots, gap_mm=10.0)
    boxes = []
    for V, d, (R, t) in zip(parts, dirs, placed):
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(R @ d, [0, 0, 1], atol=1e-12)  # the build direction stays +Z
        W = V @ R.T + t
        assert W[:, 2].min() == pytest.approx(0.0, abs=1e-9)
        np.testing.assert_allclose(np.linalg.norm(W[1:] - W[:-1], axis=1), np.linalg.norm(V[1:] - V[:-1], axis=1))
        boxes.append((W[:, :2].min(axis=0), W[:, :2].max(axis=0)))
    for i in range(3):
        for j in range(i + 1, 3):
            (lo1, hi1), (lo2, hi2) = boxes[i], boxes[j]
            gap = np.maximum(lo2 - hi1, lo1 - hi2).max()  # separated along x or y
            assert gap >= 10.0 - 1e-9
    assert min(b[0].min() for b in boxes) == pytest.approx(0.0, abs=1e-9)


def test_centre_on_plate_and_bad_input():
    W = np.array([[1.0, 2.0, 3.0], [5.0, -4.0, 7.0]])
    np.testing.assert_allclose(W + centre_on_plate(W), [[-2.0, 3.0, 0.0], [2.0, -3.0, 4.0]])
    np.testing.assert_array_equal(centre_on_plate(np.zeros((0, 3))), np.zeros(3))
    parts, rots, _ = _parts()
    bad = parts[0].copy()
    bad[7, 1] = np.nan
    with pytest.raises(BolusError, match="non-finite"):
        centre_on_plate(bad)
    with pytest.raises(BolusError, match="part 0 has non-finite"):
        plate_layout([bad] + parts[1:], rots)
    with pytest.raises(BolusError, match="not a proper 3x3 rotation"):
        plate_layout(parts, [np.diag([1.0, 1.0, -1.0])] + rots[1:])
    with pytest.raises(BolusError, match="3 parts but 2 rotations"):
        plate_layout(parts, rots[:2])
    # a part squashed to a point or a segment in the footprint is still placed
    flat = [np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 5.0]]), np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]])]
    out = plate_layout(flat, [np.eye(3), np.eye(3)])
    assert all(np.isfinite(R).all() and np.isfinite(t).all() for R, t in out)
