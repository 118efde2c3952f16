"""The seed's chapter-5 matcher (``method='SKELETON'``): feature skeletons compared by ICP.

`model_descriptor` (5.2: spectral embedding of the vertices, eqs. 5-10, 5-11; skeleton 5.2.2) and
`photo_descriptor` (5.1: edges by visual entropies, eqs. 5-1..5-4; contour by spectral clustering,
5-5..5-7; embedding of the contour, 5-8, 5-9; skeleton) describe both sides in the same 3-D feature
space; `rank` orders the library by the ICP dissimilarity (5.3, eqs. 5-12..5-14), best first.

Design notes: docs/design/retrieval.md.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import BolusError

__all__ = ["NAME", "SETTINGS", "Descriptor", "model_descriptor", "photo_descriptor", "rank"]

NAME = "SKELETON"
#: the method's settings stored with the cache (a change rebuilds it): the skeleton's samples, clusters
SETTINGS = {"method": "spectral feature skeleton + ICP (seed ch. 5)", "samples": 64, "clusters": 6, "k": 3}


@dataclass
class Descriptor:
    """What is compared of a model or a photo: its feature skeleton (5.2.2) in the 3-D feature space."""

    points: np.ndarray  #: (s,3) skeleton points (centre first)
    edges: np.ndarray  #: (e,2) int, skeleton connections
    samples: np.ndarray  #: (c,3) points spread evenly along the skeleton (the ICP input)
    kind: str  #: "model" or "photo"
    size: int  #: vertices of the model, or contour pixels of the photo
    seconds: float = 0.0  #: time to describe it

    def arrays(self) -> dict:
        return {"points": np.asarray(self.points, np.float64), "edges": np.asarray(self.edges, np.int64),
                "samples": np.asarray(self.samples, np.float64)}

    @classmethod
    def from_arrays(cls, data: dict, kind: str, size: int, seconds: float) -> Descriptor:
        return cls(np.asarray(data["points"]), np.asarray(data["edges"]), np.asarray(data["samples"]), kind,
                   int(size), float(seconds))


def _descriptor(skel, kind: str, size: int, seconds: float) -> Descriptor:
    from .spectral_skeleton import skeleton_samples  # noqa: PLC0415

    return Descriptor(np.asarray(skel.points, np.float64), np.asarray(skel.edges, np.int64),
                      skeleton_samples(skel, SETTINGS["samples"]), kind, int(size), float(seconds))


def model_descriptor(V, F, rng=0) -> Descriptor:
    """The feature skeleton of a model V (n,3), F (m,3) (5.2: eqs. 5-10, 5-11, skeleton 5.2.2)."""
    from .spectral_skeleton import model_skeleton  # noqa: PLC0415
    from ..mesh.topology import check_mesh  # noqa: PLC0415

    V, F = check_mesh(V, F, "the model", nondegenerate=False)
    t = time.perf_counter()
    skel = model_skeleton(V, F, clusters=SETTINGS["clusters"], k=SETTINGS["k"], rng=rng)
    return _descriptor(skel, "model", len(V), time.perf_counter() - t)


def photo_descriptor(rgb, rng=0) -> Descriptor:
    """The feature skeleton of a photo's object contour (5.1: eqs. 5-1..5-7; 5.2: 5-8, 5-9)."""
    from .image_contour import contour_pixels  # noqa: PLC0415
    from .spectral_skeleton import image_skeleton  # noqa: PLC0415

    t = time.perf_counter()
    contour = contour_pixels(rgb, rng=rng)
    skel = image_skeleton(contour.points, clusters=SETTINGS["clusters"], k=SETTINGS["k"], rng=rng)
    return _descriptor(skel, "photo", len(contour.points), time.perf_counter() - t)


def rank(query: Descriptor, library: dict) -> list[tuple[str, float]]:
    """[(name, dissimilarity)] of every library `Descriptor`, best (lowest) first, ties by name
    (eqs. 5-12..5-14: the ICP error between the skeletons' samples)."""
    from .spectral_skeleton import dissimilarity  # noqa: PLC0415

    if not library:
        raise BolusError("the library is empty: build it from a folder of models first")
    scores = [(name, float(dissimilarity(query.samples, d.samples))) for name, d in library.items()]
    return sorted(scores, key=lambda x: (x[1], x[0]))
