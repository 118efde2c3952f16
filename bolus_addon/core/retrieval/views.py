"""The view matcher (``method='VIEWS'``, the default): a model is the set of its silhouettes.

* `model_descriptor(V, F)`: the model rendered (`view_render`, bpy-free) from DIRECTIONS directions of
  the half sphere (Fibonacci spiral, orthographic, RENDER_PX square), each silhouette described by
  `shape_descriptors.describe` (Zernike magnitudes + centroid-distance Fourier magnitudes, invariant to
  scale, translation, in-plane rotation and mirror) -> `ViewsDescriptor` (k, D) float32, with the Zernike
  magnitudes of every view cut as a frame cuts a photo (`partial_views.cut_descriptors`) beside it;
* `photo_descriptor(rgb)`: the photo's silhouette (`photo_silhouette`: the seed's entropy edges and
  spectral contour with a background model) described the same way, with a row for each variant
  without a foreign-coloured part (`partial_views.occluder_variants`) -> (1 + variants, D);
* `ViewIndex(library)`: every view of every model stacked into one matrix, with each descriptor
  group's weight GROUP_WEIGHT / (its mean L1 distance between library views); `rank(query)`: one
  vectorised weighted L1 distance from each photo row to all views, a model's distance = its best view
  (``np.minimum.reduceat``) for the best row; a photo whose outline lies on the frame's edge
  (``cut`` > CUT_WARN) is also compared, by its first row, with the cut views; divided by the weights'
  sum (about 1 for unrelated shapes), best first.

Design notes: docs/design/retrieval.md.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import BolusError
from . import partial_views as pv
from . import shape_descriptors as sd
from .photo_silhouette import photo_silhouette
from .view_render import fibonacci_directions, render_views

__all__ = ["NAME", "SETTINGS", "DIRECTIONS", "RENDER_PX", "ViewsDescriptor", "Descriptor", "model_descriptor", "photo_descriptor",
           "ViewIndex", "rank", "group_weights"]

NAME = "VIEWS"
DIRECTIONS = 40  #: view directions on the half sphere (as 80 on the whole sphere: mirrors are alike)
RENDER_PX = 128  #: silhouette side in pixels
PAIRS = 4000  #: random view pairs that set the group weights
#: each descriptor group's weight after its scaling (measured: the Fourier group adds nothing on whole photos and
#: costs on cut or occluded ones, docs/design/retrieval.md; it stays in the cache for other weights)
GROUP_WEIGHT = {"zernike": 1.0, "fourier": 0.0}
CUT_WARN = 0.03  #: a photo whose outline lies on the frame's edge for more than this share is warned
CHUNK_ROWS = 250_000  #: cut views compared at once (bounds the memory of a query on a large library)
SETTINGS = {"method": "views: silhouettes, Zernike + Fourier, L1 best view", "directions": DIRECTIONS,
            "render_px": RENDER_PX, "grid": sd.GRID, "order": sd.ORDER, "bins": sd.BINS, "harmonics": sd.HARMONICS,
            "cut_directions": pv.CUT_DIRECTIONS, "cut_shares": list(pv.CUT_SHARES)}


@dataclass
class ViewsDescriptor:
    """The descriptor rows of a model's views (k, D) or of a photo (1, D)."""

    matrix: np.ndarray
    kind: str  #: "model" or "photo"
    size: int  #: vertices of the model, or silhouette pixels of the photo
    seconds: float = 0.0
    mask: np.ndarray | None = field(default=None, repr=False)  #: a photo's silhouette (not cached)
    cut: float = 0.0  #: a photo's share of the outline on the frame's edge
    cuts: np.ndarray | None = field(default=None, repr=False)  #: a model's cut views (c, ZERNIKE_COUNT) float16

    def warnings(self) -> list[str]:
        """What the user should know about a photo's descriptor (the object cut by the frame)."""
        if self.cut > CUT_WARN:
            return [f"the object touches the photo's edge ({100 * self.cut:.0f} % of its outline): a silhouette "
                    "cut by the frame can match the wrong model; take the photo with all of the object in the frame"]
        return []

    def arrays(self) -> dict:
        cuts = self.cuts if self.cuts is not None else np.zeros((0, sd.ZERNIKE_COUNT), np.float16)
        return {"views": np.asarray(self.matrix, np.float32), "cuts": np.asarray(cuts, np.float16)}

    @classmethod
    def from_arrays(cls, data: dict, kind: str, size: int, seconds: float) -> ViewsDescriptor:
        cuts = data.get("cuts")
        return cls(np.asarray(data["views"], np.float32), kind, int(size), float(seconds),
                   cuts=None if cuts is None else np.asarray(cuts, np.float16))


Descriptor = ViewsDescriptor  #: the name the library looks for


def model_descriptor(V, F, rng=0) -> ViewsDescriptor:
    """Descriptors of the model's DIRECTIONS silhouettes (views that show nothing are left out) and of their
    cuts (`partial_views.cut_descriptors`)."""
    from ..mesh.topology import check_mesh  # noqa: PLC0415

    V, F = check_mesh(V, F, "the model", nondegenerate=False)
    t = time.perf_counter()
    sils, _ = render_views(V, F, fibonacci_directions(DIRECTIONS), RENDER_PX)
    sils = sils[sils.reshape(len(sils), -1).any(axis=1)]
    imgs = np.array([sd.canonical(m) for m in sils]).reshape(-1, sd.GRID, sd.GRID)
    M = np.hstack([sd.zernike(imgs), sd.fourier(imgs)]).astype(np.float32)
    ok = np.isfinite(M).all(axis=1)
    return ViewsDescriptor(M[ok], "model", len(V), time.perf_counter() - t, cuts=pv.cut_descriptors(imgs[ok]))


def photo_descriptor(rgb, rng=0) -> ViewsDescriptor:
    """The descriptors (1 + variants, D) of the photo's silhouette (`photo_silhouette`) and of its variants
    without a foreign-coloured part (`partial_views.occluder_variants`); BolusError when there is none."""
    t = time.perf_counter()
    sil = photo_silhouette(rgb, rng=rng)
    masks = [sil.mask] + pv.occluder_variants(sil.image, sil.mask)
    return ViewsDescriptor(sd.describe(np.array(masks)), "photo", int(sil.mask.sum()), time.perf_counter() - t,
                           sil.mask, sil.cut)


def group_weights(M: np.ndarray, rng=0) -> np.ndarray:
    """(D,) weights: GROUP_WEIGHT / the mean L1 distance of each group (`shape_descriptors.GROUPS`) over random
    pairs of the rows of M (k, D) (GROUP_WEIGHT where the rows are all alike)."""
    g = np.random.default_rng(rng)
    n = len(M)
    i, j = g.integers(0, n, PAIRS), g.integers(0, n, PAIRS)
    diff = np.abs(M[i].astype(np.float64) - M[j])
    w = np.ones(M.shape[1])
    for name, sl in sd.GROUPS.items():
        mean = float(diff[:, sl].sum(axis=1).mean()) if n > 1 else 0.0
        w[sl] = GROUP_WEIGHT[name] / mean if mean > 1e-12 else GROUP_WEIGHT[name]
    return w


class ViewIndex:
    """All views of a library in one matrix: names (models), M (total views, D), starts (models,); the cut
    views likewise: C (total cuts, ZERNIKE_COUNT) float16, cut_starts (models,) (models without cuts: none)."""

    def __init__(self, library: dict):
        if not library:
            raise BolusError("the library is empty: build it from a folder of models first")
        self.names = sorted(library)
        mats = [np.asarray(library[n].matrix, np.float32) for n in self.names]
        counts = np.array([len(m) for m in mats])
        if (counts == 0).any():
            raise BolusError(f"{self.names[int(np.argmin(counts))]} has no views in the library")
        self.M = np.concatenate(mats)
        self.starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.w = group_weights(self.M).astype(np.float32)
        cuts = [getattr(library[n], "cuts", None) for n in self.names]
        cuts = [np.zeros((0, sd.ZERNIKE_COUNT), np.float16) if c is None else np.asarray(c, np.float16) for c in cuts]
        self.cut_counts = np.array([len(c) for c in cuts])
        self.C = np.concatenate(cuts)
        self.cut_starts = np.concatenate([[0], np.cumsum(self.cut_counts)[:-1]])

    def distances(self, q: np.ndarray) -> np.ndarray:
        """(models,) each model's best-view distance to the query row q (D,)."""
        d = np.abs(self.M - np.asarray(q, np.float32).ravel()) @ self.w / sum(GROUP_WEIGHT.values())
        return np.minimum.reduceat(d, self.starts)

    def cut_distances(self, q: np.ndarray) -> np.ndarray:
        """(models,) each model's best cut-view distance to the query row q (D,) by its Zernike group (inf for
        a model without cut views); CHUNK_ROWS rows at a time."""
        zs = sd.GROUPS["zernike"]
        qz, wz = np.asarray(q, np.float32).ravel()[zs], self.w[zs] / sum(GROUP_WEIGHT.values())
        d = np.empty(len(self.C), np.float32)
        for i in range(0, len(self.C), CHUNK_ROWS):
            d[i:i + CHUNK_ROWS] = np.abs(self.C[i:i + CHUNK_ROWS].astype(np.float32) - qz) @ wz
        out = np.full(len(self.names), np.inf)
        has = self.cut_counts > 0
        if has.any():
            out[has] = np.minimum.reduceat(d, self.cut_starts[has])
        return out

    def query_distances(self, query: ViewsDescriptor) -> np.ndarray:
        """(models,) the best over the photo's rows (`photo_descriptor`), and over the cut views when its
        outline lies on the frame's edge."""
        rows = np.asarray(query.matrix, np.float32)
        d = np.min([self.distances(r) for r in rows], axis=0)
        if query.cut > CUT_WARN:
            d = np.minimum(d, self.cut_distances(rows[0]))
        return d

    def rank(self, query: ViewsDescriptor) -> list[tuple[str, float]]:
        d = self.query_distances(query)
        order = sorted(range(len(d)), key=lambda k: (float(d[k]), self.names[k]))
        return [(self.names[k], float(d[k])) for k in order]


def rank(query: ViewsDescriptor, library: dict) -> list[tuple[str, float]]:
    """[(name, distance)] of every library `ViewsDescriptor`, best (lowest) first, ties by name."""
    return ViewIndex(library).rank(query)
