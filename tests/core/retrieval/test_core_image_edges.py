"""Edges by visual entropies (core/image_edges.py, seed eqs. 5-1..5-4) on synthetic images with known answers."""
import numpy as np
import pytest

from bolus_addon.core.errors import BolusError
from bolus_addon.core.retrieval.image_edges import (
    as_image,
    block_entropies,
    block_entropy,
    edge_blocks,
    edge_mask,
    intensity,
)

H, W = 300, 400
X0, X1, Y0, Y1 = 100, 300, 80, 220  # the rectangle: columns X0..X1-1, rows Y0..Y1-1


def rectangle(noise=0.0, seed=1, background=0.3, fill=0.7):
    """(H,W,3) float: a grey rectangle on a plain background, optional seeded gaussian noise."""
    img = np.full((H, W, 3), background)
    img[Y0:Y1, X0:X1] = fill
    if noise:
        img = np.clip(img + np.random.default_rng(seed).normal(0.0, noise, (H, W, 1)), 0.0, 1.0)
    return img


def side_distance(ys, xs):
    """Distance (px) of pixel centres (x, y) to the rectangle's outline (the lines between its edge pixels
    and the background's)."""
    x, y = np.asarray(xs, float), np.asarray(ys, float)
    lx, hx, ly, hy = X0 - 0.5, X1 - 0.5, Y0 - 0.5, Y1 - 0.5
    dx = np.maximum(np.maximum(lx - x, x - hx), 0.0)
    dy = np.maximum(np.maximum(ly - y, y - hy), 0.0)
    outside = np.hypot(dx, dy)
    inside = np.minimum.reduce([x - lx, hx - x, y - ly, hy - y])
    return np.where((dx > 0) | (dy > 0), outside, inside)


def side_pixels():
    """(rows, cols) of the rectangle's own outermost pixels (the sides to be found)."""
    m = np.zeros((H, W), bool)
    m[Y0, X0:X1] = m[Y1 - 1, X0:X1] = True
    m[Y0:Y1, X0] = m[Y0:Y1, X1 - 1] = True
    return np.nonzero(m)


def covered(mask, within=1):
    """Share of the side pixels with an edge pixel at most `within` px away (chessboard)."""
    from scipy.ndimage import binary_dilation

    grown = binary_dilation(mask, structure=np.ones((3, 3)), iterations=within)
    ys, xs = side_pixels()
    return float(grown[ys, xs].mean())


# --- eq. 5-2 ---------------------------------------------------------------------------------------------

def test_intensity_weights_exact():
    img = np.zeros((2, 3, 3))
    img[0, 0] = (1, 0, 0)
    img[0, 1] = (0, 1, 0)
    img[0, 2] = (0, 0, 1)
    img[1, 0] = (0.2, 0.4, 0.6)
    img[1, 1] = 1.0
    out = intensity(img)
    assert out.shape == (2, 3)
    assert out[0, 0] == pytest.approx(0.299, abs=1e-15)
    assert out[0, 1] == pytest.approx(0.587, abs=1e-15)
    assert out[0, 2] == pytest.approx(0.114, abs=1e-15)
    assert out[1, 0] == pytest.approx(0.299 * 0.2 + 0.587 * 0.4 + 0.114 * 0.6, abs=1e-15)
    assert out[1, 1] == pytest.approx(1.0, abs=1e-12)
    assert out[1, 2] == 0.0


def test_intensity_uint8_and_float_agree_gray_and_rgba():
    rng = np.random.default_rng(0)
    u8 = rng.integers(0, 256, (20, 30, 3), dtype=np.uint8)
    f = u8 / 255.0
    expect = 0.299 * f[..., 0] + 0.587 * f[..., 1] + 0.114 * f[..., 2]
    np.testing.assert_allclose(intensity(u8), expect, atol=1e-12)
    np.testing.assert_allclose(intensity(f), expect, atol=1e-12)
    rgba = np.concatenate([u8, rng.integers(0, 256, (20, 30, 1), dtype=np.uint8)], axis=2)
    np.testing.assert_allclose(intensity(rgba), expect, atol=1e-12)  # alpha ignored
    g = rng.random((20, 30))
    np.testing.assert_array_equal(intensity(g), g)  # grey is already the intensity
    assert as_image(u8.astype(np.uint16) * 257).max() == pytest.approx(u8.max() / 255.0)


# --- eqs. 5-1, 5-3, 5-4 --------------------------------------------------------------------------------

def test_constant_block_entropies():
    texture, edge = block_entropies(np.full((3, 3), 0.4))
    assert texture.shape == (1, 1) and texture[0, 0] == 0.0
    assert edge[0, 0] == pytest.approx(1.0)  # 1 * e^0


def test_two_level_half_and_half_block():
    g = np.array([[0.2, 0.2], [0.8, 0.8]])
    texture, edge = block_entropies(g, k=2)
    assert texture[0, 0] == pytest.approx(np.log(2.0), abs=1e-12)
    assert edge[0, 0] == pytest.approx(np.exp(0.5), abs=1e-12)  # 2 * 1/2 e^(1/2)


@pytest.mark.parametrize("counts", [(1, 8), (3, 3, 3), (2, 3, 4), (1, 1, 1, 1, 1, 1, 1, 1, 1), (4, 5)])
def test_entropies_hand_computed(counts):
    values = np.concatenate([np.full(c, 0.05 + 0.1 * i) for i, c in enumerate(counts)])  # levels 0.1 apart
    g = np.random.default_rng(len(counts)).permutation(values).reshape(3, 3)
    texture, edge = block_entropies(g, k=3, levels=32)
    p = np.array(counts) / 9.0
    assert texture[0, 0] == pytest.approx(-(p * np.log(p)).sum(), abs=1e-12)  # eq. 5-1
    assert edge[0, 0] == pytest.approx((p * np.exp(1.0 - p)).sum(), abs=1e-12)  # eq. 5-3
    E = block_entropy(texture, edge, eta=(0.3, 2.0))  # eq. 5-4
    assert E[0, 0] == pytest.approx(0.3 * texture[0, 0] + 2.0 * edge[0, 0])


def test_bins_count_from_the_darkest_pixel():
    """Values less than one level apart are one level, wherever they fall on [0, 1] (module doc, step 2):
    0.030 and 0.034 straddle the fixed bin boundary 1/32 but are one level."""
    g = np.array([[0.030, 0.034, 0.031], [0.032, 0.033, 0.030], [0.034, 0.031, 0.032]])
    texture, edge = block_entropies(g, k=3, levels=32)
    assert texture[0, 0] == 0.0 and edge[0, 0] == pytest.approx(1.0)
    g2 = g.copy()
    g2[0, 0] = 0.030 + 1.0 / 32 + 1e-6  # one level above the darkest: two levels (1 and 8 pixels)
    p = np.array([1.0, 8.0]) / 9.0
    assert block_entropies(g2, k=3, levels=32)[0][0, 0] == pytest.approx(-(p * np.log(p)).sum())


def test_sliding_blocks_cover_the_right_pixels():
    """Block [r, c] covers rows r..r+k-1, columns c..c+k-1: one bright pixel makes exactly its k x k blocks busy."""
    g = np.zeros((10, 12))
    g[4, 7] = 1.0
    for k in (2, 3, 4):
        texture, _ = block_entropies(g, k=k)
        assert texture.shape == (10 - k + 1, 12 - k + 1)
        busy = np.argwhere(texture > 0)
        rows, cols = np.arange(4 - k + 1, 5), np.arange(7 - k + 1, 8)
        assert sorted(map(tuple, busy)) == [(r, c) for r in rows for c in cols]


# --- edge blocks and pixels ---------------------------------------------------------------------------

def test_edge_blocks_at_most_fraction_and_never_uniform():
    E = np.array([1.0] * 50 + [2.0] * 30 + [3.0] * 15 + [4.0] * 5)
    assert edge_blocks(E, 0.1, floor=1.0).sum() == 5  # 3.0 is tied across the 10 % line: left out
    assert edge_blocks(E, 0.2, floor=1.0).sum() == 20
    assert edge_blocks(E, 0.9, floor=1.0).sum() == 50  # never a uniform block (E = floor)
    assert edge_blocks(np.full(10, 2.0), 0.1, floor=1.0).all()  # one top value over the fraction: taken


@pytest.mark.parametrize("k", [2, 3, 4, 5])
def test_clean_step_is_a_two_pixel_line_without_blur(k):
    """The pixel rule (module doc, step 5): the two pixels beside a straight step, for every k."""
    g = np.full((40, 200), 0.2)
    g[:, 100:] = 0.8
    m = edge_mask(g, k=k, smooth=0)
    assert set(np.nonzero(m.any(axis=0))[0]) == {99, 100}
    assert m[:, 99].all() and m[:, 100].all()


def test_rectangle_plain_background():
    m = edge_mask(rectangle())
    ys, xs = np.nonzero(m)
    d = side_distance(ys, xs)
    assert (d <= 1.5 + 1e-9).mean() >= 0.99, "the two pixels on either side of each side (0.7 px blur)"
    assert d.max() <= 2.5 + 1e-9  # the 4 inner corner pixels, covered by the blocks of two sides
    assert (d > 2.0).sum() <= 4
    assert covered(m, 1) == 1.0, "every side pixel found"


def test_rectangle_uint8_and_float_agree():
    u8 = (rectangle() * 255).round().astype(np.uint8)
    np.testing.assert_array_equal(edge_mask(u8), edge_mask(u8 / 255.0))


def test_rectangle_noisy_background():
    img = rectangle(noise=0.03, seed=4)
    m, blocks = edge_mask(img, return_blocks=True)
    assert blocks.mean() <= 0.1 + 1e-12
    ys, xs = np.nonzero(m)
    near = side_distance(ys, xs) <= 2.0
    assert covered(m, 1) >= 0.95, "the sides are found through the noise"
    assert near.mean() >= 0.7, "most edge pixels lie on the sides"
    # the 0.7 px blur is what makes this work (module doc, step 1)
    ys0, xs0 = np.nonzero(edge_mask(img, smooth=0))
    assert (side_distance(ys0, xs0) <= 2.0).mean() < near.mean() - 0.3


def test_gradient_background_makes_no_edges():
    """A smooth vertical gradient (0.25 .. 0.6) crosses 11 fixed bin boundaries; with bins counted from each
    block's darkest pixel none of them is an edge (module doc, step 2)."""
    img = np.repeat((0.25 + 0.35 * np.arange(H) / H)[:, None, None], W, axis=1).repeat(3, axis=2)
    img[Y0:Y1, X0:X1] = 0.8
    m = edge_mask(img)
    ys, xs = np.nonzero(m)
    assert side_distance(ys, xs).max() <= 2.5 + 1e-9
    assert covered(m, 1) == 1.0


# --- refusals -----------------------------------------------------------------------------------------

def test_constant_image_refused():
    with pytest.raises(BolusError, match="no edges"):
        edge_mask(np.full((50, 60, 3), 128, dtype=np.uint8))


@pytest.mark.parametrize("bad, words", [
    (np.zeros((1, 1, 3)), "at least 2 x 2"),
    (np.zeros((1, 40, 3)), "at least 2 x 2"),
    (np.zeros((2, 2, 3)), "smaller than one 3 x 3 block"),
    (np.where(np.eye(20)[..., None] > 0, np.nan, 0.5) * np.ones(3), "NaN"),
    (np.full((10, 10, 3), np.inf), "NaN or infinite"),
    (np.zeros((10, 10, 2)), "shape"),
    (np.zeros((10, 10, 3, 1)), "shape"),
    (np.full((10, 10, 3), 255.0), "values in \\[0, 1\\]"),
    (np.array([["a", "b"], ["c", "d"]]), "not an image"),
    (-np.ones((10, 10, 3), dtype=np.int16), "negative"),
])
def test_bad_images_refused(bad, words):
    with pytest.raises(BolusError, match=words):
        edge_mask(bad)


@pytest.mark.parametrize("kw, words", [
    (dict(k=1), "block size k"),
    (dict(k=2.5), "block size k"),
    (dict(levels=1), "levels"),
    (dict(fraction=0), "fraction"),
    (dict(fraction=1.5), "fraction"),
    (dict(eta=(1.0,)), "eta"),
    (dict(eta=(-1.0, 1.0)), "eta"),
    (dict(smooth=-1), "smooth"),
    (dict(smooth=float("nan")), "smooth"),
])
def test_bad_parameters_refused(kw, words):
    with pytest.raises(BolusError, match=words):
        edge_mask(rectangle(), **kw)
