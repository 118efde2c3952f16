"""Benchmark of the retrieval of a bolus from a photo (seed 5.4, eqs. 5-15..5-17, Table 5-2; printed, not asserted).

Run from the repository root (Blender renders the query photos: bpy from .venv):

    .venv/bin/python bench/retrieval_bench.py              # 10 classes, 3 views x 3 conditions = 90 queries
    .venv/bin/python bench/retrieval_bench.py --quick      # 4 small classes, the front view only: 12 queries
    .venv/bin/python bench/retrieval_bench.py --only knee --out out/retrieval --json out/retrieval_bench.json
    .venv/bin/python bench/retrieval_bench.py --markdown docs/benchmarks.md   # append the tables (make bench)

The library (a folder of ``.obj`` files, as the add-on's library is a folder of .blend/.stl/.obj):
every mesh of ``assets/`` and ``tests/data/`` is a
class, scaled to mm as that folder's README says, with three members:

* ``original``: the mesh as read (centred on its bounding box);
* ``turned``: scaled by 1.2-1.6, turned by a random rotation and moved (seeded);
* ``noisy``: every vertex moved by gaussian noise of 0.3 x the mean edge length per axis (seeded).

The right answers to a query of a class are its three members (q = 3); the library holds N = 3 x
classes models (30).  Queries: every ORIGINAL model rendered by Blender's Workbench engine
(orthographic camera framing the object, 400 x 300 px, the seed's reference size) from the views
``VIEWS`` (azimuth about the model's up axis from its front, elevation), each view with its own
background colour, object colour and studio light (``STYLES``); each render is a query as it is
(``clean``), with gaussian noise (``noise``: sigma 0.05 of the range per channel, seeded) and with a
grey rectangle over about 15 % of the object (``occlusion``).  Nothing of a query is in the
library: the seed's method caches 3-D skeletons only, the baseline silhouettes from the fixed
directions ``canonical_directions()`` in each model's own axes (the nearest to a query view is
given in the run's notes).

Methods, on the same queries and the same library in the same run:

* SEED: ``core.retrieval.photo_descriptor(query)`` ranked by ``rank`` against
  ``model_descriptor`` of every library model (5.1-5.3: entropy edges, spectral contour, spectral
  embedding, feature skeletons, ICP dissimilarity);
* HU: a plain baseline: the 7 Hu moment invariants of the query's object mask (3 x 3 median
  filter, then every pixel whose colour is more than ``HU_TOLERANCE`` from the known background
  colour in some channel, the largest connected piece) against the same invariants of each library
  model's silhouettes from ``canonical_directions()`` (numpy rasterised orthographic projections,
  ``silhouette``), compared as OpenCV's ``matchShapes`` (CONTOURS_MATCH_I1) does: the log-scaled
  invariants m = sign(h) log10 |h| by sum |1/m_a - 1/m_b| over the invariants above 1e-5 (an L1
  distance of the log-scaled values made the near-zero invariants of symmetric shapes, whose sign
  flips with a few noisy pixels, decide); a model's distance is its best view's.

Per method: ADR, MR, LR (``core.retrieval_metrics``, averaged over the queries) and the top-1
rate, overall, per condition and per view; a query whose photo cannot be described (BolusError)
counts with the library in a seeded random order (and is counted as failed).  Times (wall clock,
``time.perf_counter``; CPU time of the process, ``time.process_time``, beside it): per model
descriptor (with its vertices), per photo descriptor (with its pixels and contour points), per
comparison (a ranking's time over the library size).
"""
from __future__ import annotations

import math
import shutil
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchutil import (  # noqa: E402
    ROOT,
    data_mesh,
    Table,
    captured_output,
    error_row,
    finish,
    parser,
    run_line,
    versions,
)

from retrieval_photos import KINDS, composite, photos_of  # noqa: E402

from bolus_addon.core.errors import BolusError  # noqa: E402
from bolus_addon.core.mesh.objfile import load_obj  # noqa: E402
from bolus_addon.core.retrieval.metrics import query_scores, summarise  # noqa: E402
from bolus_addon.core.retrieval.view_render import row_spans  # noqa: E402

SEED = 0
VIEWS_NAME, SEED_NAME, HU_NAME = "VIEWS", "SKELETON", "HU"
VARIANTS = ("original", "turned", "noisy")
NOISE_EDGE = 0.3  # the noisy variant: gaussian vertex noise, sigma per axis = this x the mean edge length
TURN_SCALE = (1.2, 1.6)  # the turned variant's uniform scale range
WIDTH, HEIGHT = 400, 300  # query photos (the seed's 400 x 300 reference)
PHOTO_NOISE = 0.05  # gaussian noise of the 'noise' queries, sigma in [0, 1] units per channel
OCCLUDED = 0.15  # share of the object's pixels under the 'occlusion' rectangle
OCCLUDER_SRGB = (0.5, 0.5, 0.5)
HU_TOLERANCE = 0.12  # the baseline's object mask: a channel more than this from the background colour
SILHOUETTE_PX = 200  # the baseline's library silhouettes: the longer side in pixels
HU_EPS = 1e-5  # invariants under this are left out of the distance (OpenCV's matchShapes)

#: (class, file, how to get mm: ("factor", f) or ("longest", mm), up axis, front axis, units note)
MESHES = [
    ("airplane", "airplane.obj", ("longest", 150.0), "+z", "+y", "normalised -> longest side 150 mm"),
    ("demosthenes", "demosthenes.obj", ("longest", 300.0), "+y", "+z", "normalised -> 300 mm tall bust"),
    ("fish", "fish.obj", ("longest", 150.0), "+y", "+x", "normalised -> longest side 150 mm"),
    ("ict face", "ict_face_narrow.obj", ("factor", 10.0), "+y", "+z", "cm -> mm (x 10)"),
    ("body", "makehuman_body.obj", ("factor", 100.0), "+y", "+z", "dm -> mm (x 100)"),
    ("chest", "makehuman_chest_patch.obj", ("factor", 100.0), "+y", "+z", "dm -> mm (x 100)"),
    ("elbow", "makehuman_elbow_patch.obj", ("factor", 100.0), "+y", "+z", "dm -> mm (x 100)"),
    ("face patch", "makehuman_face_patch.obj", ("factor", 100.0), "+y", "+z", "dm -> mm (x 100)"),
    ("knee", "makehuman_knee_patch.obj", ("factor", 100.0), "+y", "+z", "dm -> mm (x 100)"),
    ("nefertiti", "nefertiti.obj", ("factor", 1.0), "+y", "+z", "mm"),
]
QUICK_CLASSES = ("chest", "elbow", "face patch", "knee")

QUERY_VIEWS = 2  #: unseen views per class (random turn, tilt and camera roll, seeded by the class name)
ROLL_DEG = 25.0  #: the camera's roll about its axis, at most
#: the two lights of every view: (background sRGB, object sRGB, Workbench studio light); A for every kind but
#: 'light', which takes B over a gradient background (retrieval_photos.py)
STYLES = [((0.78, 0.84, 0.93), (0.80, 0.62, 0.52), "studio.sl"),
          ((0.93, 0.89, 0.80), (0.45, 0.52, 0.62), "outdoor.sl")]
CONDITIONS = KINDS
SCALE_SIZES = (50, 1000)  #: library sizes of the query-time rows (copies of the bench's models)
SCALE_QUERIES = 2  #: photos of each of SCALE_KINDS timed at each size
SCALE_KINDS = ("clean", "cropped", "occlusion")  #: a cropped photo is also compared with every cut view


# ------------------------------------------------------------------ the library


def _axis(text: str) -> np.ndarray:
    v = np.zeros(3)
    v["xyz".index(text[1])] = 1.0 if text[0] == "+" else -1.0
    return v


def mesh_path(name: str) -> Path:
    """A mesh of the repository (assets/, then tests/data/)."""
    return data_mesh(name)


def load_class(file: str, scale) -> tuple[np.ndarray, np.ndarray]:
    """V (n,3) in mm centred on its bounding box, F (m,3)."""
    V, F, _ = load_obj(mesh_path(file))
    V = V * (scale[1] if scale[0] == "factor" else scale[1] / float(np.ptp(V, axis=0).max()))
    return V - (V.min(axis=0) + V.max(axis=0)) / 2, F


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation (3,3) (QR of a gaussian matrix, signs fixed, det +1)."""
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def mean_edge_length(V: np.ndarray, F: np.ndarray) -> float:
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    E = np.unique(np.sort(E, axis=1), axis=0)
    return float(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean())


def make_variants(V: np.ndarray, F: np.ndarray, rng) -> dict:
    """The three members of a class: {variant: (V (n,3), F (m,3), what was done)} (``VARIANTS``)."""
    rng = np.random.default_rng(rng)
    s = float(rng.uniform(*TURN_SCALE))
    R = random_rotation(rng)
    t = rng.uniform(-50.0, 50.0, 3)
    sigma = NOISE_EDGE * mean_edge_length(V, F)
    noisy = V + rng.normal(0.0, sigma, V.shape)
    return {"original": (V, F, "as read, centred"),
            "turned": (s * V @ R.T + t, F, f"x {s:.3f}, turned by a random rotation, moved"),
            "noisy": (noisy, F, f"vertex noise sigma {sigma:.3g} mm per axis")}


def write_obj(path, V: np.ndarray, F: np.ndarray) -> None:
    """A plain OBJ (v and f records, 1-based)."""
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("# bench/retrieval_bench.py library model\n")
        np.savetxt(fh, V, fmt="v %.6f %.6f %.6f")
        np.savetxt(fh, np.asarray(F, dtype=np.int64) + 1, fmt="f %d %d %d")


def slug(name: str) -> str:
    return name.replace(" ", "_")


def build_library(folder, classes: dict, rng=SEED) -> list[dict]:
    """Write every class's members into ``folder`` as ``<class>_<variant>.obj``.

    classes: {class name: (V (n,3), F (m,3))}.  Returns one dict per model (name = file name, class,
    variant, path, vertices, triangles, note), classes in the given order, variants in ``VARIANTS``
    order; every class has its own generator, seeded by ``rng`` (an int) and the class name, so a
    class's members do not depend on which other classes are in the library."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for cls, (V, F) in classes.items():
        child = np.random.default_rng([int(rng), zlib.crc32(cls.encode())])
        for variant, (Vv, Fv, note) in make_variants(np.asarray(V, float), np.asarray(F), child).items():
            name = f"{slug(cls)}_{variant}.obj"
            write_obj(folder / name, Vv, Fv)
            out.append({"name": name, "class": cls, "variant": variant, "path": str(folder / name),
                        "vertices": len(Vv), "triangles": len(Fv), "note": note})
    return out


def relevant_sets(library: list[dict]) -> dict:
    """{class: set of the names of its members} (the ground truth of a query of that class)."""
    out: dict = {}
    for m in library:
        out.setdefault(m["class"], set()).add(m["name"])
    return out


# ------------------------------------------------------------------ views and silhouettes


def view_frame(direction, up) -> np.ndarray:
    """(3,3) columns right, up, back of a camera looking along -direction (direction: from the object to
    the camera), as Blender's camera axes X, Y, Z.  ``up`` is made orthogonal (another axis when parallel)."""
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    u = np.asarray(up, float) - d * float(np.dot(up, d))
    if np.linalg.norm(u) < 1e-6:
        u = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        u = u - d * float(np.dot(u, d))
    u = u / np.linalg.norm(u)
    return np.column_stack([np.cross(u, d), u, d])


def view_direction(up: str, front: str, azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector from the object to the camera: ``front`` turned by azimuth about ``up``, then raised."""
    u, f = _axis(up), _axis(front)
    side = np.cross(u, f)
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    h = math.cos(a) * f + math.sin(a) * side
    return math.cos(e) * h + math.sin(e) * u


def canonical_directions() -> np.ndarray:
    """(26,3) unit vectors: the 3 x 3 x 3 grid's directions (axes, face and cube diagonals) in a model's
    own axes: the views the baseline's library holds of every model."""
    g = np.array([(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if (x, y, z) != (0, 0, 0)],
                 float)
    return g / np.linalg.norm(g, axis=1, keepdims=True)


def silhouette(V: np.ndarray, F: np.ndarray, direction, size: int = SILHOUETTE_PX) -> np.ndarray:
    """Orthographic silhouette (h, w) bool of the mesh seen from ``direction`` (object -> camera), the
    longer side ``size`` px (2 px margin), rows top down as a camera image: a pixel is set when its centre
    lies in the projection of a triangle (a scanline fill, vectorised over all triangles and rows)."""
    R = view_frame(direction, (0.0, 0.0, 1.0) if abs(direction[2]) < 0.9 else (0.0, 1.0, 0.0))
    P = np.asarray(V, float) @ R[:, :2]
    lo, ext = P.min(axis=0), np.ptp(P, axis=0)
    s = (size - 5) / max(float(ext.max()), 1e-12)
    w, h = (np.ceil(ext * s).astype(int) + 5)
    T = ((P - lo) * s + 2.0)[np.asarray(F)]  # (m,3,2) pixel units, x right, y up
    tri, j, xl, xr = row_spans(T)  # the core's scanline spans: each row centre inside each triangle
    i0 = np.clip(np.ceil(xl - 0.5).astype(np.int64), 0, w)
    i1 = np.clip(np.floor(xr - 0.5).astype(np.int64) + 1, 0, w)
    rows = np.clip(h - 1 - j, 0, h - 1)
    keep = i1 > i0
    diff = np.zeros((h, w + 1), dtype=np.int64)
    np.add.at(diff, (rows[keep], i0[keep]), 1)
    np.add.at(diff, (rows[keep], i1[keep]), -1)
    return np.cumsum(diff, axis=1)[:, :w] > 0


# ------------------------------------------------------------------ Hu moments (the baseline)


def hu_moments(mask: np.ndarray) -> np.ndarray:
    """The 7 Hu invariants (7,) of a binary image (H,W) (pixels as unit masses; invariant to translation,
    scale and rotation, h7 changes sign under a mirror).  BolusError on an empty mask."""
    y, x = np.nonzero(np.asarray(mask, bool))
    if x.size == 0:
        raise BolusError("the object mask is empty")
    x = x - x.mean()
    y = y - y.mean()
    m00 = float(x.size)

    def eta(p, q):
        return float(np.sum(x ** p * y ** q)) / m00 ** (1 + (p + q) / 2)

    n20, n02, n11 = eta(2, 0), eta(0, 2), eta(1, 1)
    n30, n03, n21, n12 = eta(3, 0), eta(0, 3), eta(2, 1), eta(1, 2)
    a, b = n30 + n12, n21 + n03
    return np.array([
        n20 + n02,
        (n20 - n02) ** 2 + 4 * n11 ** 2,
        (n30 - 3 * n12) ** 2 + (3 * n21 - n03) ** 2,
        a ** 2 + b ** 2,
        (n30 - 3 * n12) * a * (a ** 2 - 3 * b ** 2) + (3 * n21 - n03) * b * (3 * a ** 2 - b ** 2),
        (n20 - n02) * (a ** 2 - b ** 2) + 4 * n11 * a * b,
        (3 * n21 - n03) * a * (a ** 2 - 3 * b ** 2) - (n30 - 3 * n12) * b * (3 * a ** 2 - b ** 2),
    ])


def hu_features(mask: np.ndarray) -> np.ndarray:
    """Log-scaled Hu invariants (7,): -sign(h) log10 |h| (|h| floored at 1e-30)."""
    h = hu_moments(mask)
    return -np.sign(h) * np.log10(np.maximum(np.abs(h), 1e-30))


def object_mask(rgb: np.ndarray, background_srgb, tolerance: float = HU_TOLERANCE) -> np.ndarray:
    """(H,W) bool: the baseline's object in a photo (H,W,3) uint8 of a known background colour (sRGB in
    [0,1]): 3 x 3 median filter, pixels with a channel more than ``tolerance`` from the background, the
    largest 8-connected piece."""
    from scipy import ndimage

    img = ndimage.median_filter(np.asarray(rgb, float) / 255.0, size=(3, 3, 1))
    fg = np.any(np.abs(img - np.asarray(background_srgb, float)) > tolerance, axis=2)
    lab, count = ndimage.label(fg, structure=np.ones((3, 3)))
    if count == 0:
        raise BolusError("no object in the photo")
    sizes = np.bincount(lab.ravel())[1:]
    return lab == (1 + int(np.argmax(sizes)))


def hu_distance(a: np.ndarray, b: np.ndarray, eps: float = HU_EPS) -> float:
    """OpenCV's ``matchShapes`` CONTOURS_MATCH_I1 of two raw Hu invariant vectors (7,):
    sum_i |1/m_a,i - 1/m_b,i|, m = sign(h) log10 |h|, over the invariants above ``eps`` in both (the
    near-zero ones, whose sign and logarithm are noise, are left out)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    use = (np.abs(a) > eps) & (np.abs(b) > eps)
    if not use.any():
        return 0.0
    ma = np.sign(a[use]) * np.log10(np.abs(a[use]))
    mb = np.sign(b[use]) * np.log10(np.abs(b[use]))
    return float(np.abs(1.0 / ma - 1.0 / mb).sum())


# ------------------------------------------------------------------ query photos


def srgb_to_linear(c):
    c = np.asarray(c, float)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def query_views(cls: str, count: int = QUERY_VIEWS, rng=SEED) -> list[tuple]:
    """``count`` unseen views of a class: (name, azimuth from the front about the up axis, elevation, camera roll),
    degrees; azimuth anywhere, elevation -20..50, roll within ROLL_DEG, seeded by ``rng`` and the class name."""
    g = np.random.default_rng([int(rng), zlib.crc32(f"views of {cls}".encode())])
    return [(f"view {k + 1}", float(g.uniform(0, 360)), float(g.uniform(-20, 50)),
             float(g.uniform(-ROLL_DEG, ROLL_DEG))) for k in range(count)]


def _camera(V, up: str, front: str, view, diag: float):
    """(4,4) camera matrix and ortho scale of a view (name, azimuth, elevation[, roll]) of V, and its direction."""
    az, el = view[1], view[2]
    roll = math.radians(view[3]) if len(view) > 3 else 0.0
    d = view_direction(up, front, az, el)
    R = view_frame(d, _axis(up))
    c, s_ = math.cos(roll), math.sin(roll)
    R = np.column_stack([c * R[:, 0] + s_ * R[:, 1], -s_ * R[:, 0] + c * R[:, 1], R[:, 2]])
    P = V @ R[:, :2]
    w, h = np.ptp(P, axis=0)
    mid = (P.min(axis=0) + P.max(axis=0)) / 2
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = R[:, 0] * mid[0] + R[:, 1] * mid[1] + 2.0 * diag * d
    return M, float(max(w, h * WIDTH / HEIGHT) * 1.25), d


def _render_scene(bpy):
    from blender_scene import empty_scene  # noqa: PLC0415

    sc = empty_scene(bpy)
    sc.render.engine = "BLENDER_WORKBENCH"
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.display.render_aa = "8"
    sc.render.film_transparent = True  # the object on a transparent film: the backgrounds come later
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = WIDTH, HEIGHT, 100
    sc.render.image_settings.file_format = "PNG"
    sc.render.image_settings.color_mode = "RGBA"
    sc.display.shading.light = "STUDIO"
    sc.display.shading.color_type = "SINGLE"
    sc.display.shading.show_cavity = False
    cam_data = bpy.data.cameras.new("retrieval_bench")
    cam_data.type = "ORTHO"
    cam = bpy.data.objects.new("retrieval_bench", cam_data)
    sc.collection.objects.link(cam)
    sc.camera = cam
    return sc, cam, cam_data


def render_queries(models: list[tuple], views, out_dir: Path) -> tuple[list[dict], float]:
    """Render every (class, V, F, up, front) from its views (a list, or {class: list}) with Blender's Workbench
    engine on a transparent film, in both lights of ``STYLES``.

    Returns (one dict per view: class, view, direction, rgba and rgba_light (H,W,4) float, rgb (H,W,3) uint8 =
    light A over its background, background, light, path), seconds)."""
    import bpy  # noqa: PLC0415  (the bench imports bpy only here)
    from mathutils import Matrix  # noqa: PLC0415
    from PIL import Image  # noqa: PLC0415

    t0 = time.perf_counter()
    sc, cam, cam_data = _render_scene(bpy)
    out = []
    try:
        for cls, V, F, up, front in models:
            me = bpy.data.meshes.new(slug(cls))
            me.from_pydata(V.tolist(), [], np.asarray(F).tolist())
            me.validate()
            ob = bpy.data.objects.new(slug(cls), me)
            sc.collection.objects.link(ob)
            diag = float(np.linalg.norm(np.ptp(V, axis=0)))
            for view in (views[cls] if isinstance(views, dict) else views):
                M, cam_data.ortho_scale, d = _camera(V, up, front, view, diag)
                cam_data.clip_start, cam_data.clip_end = 0.01 * diag, 4.0 * diag
                cam.matrix_world = Matrix(M.tolist())
                rgba = []
                for k, (bg, colour, light) in enumerate(STYLES):
                    sc.display.shading.single_color = tuple(srgb_to_linear(colour))
                    sc.display.shading.studio_light = light
                    path = out_dir / f"{slug(cls)}_{view[0].replace('/', '-').replace(' ', '')}_{k}.png"
                    sc.render.filepath = str(path)
                    with captured_output() as said:
                        res = bpy.ops.render.render(write_still=True)
                    if res != {"FINISHED"} or not path.exists():
                        raise RuntimeError(f"render of {cls} {view[0]} returned {res}:\n{said()}")
                    rgba.append(np.asarray(Image.open(path).convert("RGBA"), float) / 255.0)
                bg, colour, light = STYLES[0]
                out.append({"class": cls, "view": view[0], "direction": d.tolist(), "background": bg,
                            "object_colour": colour, "light": light, "path": str(path), "rgba": rgba[0],
                            "rgba_light": rgba[1], "rgb": composite(rgba[0], bg)})
            bpy.data.objects.remove(ob, do_unlink=True)
            bpy.data.meshes.remove(me)
    finally:
        bpy.data.objects.remove(cam, do_unlink=True)
        bpy.data.cameras.remove(cam_data)
    return out, time.perf_counter() - t0


def add_noise(rgb: np.ndarray, sigma: float, rng) -> np.ndarray:
    """(H,W,3) uint8 with gaussian noise of ``sigma`` (in [0,1] units) per channel, clipped."""
    rng = np.random.default_rng(rng)
    noisy = np.asarray(rgb, float) + rng.normal(0.0, 255.0 * sigma, np.shape(rgb))
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def occlude(rgb: np.ndarray, mask: np.ndarray, share: float, rng, colour=OCCLUDER_SRGB) -> tuple[np.ndarray, float]:
    """A grey rectangle over about ``share`` of the object's pixels (mask (H,W) bool), centred on a random
    object pixel, aspect 0.6-1.6, grown until it covers ``share``.  Returns (the photo (H,W,3) uint8, the
    share of the object's pixels it covers)."""
    rng = np.random.default_rng(rng)
    H, W = mask.shape
    ys, xs = np.nonzero(mask)
    if xs.size == 0:
        raise BolusError("no object to occlude")
    k = int(rng.integers(xs.size))
    cy, cx = ys[k], xs[k]
    aspect = float(rng.uniform(0.6, 1.6))
    area = share * xs.size
    total = float(xs.size)
    for _ in range(60):
        rw, rh = math.sqrt(area * aspect), math.sqrt(area / aspect)
        x0, x1 = int(max(0, round(cx - rw / 2))), int(min(W, round(cx + rw / 2)))
        y0, y1 = int(max(0, round(cy - rh / 2))), int(min(H, round(cy + rh / 2)))
        covered = float(mask[y0:y1, x0:x1].sum()) / total
        if covered >= share:
            break
        area *= 1.1
    out = np.array(rgb, dtype=np.uint8, copy=True)
    out[y0:y1, x0:x1] = np.rint(255 * np.asarray(colour)).astype(np.uint8)
    return out, covered


def make_queries(renders: list[dict], conditions=CONDITIONS, rng=SEED) -> list[dict]:
    """One query per kind (``conditions``, retrieval_photos.KINDS) of every render; the noise, crop and occluder
    of a render are seeded by ``rng`` and its class and view."""
    out = []
    for r in renders:
        out += photos_of(r, occlude, object_mask, conditions, rng)
    return out


# ------------------------------------------------------------------ the methods


def retrieval_api(method: str = "SKELETON"):
    """The module of a core.retrieval method (model_descriptor, photo_descriptor, rank), BolusError naming what
    is missing."""
    try:
        from bolus_addon.core.retrieval import library  # noqa: PLC0415
        mod = library.method_module(method)
    except ImportError as exc:
        raise BolusError(f"core.retrieval cannot be imported: {exc}") from None
    missing = [n for n in ("model_descriptor", "photo_descriptor", "rank") if not hasattr(mod, n)]
    if missing:
        raise BolusError(f"core.retrieval's {method} has no {', '.join(missing)} yet")
    mod.read_model = library.read_model
    return mod


def _clock():
    return time.perf_counter(), time.process_time()


def _since(t):
    return time.perf_counter() - t[0], time.process_time() - t[1]


def best_of(fn, repeat: int):
    """(result, wall seconds, CPU seconds) of the fastest of ``repeat`` runs of fn()."""
    best = None
    for _ in range(max(1, repeat)):
        t = _clock()
        out = fn()
        wall, cpu = _since(t)
        if best is None or wall < best[1]:
            best = (out, wall, cpu)
    return best


def fallback_ranking(names: list[str], rng) -> list[str]:
    """The ranking of a query that could not be described: the library in a random order."""
    return [names[i] for i in np.random.default_rng(rng).permutation(len(names))]


def score_query(q: dict, ranked: list[str], rel: dict) -> dict:
    s = query_scores(ranked, rel[q["class"]])
    return {"id": q["id"], "class": q["class"], "view": q["view"], "condition": q["condition"], **s,
            "top5": ranked[:5]}


def run_core(method: str, library: list[dict], queries: list[dict], rel: dict, repeat: int = 1) -> dict:
    """A core.retrieval method: model descriptors of the library, photo descriptors of the queries, ranking
    (each descriptor timed best of ``repeat`` runs)."""
    api = retrieval_api(method)
    models = []
    descriptors = {}
    for m in library:
        V, F = api.read_model(m["path"])
        descriptors[m["name"]], wall, cpu = best_of(lambda: api.model_descriptor(V, F, rng=SEED), repeat)
        models.append({"name": m["name"], "class": m["class"], "variant": m["variant"], "vertices": len(V),
                       "wall_s": wall, "cpu_s": cpu})
        print(f"   {method} model {m['name']:<28} {len(V):>6} vertices {wall:7.2f} s", flush=True)
    names = [m["name"] for m in library]
    rows, photos, comparisons = [], [], []
    for k, q in enumerate(queries):
        t = _clock()
        try:
            d, wall, cpu = best_of(lambda: api.photo_descriptor(q["rgb"], rng=SEED), repeat)
        except BolusError as exc:
            wall, cpu = _since(t)
            photos.append({"id": q["id"], "wall_s": wall, "cpu_s": cpu, "error": str(exc)})
            rows.append({**score_query(q, fallback_ranking(names, SEED + k), rel), "error": str(exc)})
            print(f"   {method} {q['id']:<36} FAILED: {exc}", flush=True)
            continue
        photos.append({"id": q["id"], "wall_s": wall, "cpu_s": cpu, "pixels": int(np.prod(q["rgb"].shape[:2])),
                       "contour_points": int(getattr(d, "size", 0))})
        t = _clock()
        ranking = api.rank(d, descriptors)
        rw, rc = _since(t)
        comparisons.append({"wall_s": rw / len(names), "cpu_s": rc / len(names), "ranking_s": rw})
        ranked = [n for n, _ in ranking]
        row = score_query(q, ranked, rel)
        row["scores"] = {n: float(s) for n, s in ranking[:5]}
        rows.append(row)
        print(f"   {method} {q['id']:<36} first right answer at {row['first_rank']:>2}  ADR {row['ADR']:.3f}  "
              f"photo {wall:5.2f} s, ranking {rw:6.3f} s  best {ranked[0]}", flush=True)
    return {"queries": rows, "models": models, "photos": photos, "comparisons": comparisons}


def run_views(library, queries, rel, repeat: int = 1) -> dict:
    return run_core("VIEWS", library, queries, rel, repeat)


def run_seed(library, queries, rel, repeat: int = 1) -> dict:
    return run_core("SKELETON", library, queries, rel, repeat)


def run_hu(library: list[dict], queries: list[dict], rel: dict, repeat: int = 1) -> dict:
    """The baseline: log Hu invariants of the query's object mask against each model's best silhouette
    (the silhouettes and invariants of a model, and the mask and invariants of a photo, timed best of
    ``repeat`` runs)."""
    dirs = canonical_directions()
    feats, models = {}, []
    for m in library:
        V, F, _ = load_obj(m["path"])
        feats[m["name"]], wall, cpu = best_of(lambda: np.array([hu_moments(silhouette(V, F, d)) for d in dirs]),
                                              repeat)
        models.append({"name": m["name"], "class": m["class"], "variant": m["variant"], "vertices": len(V),
                       "views": len(dirs), "wall_s": wall, "cpu_s": cpu})
    names = [m["name"] for m in library]
    rows, photos, comparisons = [], [], []
    for k, q in enumerate(queries):
        t = _clock()
        try:
            (mask, f), wall, cpu = best_of(lambda: _mask_and_hu(q), repeat)
        except BolusError as exc:
            wall, cpu = _since(t)
            photos.append({"id": q["id"], "wall_s": wall, "cpu_s": cpu, "error": str(exc)})
            rows.append({**score_query(q, fallback_ranking(names, SEED + k), rel), "error": str(exc)})
            continue
        photos.append({"id": q["id"], "wall_s": wall, "cpu_s": cpu, "pixels": int(mask.size),
                       "mask_pixels": int(mask.sum())})
        t = _clock()
        dist = {n: min(hu_distance(f, g) for g in feats[n]) for n in names}
        ranking = sorted(names, key=lambda n: (dist[n], n))
        rw, rc = _since(t)
        comparisons.append({"wall_s": rw / len(names), "cpu_s": rc / len(names)})
        row = score_query(q, ranking, rel)
        row["scores"] = {n: dist[n] for n in ranking[:5]}
        rows.append(row)
    hits = sum(r["first_rank"] == 1 for r in rows)
    print(f"   HU: {hits} of {len(rows)} queries with a right answer first", flush=True)
    return {"queries": rows, "models": models, "photos": photos, "comparisons": comparisons}


def _mask_and_hu(q: dict):
    mask = object_mask(q["rgb"], q["background"])
    return mask, hu_moments(mask)


def chance(queries: list[dict], names: list[str], rel: dict, draws: int = 200) -> dict:
    """The measures of random rankings of the same queries (``draws`` seeded shuffles each)."""
    g = np.random.default_rng(SEED)
    scores = [query_scores([names[i] for i in g.permutation(len(names))], rel[q["class"]])
              for q in queries for _ in range(draws)]
    return summarise(scores)


def most_often_first(rows: list[dict], top: int = 3) -> list[tuple[str, int]]:
    """The models a method ranks first most often, with how often (a 'hub' answers many queries)."""
    names = [r["top5"][0] for r in rows if "error" not in r and r.get("top5")]
    counts = {n: names.count(n) for n in dict.fromkeys(names)}
    return sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))[:top]


def summaries(rows: list[dict]) -> dict:
    """summarise() overall, per condition, per view, per class; failed queries counted."""
    def one(sel):
        return {**summarise(sel), "failed": sum("error" in r for r in sel)} if sel else None

    out = {"all": one(rows)}
    for key in ("condition", "view", "class"):
        out[key] = {v: one([r for r in rows if r[key] == v]) for v in dict.fromkeys(r[key] for r in rows)}
    return out


def timing(result: dict) -> dict:
    """Mean and largest wall / CPU seconds of the models, photos and comparisons of one method."""
    def stats(rows, key):
        vals = [r[key] for r in rows if "error" not in r]
        return {"mean": float(np.mean(vals)), "max": float(np.max(vals)), "count": len(vals)} if vals else None

    out = {}
    for part in ("models", "photos", "comparisons"):
        out[part] = {k: stats(result[part], k) for k in ("wall_s", "cpu_s")}
    v = [m["vertices"] for m in result["models"]]
    out["models"]["vertices"] = {"min": min(v), "max": max(v)} if v else None
    small = [m["wall_s"] for m in result["models"] if m["vertices"] < 3000]
    out["models"]["under_3000_max_wall_s"] = max(small) if small else None
    px = [p.get("pixels") for p in result["photos"] if p.get("pixels")]
    out["photos"]["pixels"] = int(np.median(px)) if px else None
    cp = [p["contour_points"] for p in result["photos"] if "contour_points" in p]
    out["photos"]["contour_points"] = {"min": min(cp), "max": max(cp)} if cp else None
    return out


# ------------------------------------------------------------------ tables


SEED_TABLE = {"ADR": 0.8589, "MR": 14.1, "LR": 0.9744}  # seed Table 5-2, "The proposed method"


def _f(x, fmt=".3f"):
    return "–" if x is None else format(x, fmt)


TARGETS = {"top1": 0.90, "first_rank": 1.2, "ADR": 0.86}  #: what the view matcher should reach


def accuracy_table(methods: dict, chance_row: dict | None, q: int, N: int) -> Table:
    t = Table([("method", "<"), ("photos", "<"), ("count", ">"), ("failed", ">"), ("top-1 %", ">"),
               ("mean 1st rank", ">"), ("ADR", ">"), ("MR", ">"), ("LR", ">")])
    t.add("seed Table 5-2 (q = 20, their set)", "–", "–", "–", "–", "–", _f(SEED_TABLE["ADR"], ".4f"),
          _f(SEED_TABLE["MR"], ".1f"), _f(SEED_TABLE["LR"], ".4f"))
    t.add("target", "all", "–", "–", f"≥ {100 * TARGETS['top1']:.0f}", f"≤ {TARGETS['first_rank']}",
          f"≥ {TARGETS['ADR']}", "–", "–")
    t.add(f"ideal here (q = {q}, N = {N})", "–", "–", "–", "100.0", "1.00", "1.000", f"{(q + 1) / 2:.2f}", "1.000")
    if chance_row:
        t.add("random ranking", "all", chance_row["queries"], "–", _f(100 * chance_row["top1"], ".1f"), "–",
              _f(chance_row["ADR"]), _f(chance_row["MR"], ".2f"), _f(chance_row["LR"]))
    for name, res in methods.items():
        if "error" in res:
            t.add_error(name, res["error"])
            continue
        s = res["summary"]
        groups = [("all", s["all"])] + [(c, v) for c, v in s["condition"].items()]
        for label, g in groups:
            rows = [r for r in res["queries"] if label == "all" or r["condition"] == label]
            first = float(np.mean([r["first_rank"] for r in rows]))
            t.add(name, label, g["queries"], g["failed"], _f(100 * g["top1"], ".1f"), _f(first, ".2f"),
                  _f(g["ADR"]), _f(g["MR"], ".2f"), _f(g["LR"]))
    return t


def view_table(methods: dict) -> Table:
    t = Table([("method", "<"), ("view", "<"), ("count", ">"), ("ADR", ">"), ("MR", ">"), ("LR", ">"),
               ("top-1 %", ">")])
    for name, res in methods.items():
        if "error" in res:
            continue
        for v, g in res["summary"]["view"].items():
            t.add(name, v, g["queries"], _f(g["ADR"]), _f(g["MR"], ".2f"), _f(g["LR"]), _f(100 * g["top1"], ".1f"))
    return t


def class_table(classes: list[dict], methods: dict) -> Table:
    names = [n for n, r in methods.items() if "error" not in r]
    cols = [("class", "<"), ("vertices", ">")]
    for n in names:
        cols += [(f"{n} top-1", ">"), (f"{n} ADR", ">"), (f"{n} mean 1st rank", ">")]
    t = Table(cols)
    for c in classes:
        cells = [c["class"], c["vertices"]]
        for n in names:
            rows = [r for r in methods[n]["queries"] if r["class"] == c["class"]]
            if not rows:
                cells += ["–"] * 3
                continue
            hits = sum(r["first_rank"] == 1 for r in rows)
            cells += [f"{hits}/{len(rows)}", _f(float(np.mean([r["ADR"] for r in rows]))),
                      _f(float(np.mean([r["first_rank"] for r in rows])), ".1f")]
        t.add(*cells)
    return t


def timing_table(methods: dict) -> Table:
    t = Table([("method", "<"), ("per model s (wall / CPU)", ">"), ("largest model s", ">"), ("vertices", ">"),
               ("largest under 3,000 vertices s", ">"), ("per photo s (wall / CPU)", ">"), ("largest photo s", ">"),
               ("pixels", ">"), ("contour points", ">"), ("per comparison s", ">")])
    t.add("seed 5.4 (MATLAB, i7)", "–", "–", "–", "< 50", "≈ 5", "–", "120000", "–", "≈ 0.33")
    t.add("target (VIEWS)", "≤ 2", "–", "–", "–", "–", "–", "–", "–", "–")
    for name, res in methods.items():
        if "error" in res:
            t.add_error(name, res["error"])
            continue
        tm = res["timing"]
        mo, ph, co = tm["models"], tm["photos"], tm["comparisons"]

        def pair(d):
            return "–" if d["wall_s"] is None else f"{d['wall_s']['mean']:.3f} / {d['cpu_s']['mean']:.3f}"

        vert = "–" if mo["vertices"] is None else f"{mo['vertices']['min']}-{mo['vertices']['max']}"
        cp = ph.get("contour_points")
        t.add(name, pair(mo), _f(mo["wall_s"] and mo["wall_s"]["max"], ".2f"), vert,
              _f(mo["under_3000_max_wall_s"], ".2f"), pair(ph), _f(ph["wall_s"] and ph["wall_s"]["max"], ".2f"),
              _f(ph["pixels"], "d"), "–" if not cp else f"{cp['min']}-{cp['max']}",
              _f(co["wall_s"] and co["wall_s"]["mean"], ".4f"))
    return t


def model_time_table(methods: dict) -> Table:
    """The view matcher's build time of every library model (as the seed's Figure 5-7 (a))."""
    res = methods.get(VIEWS_NAME, {})
    t = Table([("model", "<"), ("vertices", ">"), ("wall s", ">"), ("CPU s", ">")])
    for m in sorted(res.get("models", []), key=lambda m: m["vertices"]):
        t.add(m["name"], m["vertices"], _f(m["wall_s"], ".2f"), _f(m["cpu_s"], ".2f"))
    return t


# ------------------------------------------------------------------ main


def warm_up() -> None:
    """Imports and caches, so no timed call pays for them (the core methods only when they are there)."""
    import meshgen  # noqa: PLC0415  (tests/meshgen.py)

    V, F = meshgen.icosphere(2, 30.0)
    hu_features(silhouette(V, F, (0.0, 0.0, 1.0)))
    for method in ("VIEWS", "SKELETON"):
        try:
            api = retrieval_api(method)
        except BolusError:
            continue
        with __import__("contextlib").suppress(Exception):
            api.model_descriptor(V, F, rng=SEED)
            img = np.full((120, 160, 3), 200, np.uint8)
            img[30:90, 50:110] = 60
            api.photo_descriptor(img, rng=SEED)


def main(argv=None) -> int:
    ap = parser(__doc__, "4 small classes (chest, elbow, face patch, knee), one view each", repeat=1)
    ap.add_argument("--only", metavar="NAME", action="append", default=[],
                    help="only the classes whose name contains NAME (repeatable)")
    ap.add_argument("--methods", default=",".join((VIEWS_NAME, SEED_NAME, HU_NAME)),
                    help="the methods to run, comma-separated (default: all three)")
    ap.add_argument("--no-scale", action="store_true", help="leave out the build and query times at 50 and 1,000 "
                    "models")
    ap.add_argument("--out", metavar="DIR", help="keep the library and the query photos in DIR (default: a temp "
                    "folder, removed)")
    args = ap.parse_args(argv)
    v = versions()
    print(f"Bolus retrieval benchmark: Python {v['python']}, numpy {v['numpy']}, scipy {v['scipy']}, "
          f"{v['cpus']} CPUs{'  [--quick]' if args.quick else ''}", flush=True)
    t_start = time.perf_counter()
    chosen = [m for m in MESHES if (not args.quick or m[0] in QUICK_CLASSES)
              and (not args.only or any(o in m[0] for o in args.only))]
    views = {m[0]: query_views(m[0], 1 if args.quick else QUERY_VIEWS) for m in chosen}
    work = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bolus_retrieval_bench_"))
    try:
        payload = run(chosen, views, work, args.repeat, args.methods.split(","), scale=not args.no_scale)
    finally:
        if not args.out:
            shutil.rmtree(work, ignore_errors=True)
    total = time.perf_counter() - t_start
    md = report(payload, argv)
    finish(args, payload, total, md)
    return 0


def load_classes(chosen) -> tuple[list[dict], dict, list[str]]:
    """(class rows, {class: (V, F, up, front)}, skipped classes) of the chosen MESHES."""
    classes, data, skipped = [], {}, []
    for cls, file, scale, up, front, note in chosen:
        if not mesh_path(file).exists():
            print(f"== {cls}: {mesh_path(file)} not found, skipped")
            skipped.append(cls)
            continue
        V, F = load_class(file, scale)
        data[cls] = (V, F, up, front)
        classes.append({"class": cls, "file": file, "units": note, "vertices": len(V), "triangles": len(F),
                        "bbox_mm": np.ptp(V, axis=0).tolist(), "up": up, "front": front})
    if not classes:
        raise BolusError("no mesh of the library was found")
    return classes, data, skipped


def nearest_views(renders: list[dict]) -> dict:
    """The angle (degrees) from each query view to the nearest library view, for both libraries of views."""
    from bolus_addon.core.retrieval.view_render import fibonacci_directions  # noqa: PLC0415
    from bolus_addon.core.retrieval.views import DIRECTIONS  # noqa: PLC0415

    out = {}
    for key, dirs, mirror in (("HU", canonical_directions(), False), ("VIEWS", fibonacci_directions(DIRECTIONS),
                                                                       True)):
        ang = []
        for r in renders:
            c = dirs @ np.asarray(r["direction"])
            ang.append(float(np.degrees(np.arccos(np.clip((np.abs(c) if mirror else c).max(), -1.0, 1.0)))))
        out[key] = {"min": min(ang), "max": max(ang), "mean": float(np.mean(ang))}
    return out


def run_methods(names: list[str], library, queries, rel, repeat) -> dict:
    fns = {VIEWS_NAME: run_views, SEED_NAME: run_seed, HU_NAME: run_hu}
    methods = {}
    for name in names:
        print(f"== {name}", flush=True)
        try:
            res = fns[name](library, queries, rel, repeat)
            res["summary"] = summaries(res["queries"])
            res["most_often_first"] = most_often_first(res["queries"])
            res["timing"] = timing(res)
            methods[name] = res
        except Exception as exc:  # a benchmark reports, it does not stop at the first failure
            methods[name] = error_row("method", name, exc)
    return methods


def scale_rows(lib_dir: Path, work: Path, queries: list[dict]) -> dict:
    """Build times (1 and 2 at a time) and query times at SCALE_SIZES models (retrieval_scale.py)."""
    import retrieval_scale  # noqa: PLC0415

    print("== build and query times at scale", flush=True)
    try:
        builds = retrieval_scale.build_times(lib_dir, work)
        library_mod = __import__("bolus_addon.core.retrieval.library", fromlist=["x"])
        keep, todo, _ = library_mod.plan_update(lib_dir, "VIEWS")
        library_mod.update_library(lib_dir, [(p, p) for p in todo], keep, lambda *a: None, 0, 1, "VIEWS")
        by_kind = {k: [q["rgb"] for q in queries if q["condition"] == k] for k in SCALE_KINDS}
        photos = [p for k in SCALE_KINDS for p in by_kind[k][:SCALE_QUERIES]]
        return {"build": builds, "query": retrieval_scale.query_times(lib_dir, work, photos, SCALE_SIZES)}
    except Exception as exc:  # noqa: BLE001
        return error_row("scale", "scale", exc)


def run(chosen, views, work: Path, repeat: int = 1, method_names=(VIEWS_NAME, SEED_NAME, HU_NAME),
        scale: bool = True) -> dict:
    """Library, renders, queries, the methods; the JSON payload (without the photos)."""
    classes, data, skipped = load_classes(chosen)
    lib_dir, photo_dir = work / "library", work / "photos"
    photo_dir.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    library = build_library(lib_dir, {c: (V, F) for c, (V, F, _, _) in data.items()}, SEED)
    build_s = time.perf_counter() - t
    rel = relevant_sets(library)
    names = [m["name"] for m in library]
    print(f"== library: {len(library)} models of {len(classes)} classes in {lib_dir} ({build_s:.1f} s)", flush=True)
    renders, render_s = render_queries([(c, V, F, up, front) for c, (V, F, up, front) in data.items()], views,
                                       photo_dir)
    print(f"== {len(renders)} views rendered in two lights in {render_s:.1f} s", flush=True)
    queries = make_queries(renders)
    warm_up()
    methods = run_methods(list(method_names), library, queries, rel, repeat)
    extra = {k: [q[k] for q in queries if k in q] for k in ("occluded_share", "cropped_share")}
    view_rows = [{"class": c, "name": v[0], "azimuth_deg": v[1], "elevation_deg": v[2], "roll_deg": v[3]}
                 for c, vs in (views.items() if isinstance(views, dict) else []) for v in vs]
    return {"seed": SEED, "repeat": repeat, "classes": classes, "skipped": skipped,
            "library": [{k: m[k] for k in ("name", "class", "variant", "vertices", "triangles", "note")}
                        for m in library],
            "views": view_rows, "styles": [{"background_srgb": b, "object_srgb": o, "light": li} for b, o, li in STYLES],
            "renders": {"count": len(renders), "seconds": render_s, "size": [WIDTH, HEIGHT],
                        "nearest_library_view_deg": nearest_views(renders)},
            "queries": {"count": len(queries), "conditions": list(CONDITIONS), "photo_noise_sigma": PHOTO_NOISE,
                        **{k: ({"min": min(v), "max": max(v)} if v else None) for k, v in extra.items()}},
            "q": 3, "N": len(names), "chance": chance(queries, names, rel), "methods": methods,
            "scale": scale_rows(lib_dir, work, queries) if scale and VIEWS_NAME in method_names else None}


def hub_line(methods: dict) -> str:
    """Which models each method ranks first most often (of how many queries)."""
    parts = []
    for name, res in methods.items():
        if "error" in res or not res.get("most_often_first"):
            continue
        n = sum("error" not in r for r in res["queries"])
        parts.append(f"{name}: " + ", ".join(f"{m} ({c} of {n})" for m, c in res["most_often_first"]))
    return "Ranked first most often: " + ("; ".join(parts) if parts else "–") + "."


def scale_table(scale) -> Table | None:
    """Build seconds per model (1 and 2 at a time) and query seconds at 50 and 1,000 models."""
    if not scale:
        return None
    t = Table([("what", "<"), ("models", ">"), ("wall s", ">"), ("per model / per query s", ">"), ("target", ">")])
    if "error" in scale:
        t.add_error("scale", scale["error"])
        return t
    for b in scale["build"]:
        t.add(f"build, {b['jobs']} at a time", b["models"], _f(b["wall_s"], ".1f"), _f(b["per_model_s"], ".2f"),
              "≤ 2 per model")
    for q in scale["query"]:
        t.add(f"query (median of {q['queries']}; folder check {q['plan_s']:.2f} s, ranking {q['ranking_s']:.3f} s)",
              q["models"], _f(q["max_s"], ".2f") + " max", _f(q["median_s"], ".2f"),
              "≤ 2" if q["models"] <= 50 else "≤ 5")
    return t


def how_line(payload: dict) -> str:
    rq, qs = payload["renders"], payload["queries"]
    near = rq["nearest_library_view_deg"]
    occ, crop = qs.get("occluded_share"), qs.get("cropped_share")
    rng = (lambda d: "–" if not d else f"{100 * d['min']:.0f}-{100 * d['max']:.0f} %")
    return (f"{payload['N']} library models ({len(payload['classes'])} classes x original / turned / noisy, q = "
            f"{payload['q']} right answers per query), {qs['count']} photos: {rq['count']} unseen views (random turn, "
            f"tilt -20..50°, camera roll ±{ROLL_DEG:.0f}°; the nearest of VIEWS' library directions "
            f"{near['VIEWS']['min']:.0f}-{near['VIEWS']['max']:.0f}° away, mean {near['VIEWS']['mean']:.0f}°, of HU's "
            f"{near['HU']['min']:.0f}-{near['HU']['max']:.0f}°) rendered by Workbench ({rq['size'][0]} x "
            f"{rq['size'][1]} px) in two lights, each view as one photo per kind: clean, light (the other light and "
            f"object colour over a gradient background), noise (sigma {qs['photo_noise_sigma']}), blur (2 px), "
            f"cropped ({rng(crop)} of the object out of the frame), phone (270 x 480 portrait), occlusion (a grey "
            f"rectangle over {rng(occ)} of the object)")


def report(payload: dict, argv) -> str:
    methods = payload["methods"]
    t1 = accuracy_table(methods, payload["chance"], payload["q"], payload["N"])
    t2, t3, t4 = view_table(methods), class_table(payload["classes"], methods), timing_table(methods)
    t5, t6 = model_time_table(methods), scale_table(payload.get("scale"))
    how, hubs = how_line(payload), hub_line(methods)
    print(f"\nAccuracy ({how})\n{t1.text()}\n\nPer class\n{t3.text()}\n\n{hubs}\n\nTimes\n{t4.text()}")
    if t6:
        print(f"\nAt scale\n{t6.text()}")
    classes = "\n".join(f"* {c['class']}: `{c['file']}`, {c['vertices']} vertices, {c['units']}"
                        for c in payload["classes"])
    return (f"## Retrieval from a photo (`bench/retrieval_bench.py`)\n\n"
            f"{run_line('retrieval_bench.py', argv)}\n\n"
            f"VIEWS (the default: each model's silhouettes from 40 directions, and each of them cut by half-planes "
            f"from 16 directions taking away 10, 20, 30 or 40 % of it, for photos cut by the frame; Zernike "
            f"descriptors (the Fourier group cached, weight 0); the photo's silhouette from the seed's entropy edges "
            f"and spectral contour with a background model, and a variant without each foreign-coloured part of it, "
            f"an occluder) beside "
            f"SKELETON (the seed's chapter 5: feature skeletons, ICP) and HU (log Hu moment invariants of the object "
            f"mask against each model's best of {len(canonical_directions())} silhouettes) on the same photos; top-1 "
            f"= the right class first, mean 1st rank = the rank of the first right model; ADR, MR, LR as eqs. "
            f"5-15..5-17, averaged over the photos; {how}.  MR depends on q (the seed's set had q = 20, ideal 10.5; "
            f"here ideal {(payload['q'] + 1) / 2:.1f}).  Classes:\n\n{classes}\n\n"
            f"{t1.markdown()}\n\nPer view:\n\n{t2.markdown()}\n\nPer class (all views and kinds):\n\n"
            f"{t3.markdown()}\n\n{hubs}\n\nTimes (wall clock / CPU time of the process; the seed's figures are CPU "
            f"times in MATLAB):\n\n{t4.markdown()}\n"
            + (f"\nBuild and query times at scale (2 CPUs; the 1,000 models are copies of the bench's with jittered "
               f"descriptors, searched as Find Matching Bolus does):\n\n{t6.markdown()}\n" if t6 else "")
            + (f"\nVIEWS build time per library model:\n\n{t5.markdown()}\n" if t5.rows else ""))


if __name__ == "__main__":
    sys.exit(main())
