"""The object's contour in a photo: spectral clustering of its edge pixels (seed 5.1.2, eqs. 5-5..5-7).

`contour_pixels` takes the image (`image_edges.as_image`; pixel (x, y) is column x, row y, y down;
RGB in [0,1]) and its edge pixels (`image_edges.edge_mask`) and returns a `ContourResult`:

1. samples: above ``max_points`` (N_MAX, 6,000) edge pixels, one per s x s grid cell;
2. distance (eqs. 5-6, 5-7): d_ij = p_ij + w c_ij, p in pixels, c the RGB distance,
   w = W_COLOUR (80) px per unit (w s on a grid of s px);
3. graph (eq. 5-5): each sample joined to its ``neighbours`` (12) nearest by d, symmetrised,
   W_ij = exp(-d_ij^2 / (2 sigma^2)), sigma the mean d over these edges, >= BRIDGE_WEIGHT;
4. groups: connected pieces of the strong edges (d <= 3 sigma); under MIN_GROUP (2 %): background;
5. spectral clustering into 2 (eqs. 3-3, 3-8): the two smallest eigenvectors of L = D - W, then
   k-means (`clustering.cluster_rows`), pieces of the graph first joined by their closest pair;
6. the object is the cluster nearer the image centre; step 5 is repeated on it while the cut's
   mean edge weight is under SEPARATE (1/2) of the graph's (at most MAX_SPLITS times);
7. the contour: the object's outermost pixel layer after closing gaps of up to 2 % of the image
   diagonal, filling holes and dropping pieces under MIN_PIECE; points ordered by angle.

Design notes: docs/design/retrieval.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from ..analysis.clustering import cluster_rows
from ..errors import BolusError
from .image_edges import as_image, checked_float, edge_mask
from ..rng import as_rng
from ..analysis.spectral import graph_laplacian, smallest_eigenvectors

__all__ = ["N_MAX", "W_COLOUR", "NEIGHBOURS", "BRIDGE_WEIGHT", "STRONG_WEIGHT", "MIN_GROUP", "SEPARATE", "MAX_SPLITS",
           "CLOSE_FRACTION", "CLOSE_MIN", "MIN_PIECE", "ContourResult", "contour_pixels", "sample_grid", "edge_graph",
           "join_groups", "two_way", "cut_ratio", "separate_object", "object_cluster", "outer_contour"]

N_MAX = 6000  #: at most this many edge pixels in the eigenproblem (module doc, step 1)
W_COLOUR = 80.0  #: w of eq. 5-6: pixels per unit of RGB distance (RGB in [0,1])
NEIGHBOURS = 12  #: nearest neighbours of each edge pixel in the graph
BRIDGE_WEIGHT = 1e-6  #: least weight of a graph edge, and of an edge that joins two pieces of the graph
CLOSE_FRACTION, CLOSE_MIN = 0.02, 3.0  #: r of step 7: 2 % of the image diagonal, >= 3 px
FLOOD_DEPTH = 2.0  #: px: how deep the outside is flooded into the filled outline (step 7)
MIN_PIECE = 0.1  #: filled pieces less than this share of the largest piece's size across are dropped
MIN_GROUP = 0.02  #: groups (and cut sides) under this share of the samples are background (module doc, step 4)
MIN_EDGE_PIXELS = 16  #: fewer edge pixels: no contour to find
STRONG_WEIGHT = float(np.exp(-4.5))  #: graph edges at least this heavy (d <= 3 sigma) make the groups (step 4)
SEPARATE = 0.5  #: a 2-way cut separates two structures when its cut edges weigh under this share of the mean
MAX_SPLITS = 8  #: 2-way cuts at most (module doc, step 6)


@dataclass
class ContourResult:
    """points (P,2) float: the object's contour pixels (x, y), ordered by angle about their centroid;
    edge_points (n,2) float: every edge pixel (x, y), raster order; labels (n,) int64: 1 the object's
    cluster, 0 the background's; object_label: 1; sigma: sigma of eq. 5-5 (px); samples: edge pixels in
    the graph; groups: groups of the graph (module doc, step 4); splits: the 2-way cuts, see
    `separate_object`."""

    points: np.ndarray
    edge_points: np.ndarray
    labels: np.ndarray
    object_label: int
    sigma: float
    samples: int
    groups: int
    splits: list

    @property
    def object_points(self) -> np.ndarray:
        """(m,2) every edge pixel (x, y) of the object's cluster."""
        return self.edge_points[self.labels == self.object_label]


def sample_grid(xy: np.ndarray, max_points: int = N_MAX) -> tuple[np.ndarray, int]:
    """Evenly spread samples of pixels xy (n,2) int: (indices (m,) into xy, m <= max_points, cell size s)."""
    n = len(xy)
    if n <= max_points:
        return np.arange(n), 1
    s = max(2, int(np.floor(np.sqrt(n / max_points))))
    while True:
        cells = (xy[:, 1] // s) * (int(xy[:, 0].max()) // s + 1) + xy[:, 0] // s
        _, first = np.unique(cells, return_index=True)
        if len(first) <= max_points:
            return np.sort(first), s
        s += 1


def edge_graph(xy: np.ndarray, rgb: np.ndarray, w: float, neighbours: int = NEIGHBOURS
               ) -> tuple[sp.csr_matrix, float]:
    """Eqs. 5-5..5-7 on the k-nearest graph of the points xy (n,2) float with colours rgb (n,3) in [0,1].

    Returns (W (n,n) symmetric csr, zero diagonal, sigma); W may have several connected components
    (`join_groups`).
    """
    n = len(xy)
    k = min(neighbours, n - 1)
    joint = np.hstack([xy, w * rgb])
    cand = min(n, 3 * k + 1)
    _, idx = cKDTree(joint).query(joint, k=cand)
    idx = idx.reshape(n, -1)[:, 1:]
    d = _d(xy, rgb, w, np.repeat(np.arange(n), idx.shape[1]), idx.ravel()).reshape(idx.shape)
    order = np.argsort(d, axis=1, kind="stable")[:, :k]
    rows = np.repeat(np.arange(n), k)
    cols = np.take_along_axis(idx, order, axis=1).ravel()
    dist = np.take_along_axis(d, order, axis=1).ravel()
    sigma = float(dist.mean()) if dist.size else 1.0
    if not sigma > 0:
        sigma = 1.0
    wts = np.maximum(np.exp(-(dist**2) / (2.0 * sigma**2)), BRIDGE_WEIGHT)  # an edge of the graph stays an edge
    W = sp.coo_matrix((wts, (rows, cols)), shape=(n, n)).tocsr()
    W = W.maximum(W.T).tocsr()
    W.setdiag(0.0)
    W.eliminate_zeros()
    return W, sigma


def join_groups(W: sp.csr_matrix, xy: np.ndarray, rgb: np.ndarray, w: float, sigma: float) -> sp.csr_matrix:
    """W (n,n) with its connected components joined, each by its closest pair (d of eq. 5-6) to another,
    weight max(eq. 5-5, BRIDGE_WEIGHT), until W is connected (module doc, step 3)."""
    n = W.shape[0]
    ncomp, comp = connected_components(W, directed=False)
    if ncomp == 1:
        return W
    joint = np.hstack([xy, w * rgb])
    tree = cKDTree(joint)
    while ncomp > 1:
        bi, bj = _bridges(joint, tree, comp, ncomp)
        bd = _d(xy, rgb, w, bi, bj)
        bw = np.maximum(np.exp(-(bd**2) / (2.0 * sigma**2)), BRIDGE_WEIGHT)
        B = sp.coo_matrix((np.r_[bw, bw], (np.r_[bi, bj], np.r_[bj, bi])), shape=(n, n)).tocsr()
        W = W.maximum(B).tocsr()
        ncomp, comp = connected_components(W, directed=False)
    return W


def _d(xy, rgb, w, i, j) -> np.ndarray:
    """Eq. 5-6 for the pairs (i, j): pixel distance + w * RGB distance (eq. 5-7)."""
    return np.linalg.norm(xy[i] - xy[j], axis=1) + w * np.linalg.norm(rgb[i] - rgb[j], axis=1)


def _bridges(joint, tree, comp, ncomp) -> tuple[np.ndarray, np.ndarray]:
    """For every component but the largest: its closest pair (joint space) to another component."""
    sizes = np.bincount(comp, minlength=ncomp)
    largest = int(np.argmax(sizes))
    bi, bj = [], []
    n = len(joint)
    for c in range(ncomp):
        if c == largest:
            continue
        members = np.flatnonzero(comp == c)
        kq = min(n, 32)
        dist, idx = tree.query(joint[members], k=kq)
        dist, idx = dist.reshape(len(members), -1), idx.reshape(len(members), -1)
        foreign = comp[idx] != c
        if foreign.any():
            dist = np.where(foreign, dist, np.inf)
            r, col = np.unravel_index(np.argmin(dist), dist.shape)
            bi.append(members[r])
            bj.append(idx[r, col])
        else:  # a tight group: search the other pixels only
            others = np.flatnonzero(comp != c)
            dist, j = cKDTree(joint[others]).query(joint[members], k=1)
            r = int(np.argmin(dist))
            bi.append(members[r])
            bj.append(others[j[r]])
    return np.asarray(bi, dtype=np.int64), np.asarray(bj, dtype=np.int64)


def two_way(W: sp.csr_matrix, rng) -> np.ndarray:
    """Spectral clustering of a connected graph W (n,n) into 2 (eqs. 3-3, 3-8): the two smallest
    eigenvectors of L = D - W and k-means -> labels (n,) in {0, 1}."""
    _, U = smallest_eigenvectors(graph_laplacian(W), 2, rng=rng)
    return cluster_rows(U, 2, "kmeans", rng=rng)


def cut_ratio(W: sp.csr_matrix, side: np.ndarray) -> float:
    """Mean weight of the edges of W (n,n) that the split side (n,) bool cuts, over the mean weight of all of
    W's edges (0 when nothing is cut)."""
    cross = W[side][:, ~side]
    if cross.nnz == 0:
        return 0.0
    return float(cross.data.mean()) / float(W.data.mean())


def separate_object(W: sp.csr_matrix, xy: np.ndarray, rgb: np.ndarray, w: float, sigma: float,
                    shape: tuple[int, int], rng) -> tuple[np.ndarray, int, list]:
    """The object's samples among the edge-pixel samples (module doc, steps 4-6).

    W (n,n) the graph of `edge_graph`, xy (n,2), rgb (n,3), w, sigma as there; shape (H, W) of the image.
    Returns (indices (m,) of the object's samples, number of groups, splits: one (cut ratio, samples kept
    as the object, samples given to the background) per 2-way cut; the last one, when it was not taken,
    with 0 given to the background).
    """
    n = W.shape[0]
    strong = W.copy()
    strong.data = np.where(strong.data >= STRONG_WEIGHT, strong.data, 0.0)
    strong.eliminate_zeros()
    groups, comp = connected_components(strong, directed=False)
    sizes = np.bincount(comp)
    big = (sizes >= MIN_GROUP * n) | (sizes == sizes.max())
    obj = np.flatnonzero(big[comp])
    splits = []
    for _ in range(MAX_SPLITS):
        if len(obj) < 2 * MIN_EDGE_PIXELS:
            break
        Wc = join_groups(W[obj][:, obj].tocsr(), xy[obj], rgb[obj], w, sigma)
        lab = two_way(Wc, rng)
        if lab.min() == lab.max():
            break
        side = lab == 0
        cut = cut_ratio(Wc, side)
        if cut >= SEPARATE:
            splits.append((cut, len(obj), 0))
            break
        small = min(side.sum(), (~side).sum())
        if small < MIN_GROUP * n:  # a crumb: background, whatever its place
            keep = side if side.sum() > (~side).sum() else ~side
        else:
            o = object_cluster(xy[obj], lab, shape)
            keep = lab == o
        splits.append((cut, int(keep.sum()), int((~keep).sum())))
        obj = obj[keep]
    return obj, groups, splits


def object_cluster(xy: np.ndarray, labels: np.ndarray, shape: tuple[int, int]) -> int:
    """The object's label (module doc, step 5): the cluster nearer the image centre on average.
    xy (n,2) pixels (x, y), labels (n,), shape (H, W)."""
    H, W = shape
    centre = np.array([(W - 1) / 2.0, (H - 1) / 2.0])
    r = np.linalg.norm(xy - centre, axis=1) / (0.5 * np.hypot(W, H))
    present = np.unique(labels)
    means = [float(r[labels == c].mean()) for c in present]
    return int(present[int(np.argmin(means))])


def outer_contour(obj: np.ndarray, close_radius: float | None = None, min_piece: float = MIN_PIECE) -> np.ndarray:
    """The outline pixels of an object's edge pixels obj (H,W) bool -> (H,W) bool (module doc, step 6).

    close_radius: r in px (default CLOSE_FRACTION of the image diagonal, at least CLOSE_MIN)."""
    H, W = obj.shape
    r = float(close_radius) if close_radius is not None else max(CLOSE_MIN, CLOSE_FRACTION * np.hypot(H, W))
    pad = int(np.ceil(r)) + 2
    O = np.pad(obj, pad)
    if not O.any():
        return np.zeros((H, W), dtype=bool)
    # grown by r (gaps up to 2r closed), holes filled, shrunk by r: the filled outline
    grown = ndimage.binary_fill_holes(ndimage.distance_transform_edt(~O) <= r)
    filled = ndimage.binary_fill_holes((ndimage.distance_transform_edt(grown) > r) | O)
    lab, count = ndimage.label(filled, structure=np.ones((3, 3)))
    if count > 1:  # stray specks: pieces much smaller across than the largest
        boxes = ndimage.find_objects(lab)
        size = np.array([np.hypot(b[0].stop - b[0].start, b[1].stop - b[1].start) for b in boxes])
        filled = np.isin(lab, np.flatnonzero(size >= min_piece * size.max()) + 1)
    O &= filled
    # the outside, flooded (4-connected) through the pixels that are not the object's, FLOOD_DEPTH deep at most
    margin = ~O & (ndimage.distance_transform_edt(filled) <= FLOOD_DEPTH)
    outside = ndimage.binary_propagation(~filled, mask=~filled | margin)
    out = O & ndimage.binary_dilation(outside)
    return out[pad:-pad, pad:-pad]


def contour_pixels(rgb, mask=None, w: float = W_COLOUR, neighbours: int = NEIGHBOURS, rng=0,
                   max_points: int = N_MAX) -> ContourResult:
    """The object's contour from the edge pixels of a photo (eqs. 5-5..5-7, module doc steps 1-6).

    rgb (H,W,3) uint8 or float in [0,1] ((H,W) grey, (H,W,4) RGBA: alpha ignored); mask (H,W) bool
    edge pixels (default: `image_edges.edge_mask(rgb)`); w: eq. 5-6's colour weight (px per unit RGB
    distance); neighbours: graph degree; rng: seed or Generator of the eigen-solver and k-means;
    max_points: edge pixels in the eigenproblem.  -> ContourResult.  BolusError on a bad image or mask,
    or too few edge pixels.
    """
    img = as_image(rgb)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    H, W = img.shape[:2]
    if mask is None:
        mask = edge_mask(img)
    m = np.asarray(mask)
    if m.shape != (H, W):
        raise BolusError(f"the edge mask must be {H} x {W} like the image, got shape {m.shape}")
    if m.dtype != bool:
        if m.dtype.kind not in "biuf" or not np.isin(m, (0, 1)).all():
            raise BolusError("the edge mask must be a boolean (H, W) array")
        m = m.astype(bool)
    w = checked_float(w, lambda x: np.isfinite(x) and x >= 0, "the colour weight w must be a number >= 0")
    if isinstance(neighbours, bool) or not isinstance(neighbours, (int, np.integer)) or neighbours < 2:
        raise BolusError(f"neighbours must be an integer >= 2, got {neighbours!r}")
    if isinstance(max_points, bool) or not isinstance(max_points, (int, np.integer)) or max_points < 100:
        raise BolusError(f"max_points must be an integer >= 100, got {max_points!r}")
    ys, xs = np.nonzero(m)
    n = len(xs)
    if n < MIN_EDGE_PIXELS:
        raise BolusError(f"the photo has no edges to find a contour in: {n} edge pixels (at least "
                         f"{MIN_EDGE_PIXELS} are needed); use a photo of the object against a background")
    xy_all = np.column_stack([xs, ys])
    rgb_all = img[ys, xs]
    rng = as_rng(rng)
    pick, s = sample_grid(xy_all, int(max_points))
    xy, col = xy_all[pick].astype(np.float64), rgb_all[pick]
    ws = w * s
    Wg, sigma = edge_graph(xy, col, ws, int(neighbours))
    with threadpool_limits(1):  # small problems: BLAS and OpenMP threads only wait on each other (10-100x)
        obj, groups, splits = separate_object(Wg, xy, col, ws, sigma, (H, W), rng)
    is_obj = np.zeros(len(xy), dtype=bool)
    is_obj[obj] = True
    if len(pick) < n:  # the pixels off the grid: the label of the nearest sample
        tree = cKDTree(np.hstack([xy, ws * col]))
        _, nearest = tree.query(np.hstack([xy_all.astype(np.float64), ws * rgb_all]), k=1)
        is_obj = is_obj[nearest]
    labels = is_obj.astype(np.int64)
    obj_label = 1
    omask = np.zeros((H, W), dtype=bool)
    sel = labels == obj_label
    omask[ys[sel], xs[sel]] = True
    outline = outer_contour(omask)
    cy, cx = np.nonzero(outline)
    pts = np.column_stack([cx, cy]).astype(np.float64)
    if len(pts):
        c = pts.mean(axis=0)
        ang = np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0])
        pts = pts[np.lexsort((np.hypot(*(pts - c).T), ang))]
    return ContourResult(points=pts, edge_points=xy_all.astype(np.float64), labels=labels, object_label=obj_label,
                         sigma=sigma, samples=len(pick), groups=int(groups), splits=splits)
