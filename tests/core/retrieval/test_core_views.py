"""The view matcher (core/retrieval: view_render, shape_descriptors, photo_silhouette, partial_views, views): the
rasteriser against known projections, the descriptors' invariance, the photo's silhouette against the painted
truth, the cut views against masks cut directly, the occluder taken out, the true model ranked first on photos of
views the library never saw (whole, cut by the frame, occluded), and the refusals."""
import numpy as np
import pytest
from meshgen import box, icosphere, torus
from scipy import ndimage

from bolus_addon.core.errors import BolusError
from bolus_addon.core.retrieval import partial_views as pv
from bolus_addon.core.retrieval import shape_descriptors as sd
from bolus_addon.core.retrieval import views
from bolus_addon.core.retrieval.photo_silhouette import photo_silhouette
from bolus_addon.core.retrieval.view_render import MARGIN_PX, fibonacci_directions, render_views, view_frame

BACKGROUND = (0.78, 0.84, 0.93)


def shapes():
    """Four models that differ from most sides: a long egg, a stretched ring, a flat slab, a pear."""
    egg = icosphere(3, 30.0)
    pear = icosphere(3, 30.0)
    P = pear[0].copy()
    P[:, 0] += np.where(P[:, 0] > 0, 40.0 * (P[:, 0] / 30.0) ** 2, 0.0)
    ring = torus(50.0, 16.0, 40, 14)
    return {"egg": (egg[0] * np.array([2.5, 1.0, 0.6]), egg[1]), "ring": (ring[0] * np.array([1.6, 1.0, 1.0]), ring[1]),
            "slab": box((80.0, 40.0, 12.0), 4), "pear": (P, pear[1])}


def photo(V, F, direction, rng, shape=(300, 400), background=BACKGROUND, colour=(0.8, 0.62, 0.52)):
    """(H,W,3) float: the mesh seen from ``direction``, shaded by its depth (near bright, far 40 % darker), turned
    by a random angle in the image, on a plain background with noise; and its true mask."""
    g = np.random.default_rng(rng)
    sil, z = render_views(V, F, [direction], int(0.6 * min(shape)), depth=True)
    sil, z = sil[0], z[0]
    zf = np.where(np.isfinite(z), z, np.nan)
    shade = np.where(sil, 1.0 - 0.4 * (np.nan_to_num(zf, nan=np.nanmax(zf)) - np.nanmin(zf)) / np.ptp(z[sil]), 0)
    angle = g.uniform(0.0, 360.0)
    m = ndimage.rotate(sil.astype(float), angle, order=1) > 0.5
    shade = ndimage.rotate(shade, angle, order=1)
    H, W = shape
    y0, x0 = (H - m.shape[0]) // 2, (W - m.shape[1]) // 2
    truth = np.zeros((H, W), bool)
    truth[y0:y0 + m.shape[0], x0:x0 + m.shape[1]] = m
    img = np.ones((H, W, 3)) * np.asarray(background)
    sh = np.zeros((H, W))
    sh[y0:y0 + m.shape[0], x0:x0 + m.shape[1]] = shade
    img[truth] = np.asarray(colour) * sh[truth][:, None]
    return np.clip(img + g.normal(0.0, 0.01, img.shape), 0.0, 1.0), truth


def unseen_directions(n, rng):
    g = np.random.default_rng(rng)
    d = g.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


# ------------------------------------------------------------------ rendering


def test_fibonacci_directions_cover_the_sphere_up_to_mirrors():
    D = fibonacci_directions(40)
    assert D.shape == (40, 3) and np.allclose(np.linalg.norm(D, axis=1), 1.0) and (D[:, 2] >= 0).all()
    probe = unseen_directions(5000, 1)
    gap = np.degrees(np.arccos(np.clip(np.abs(probe @ D.T).max(axis=1), -1, 1)))
    assert gap.max() < 20.0  # every direction (or its opposite) within 20 degrees of a library view
    with pytest.raises(BolusError, match="integer >= 1"):
        fibonacci_directions(0)


def test_silhouette_of_a_ball_is_a_disc_and_of_a_box_its_face():
    V, F = icosphere(4, 10.0)
    size = 128
    sil, z = render_views(V, F, unseen_directions(3, 2), size, depth=True)
    inner = size - 2 * MARGIN_PX
    for s in sil:  # a ball's outline fills the inner square across: a disc of that diameter
        assert s.sum() == pytest.approx(np.pi * (inner / 2) ** 2, rel=0.02)
    # the z-buffer: the nearest surface, the sphere's front at -R (scaled) in the middle
    scale = inner / 20.0
    assert z[0][size // 2, size // 2] == pytest.approx(-10.0 * scale, rel=0.01)
    assert np.array_equal(np.isfinite(z[0]), sil[0])
    V, F = box((80.0, 40.0, 20.0), 2)
    (s,), _ = render_views(V, F, [(0.0, 0.0, 1.0)], size)
    assert s.sum() == pytest.approx(inner * inner / 2, rel=0.03)  # an 80 x 40 face fills half the square
    R = view_frame((0.3, -0.5, 0.8))
    assert np.allclose(R.T @ R, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)


def test_render_refuses_a_model_without_faces_or_area():
    with pytest.raises(BolusError, match="no faces"):
        render_views(np.zeros((3, 3)), np.zeros((0, 3), int), [(0, 0, 1)])
    with pytest.raises(BolusError, match="faces have no area"):
        render_views(np.zeros((3, 3)), np.array([[0, 1, 2]]), [(0, 0, 1)])
    with pytest.raises(BolusError, match="faces have no area"):
        render_views(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), np.array([[0, 1, 2]]), [(0, 0, 1)])


# ------------------------------------------------------------------ descriptors


def l1(a, b):
    return float(np.abs(np.asarray(a, float) - b).sum())


def test_descriptors_are_invariant_to_scale_translation_rotation_and_mirror():
    V, F = shapes()["pear"]
    (m,), _ = render_views(V, F, [(0.2, 0.3, 0.9)], 128)
    base = sd.describe(m)[0]
    big = np.pad(ndimage.zoom(m.astype(float), 2.3, order=1) > 0.5, ((40, 10), (5, 70)))
    turned = ndimage.rotate(big.astype(float), 37.0, order=1) > 0.5
    others = [sd.describe(render_views(*shapes()[k], [(0.2, 0.3, 0.9)], 128)[0])[0] for k in ("egg", "slab", "ring")]
    apart = min(l1(base, o) for o in others)
    for variant in (big, turned, turned[:, ::-1], np.roll(turned, (17, -9), axis=(0, 1))):
        assert l1(base, sd.describe(variant)[0]) < 0.15 * apart


def test_canonical_image_is_centred_and_scaled():
    m = np.zeros((200, 300), bool)
    m[50:90, 100:260] = True  # a 160 x 40 bar off centre
    c = sd.canonical(m)
    ys, xs = np.nonzero(c > 0.5)
    mid = (sd.GRID - 1) / 2
    assert abs(xs.mean() - mid) < 0.6 and abs(ys.mean() - mid) < 0.6
    assert np.ptp(xs) + 1 == pytest.approx(sd.GRID * 160 / np.hypot(160, 40), abs=2)
    with pytest.raises(BolusError, match="empty"):
        sd.canonical(np.zeros((10, 10), bool))


# ------------------------------------------------------------------ the photo


def iou(a, b):
    return (a & b).sum() / (a | b).sum()


@pytest.mark.parametrize("name", ["egg", "ring", "slab"])
def test_photo_silhouette_matches_the_painted_truth(name):
    V, F = shapes()[name]
    img, truth = photo(V, F, unseen_directions(1, 7)[0], 3)
    sil = photo_silhouette(img)
    assert iou(sil.mask, truth) > 0.95
    # the shaded side close to the background: an object whose colour fades into the background's
    yy, xx = np.mgrid[0:300, 0:400]
    fade = np.clip((xx - 120) / 200.0, 0, 1)[..., None]
    dim = img * (1 - fade) + np.asarray(BACKGROUND) * 0.93 * fade
    dim[~truth] = img[~truth]
    assert iou(photo_silhouette(dim).mask, truth) > 0.9


def test_photo_silhouette_on_a_gradient_background_keeps_a_rings_opening():
    V, F = shapes()["ring"]
    img, truth = photo(V, F, (0.05, 0.1, 1.0), 4)
    t = np.linspace(0, 1, img.shape[0])[:, None, None]
    bg = (1 - t) * np.array([0.95, 0.9, 0.78]) + t * np.array([0.55, 0.5, 0.45])
    img = np.where(truth[..., None], img, bg)
    mask = photo_silhouette(img).mask
    assert iou(mask, truth) > 0.93
    assert ndimage.binary_fill_holes(truth).sum() - truth.sum() > 1000  # the ring's opening is there ...
    assert ndimage.binary_fill_holes(mask).sum() - mask.sum() > 0.8 * (ndimage.binary_fill_holes(truth).sum()
                                                                      - truth.sum())  # ... and stays open


def test_bad_photos_are_refused_clearly():
    rng = np.random.default_rng(0)
    with pytest.raises(BolusError, match=r"40 x 30 pixels: at least 64 x 64"):
        photo_silhouette(rng.random((30, 40, 3)))
    with pytest.raises(BolusError, match="all white"):
        photo_silhouette(np.ones((200, 300, 3)))
    with pytest.raises(BolusError, match="all black"):
        photo_silhouette(np.zeros((200, 300, 3), np.uint8))
    empty = np.clip(np.ones((200, 300, 3)) * np.asarray(BACKGROUND) + rng.normal(0, 0.02, (200, 300, 3)), 0, 1)
    with pytest.raises(BolusError, match="no object"):
        photo_silhouette(empty)
    with pytest.raises(BolusError, match="no object"):
        views.photo_descriptor(empty)


# ------------------------------------------------------------------ matching


@pytest.fixture(scope="module")
def library():
    return {k: views.model_descriptor(V, F) for k, (V, F) in shapes().items()}


def test_true_model_first_on_photos_of_unseen_views(library):
    index = views.ViewIndex(library)
    lib_dirs = fibonacci_directions(views.DIRECTIONS)
    for k, (name, (V, F)) in enumerate(shapes().items()):
        for j, d in enumerate(unseen_directions(2, 10 + k)):
            assert np.degrees(np.arccos(np.abs(lib_dirs @ d).max())) > 0.5  # not a library view
            img, _ = photo(V, F, d, 100 * k + j, shape=(220, 290))
            ranking = index.rank(views.photo_descriptor(img))
            assert ranking[0][0] == name, (name, j, ranking)


@pytest.mark.parametrize("name", ["slab", "pear"])
def test_model_descriptor_ignores_pose_and_size(library, name):
    """The views of the model turned, scaled and moved (other directions than the library's): most of them find
    the model itself first."""
    V, F = shapes()[name]
    Q, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
    moved = views.model_descriptor(3.0 * V @ Q.T + 50.0, F)
    index = views.ViewIndex(library)
    firsts = [index.rank(views.ViewsDescriptor(row[None], "photo", 1))[0][0] for row in moved.matrix]
    assert np.mean([f == name for f in firsts]) >= 0.85


def test_vectorised_ranking_is_the_best_view_distance(library):
    index = views.ViewIndex(library)
    q = library["pear"].matrix[5] * 1.03
    got = dict(index.rank(views.ViewsDescriptor(q[None], "photo", 1)))
    for name, d in library.items():  # one model at a time, plain loops
        best = min(float(np.sum(index.w * np.abs(row - q))) / sum(views.GROUP_WEIGHT.values()) for row in d.matrix)
        assert got[name] == pytest.approx(best, rel=1e-4)
    with pytest.raises(BolusError, match="library is empty"):
        views.ViewIndex({})


def test_an_object_cut_by_the_frame_is_warned():
    V, F = shapes()["slab"]
    img, truth = photo(V, F, unseen_directions(1, 5)[0], 1)
    whole = views.photo_descriptor(img)
    assert whole.cut == 0.0 and whole.warnings() == []
    cols = np.flatnonzero(truth.any(axis=0))
    cut = img[:, (cols[0] + cols[-1]) // 2 - 60:]  # the left part of the object out of the frame
    d = views.photo_descriptor(cut)
    assert d.cut > views.CUT_WARN and "touches the photo's edge" in d.warnings()[0]


# ------------------------------------------------------------------ partial silhouettes


def test_cut_views_are_the_masks_cut_directly():
    """Each cut of a canonical image describes as the full-resolution mask cut by the same half-plane (the share
    of its pixels on the far side of the direction) does, and nearer than the other cuts of that view."""
    V, F = shapes()["pear"]
    mask = render_views(V, F, unseen_directions(1, 7), 256)[0][0]
    cuts = pv.cut_descriptors(sd.canonical(mask)[None]).astype(np.float64)
    assert cuts.shape == (pv.CUT_DIRECTIONS * len(pv.CUT_SHARES), sd.ZERNIKE_COUNT)
    ys, xs = np.nonzero(mask)
    cy, cx = ys.mean(), xs.mean()
    for k, (a, s) in enumerate((a, s) for a in range(pv.CUT_DIRECTIONS) for s in pv.CUT_SHARES):
        ang = 2 * np.pi * a / pv.CUT_DIRECTIONS
        t = (xs - cx) * np.cos(ang) + (ys - cy) * np.sin(ang)  # image rows grow downwards, as in the cuts
        kept = np.zeros_like(mask)
        keep = t > np.quantile(t, s)
        kept[ys[keep], xs[keep]] = True
        direct = sd.describe(kept)[0, sd.GROUPS["zernike"]]
        d = np.abs(cuts - direct).sum(axis=1)
        assert int(np.argmin(d)) == k or d[k] < 0.1 * np.abs(direct).sum(), (a, s)
    with pytest.raises(BolusError, match="square images"):
        pv.cut_images(np.zeros((2, 8, 9)))


def test_a_photo_cut_by_the_frame_matches_the_cut_views(library):
    """A quarter of the object out of the frame: its true model first, and nearer by the cut views than by the
    whole ones."""
    index = views.ViewIndex(library)
    for k, (name, (V, F)) in enumerate(shapes().items()):
        img, truth = photo(V, F, unseen_directions(1, 40 + k)[0], 60 + k)
        rows = np.flatnonzero(truth.any(axis=1))
        counts = np.cumsum(truth.sum(axis=1))
        cut_row = int(np.searchsorted(counts, 0.25 * counts[-1]))
        q = views.photo_descriptor(img[max(cut_row, rows[0]):])  # the top quarter out of the frame
        assert q.cut > views.CUT_WARN
        i = index.names.index(name)
        assert index.cut_distances(q.matrix[0])[i] < index.distances(q.matrix[0])[i]
        assert index.rank(q)[0][0] == name


def test_an_occluder_is_taken_out_of_the_silhouette():
    """A grey card over part of the object, jutting out of its outline: the variant without it is nearer to the
    true silhouette than the mask with it; a shaded object of one colour gives no variant."""
    V, F = shapes()["slab"]
    img, truth = photo(V, F, unseen_directions(1, 5)[0], 2)
    assert pv.occluder_variants(img, truth) == []  # shading alone is not foreign
    ys, xs = np.nonzero(truth)
    y0, x0 = int(np.quantile(ys, 0.55)), int(np.quantile(xs, 0.75))
    occluded = img.copy()
    occluded[y0:y0 + 50, x0:x0 + 70] = 0.5
    sil = photo_silhouette(occluded)
    variants = pv.occluder_variants(sil.image, sil.mask)
    assert len(variants) >= 1

    def iou(a, b):
        return (a & b).sum() / (a | b).sum()

    assert iou(sil.mask, truth) < 0.93 and max(iou(v, truth) for v in variants) > 0.95
    q = views.photo_descriptor(occluded)
    assert len(q.matrix) == 1 + len(variants)
