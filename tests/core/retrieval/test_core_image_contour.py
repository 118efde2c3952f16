"""The object's contour by spectral clustering of edge pixels (core/image_contour.py, seed eqs. 5-5..5-7)."""
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from bolus_addon.core.errors import BolusError
from bolus_addon.core.retrieval.image_contour import N_MAX, contour_pixels, cut_ratio, outer_contour, sample_grid
from bolus_addon.core.retrieval.image_edges import edge_mask

DISC = (0.95, 0.6, 0.45)


def disc_scene(seed=0, H=300, W=400, cx=180, cy=150, R=80, texture=0.03, noise=0.02, line_x=348):
    """(H,W,3) float: a flat-coloured disc on a textured background (colour blotches, fine grain, noise) with
    background edges: a dark 2-px line from y = 30 to 269 at x = line_x and a grey square at (20..59, 240..274)."""
    rng = np.random.default_rng(seed)
    low = gaussian_filter(rng.random((H, W, 3)), (25, 25, 0))
    low = (low - low.min()) / np.ptp(low)
    img = 0.35 + 0.2 * low * np.array([0.6, 1.0, 0.7])
    grain = gaussian_filter(rng.normal(0.0, 1.0, (H, W)), 1.5)
    img += (texture * grain / grain.std())[..., None]
    img[30:270, line_x:line_x + 2] = (0.15, 0.15, 0.2)
    img[240:275, 20:60] = (0.6, 0.6, 0.65)
    yy, xx = np.mgrid[:H, :W]
    img[(xx - cx) ** 2 + (yy - cy) ** 2 <= R * R] = DISC
    img += rng.normal(0.0, noise, (H, W, 3))
    return np.clip(img, 0.0, 1.0)


def check_circle(points, cx, cy, R, tol=2.0, min_cover=0.9):
    """Every point within tol px of the circle; the points cover >= min_cover of its angles (2-degree bins)."""
    assert points.ndim == 2 and points.shape[1] == 2 and len(points) > 0
    r = np.hypot(points[:, 0] - cx, points[:, 1] - cy)
    assert np.abs(r - R).max() <= tol, f"contour points up to {np.abs(r - R).max():.2f} px off the circle"
    ang = np.degrees(np.arctan2(points[:, 1] - cy, points[:, 0] - cx)) % 360.0
    cover = np.unique((ang // 2).astype(int)).size / 180.0
    assert cover >= min_cover, f"the contour covers {cover:.0%} of the circle's angles"


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_disc_on_textured_background(seed):
    img = disc_scene(seed)
    mask = edge_mask(img)
    res = contour_pixels(img, mask, rng=0)
    # the object cluster is the disc: its pixels lie on the disc's outline
    obj = res.object_points
    d = np.abs(np.hypot(obj[:, 0] - 180, obj[:, 1] - 150) - 80)
    assert d.max() <= 3.0
    check_circle(res.points, 180, 150, 80)
    # the background's edges are found (the line, the square, texture) but are not the object
    ep = res.edge_points
    on_line = (ep[:, 0] >= 344) & (ep[:, 0] <= 353) & (ep[:, 1] >= 30) & (ep[:, 1] < 270)
    assert on_line.sum() > 300, "the edge detection finds the background line"
    assert (res.labels[on_line] == 0).all(), "the line is background"
    assert (res.points[:, 0] < 300).all(), "no contour point near the line"
    far = np.abs(np.hypot(ep[:, 0] - 180, ep[:, 1] - 150) - 80) > 5
    assert far.sum() > 2000 and (res.labels[far] == 0).all(), "texture and square edges are background"
    assert res.object_label == 1 and set(np.unique(res.labels)) == {0, 1}
    assert res.labels.shape == (len(ep),) and ep.shape == (int(mask.sum()), 2)


def test_points_are_x_right_y_down_and_ordered():
    """An off-centre disc (up and left of the middle): points are (column, row), ordered by angle."""
    img = disc_scene(7, cx=120, cy=100, R=60, line_x=360)
    res = contour_pixels(img)
    check_circle(res.points, 120, 100, 60)
    c = res.points.mean(axis=0)
    assert abs(c[0] - 120) < 1.5 and abs(c[1] - 100) < 1.5
    ang = np.arctan2(res.points[:, 1] - c[1], res.points[:, 0] - c[0])
    assert (np.diff(ang) >= 0).all()


def test_clean_disc_and_line():
    H, W = 300, 400
    yy, xx = np.mgrid[:H, :W]
    img = np.full((H, W, 3), 0.5)
    img[(xx - 180) ** 2 + (yy - 150) ** 2 <= 80 ** 2] = (0.9, 0.6, 0.4)
    img[30:270, 348:350] = 0.1
    res = contour_pixels((img * 255).astype(np.uint8))
    check_circle(res.points, 180, 150, 80, min_cover=0.99)
    assert len(res.splits) >= 2, "line, then the background side of the disc's edge, split off"


def test_same_seed_same_result():
    img = disc_scene(3)
    a, b = contour_pixels(img, rng=5), contour_pixels(img, rng=5)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.labels, b.labels)


def test_large_photo_is_sampled():
    """800 x 600 with a large disc: at most N_MAX samples in the eigenproblem, the contour still on the circle."""
    img = disc_scene(11, H=600, W=800, cx=420, cy=280, R=230, line_x=740)
    mask = edge_mask(img)
    res = contour_pixels(img, mask)
    assert mask.sum() > N_MAX and res.samples <= N_MAX
    check_circle(res.points, 420, 280, 230)


def test_sample_grid_even_and_bounded():
    rng = np.random.default_rng(0)
    xy = np.unique(rng.integers(0, 500, (40_000, 2)), axis=0)
    idx, s = sample_grid(xy, 3000)
    assert len(idx) <= 3000 and s >= 2
    cells = {(int(x) // s, int(y) // s) for x, y in xy[idx]}
    assert len(cells) == len(idx), "one sample per cell"
    every = {(int(x) // s, int(y) // s) for x, y in xy}
    assert cells == every, "every occupied cell has its sample"
    assert sample_grid(xy[:100], 3000)[1] == 1


def test_outer_contour_keeps_the_outline_only():
    """Object pixels: an outline (a 3-px ring at R 60) with a 12 px gap, an inner edge (circle R 20) and a far
    speck; the contour is the ring's outermost pixels, not its inner side, the inner edge nor the speck."""
    H, W = 300, 400
    yy, xx = np.mgrid[:H, :W]
    r = np.hypot(xx - 200, yy - 150)
    obj = (np.abs(r - 60) <= 1.5) | (np.abs(r - 20) <= 1.0)
    obj[(np.abs(yy - 150) <= 6) & (xx > 200)] = False  # the gap, at the right (closing radius: 10 px)
    obj[10:13, 10:13] = True  # a speck
    out = outer_contour(obj)
    ys, xs = np.nonzero(out)
    rr = r[ys, xs]
    at_gap = (np.abs(ys - 150) <= 8) & (xs > 200)  # the ends of the ring beside the gap are outline too
    assert (rr[~at_gap] >= 60.5).all() and (rr <= 61.5).all() and at_gap.sum() <= 12
    ang = np.degrees(np.arctan2(ys - 150, xs - 200)) % 360
    assert np.unique((ang // 5).astype(int)).size >= 72 - 3  # all around but the gap
    # a gap wider than the closing: nothing is filled, the ring's pixels on both sides are contour
    obj[(np.abs(yy - 150) <= 20) & (xx > 200)] = False
    rr = r[outer_contour(obj)]
    assert rr.min() < 59.5 and rr.max() > 60.5


def test_cut_ratio():
    import scipy.sparse as sp

    W = sp.csr_matrix(np.array([[0, 1, 0.01, 0], [1, 0, 0, 0], [0.01, 0, 0, 1], [0, 0, 1, 0]], float))
    side = np.array([True, True, False, False])
    assert cut_ratio(W, side) == pytest.approx(0.01 / np.mean([1, 1, 0.01, 0.01, 1, 1]))
    assert cut_ratio(sp.csr_matrix(np.array([[0, 1.0], [1.0, 0]])), np.array([True, True])) == 0.0


# --- refusals -----------------------------------------------------------------------------------------

def test_constant_image_refused():
    with pytest.raises(BolusError, match="no edges"):
        contour_pixels(np.full((300, 400, 3), 0.5))


def test_too_few_edge_pixels_refused():
    img = disc_scene(0)
    mask = np.zeros(img.shape[:2], bool)
    mask[100, 100:110] = True
    with pytest.raises(BolusError, match="no edges to find a contour"):
        contour_pixels(img, mask)


@pytest.mark.parametrize("img, words", [
    (np.zeros((1, 1, 3)), "at least 2 x 2"),
    (np.where(np.eye(30)[..., None] > 0, np.nan, 0.5) * np.ones(3), "NaN"),
    (np.zeros((30, 30, 5)), "shape"),
])
def test_bad_images_refused(img, words):
    with pytest.raises(BolusError, match=words):
        contour_pixels(img)


@pytest.mark.parametrize("kw, words", [
    (dict(mask=np.ones((10, 10), bool)), "edge mask must be 300 x 400"),
    (dict(mask=np.full((300, 400), 0.5)), "boolean"),
    (dict(w=-1.0), "colour weight"),
    (dict(w="x"), "colour weight"),
    (dict(neighbours=1), "neighbours"),
    (dict(max_points=10), "max_points"),
])
def test_bad_parameters_refused(kw, words):
    with pytest.raises(BolusError, match=words):
        contour_pixels(disc_scene(0), **kw)
