"""The result of a print segmentation: its parts, their table and area balance.

Shared by the spectral split (`print_segmentation`) and the learned one
(`learned_segmentation`), which both return a `PrintSegmentation`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import BolusError
from ..mesh.topology import MeshTopology

__all__ = ["MIN_PART_FRACTION", "PrintPart", "PrintSegmentation", "part_stats", "area_balance"]

MIN_PART_FRACTION = 0.05  #: parts under 5 % of the area are merged: a smaller part is not worth a print


@dataclass
class PrintPart:
    """One part of a print segmentation."""

    part: int
    faces: int
    vertices: int
    area_mm2: float

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class PrintSegmentation:
    """Result of `print_segmentation` on a mesh with m triangles."""

    labels: np.ndarray  #: (m,) part of each triangle, 0..p-1, by decreasing area
    clusters: np.ndarray  #: (m,) raw Gaussian-mixture cluster of each triangle
    eigenvalues: np.ndarray  #: (k,)
    embedding: np.ndarray  #: (m,k) U' (abcut) or U (ratiocut)
    method: str
    requested: int
    min_part_fraction: float = MIN_PART_FRACTION  #: parts below this fraction of the area were merged

    @property
    def part_count(self) -> int:
        return int(self.labels.max()) + 1 if self.labels.size else 0

    def count_note(self) -> str | None:
        """Why the part count differs from the one asked, or None."""
        p = self.part_count
        if p == self.requested:
            return None
        return (f"{p} parts instead of the {self.requested} asked: clusters that fell apart became separate parts, "
                f"pieces under {100 * self.min_part_fraction:g} % of the area were merged")

    def summary(self) -> str | None:
        """A line for the user on how the parts were found (the learned split's); None here."""
        return None

    def table(self, V, F, topo: MeshTopology | None = None) -> dict:
        """The parts' rows (`part_stats`) and their area balance, as JSON-ready data."""
        topo = MeshTopology(V, F) if topo is None else topo
        return {"method": self.method, "requested": self.requested,
                "parts": [r.as_dict() for r in part_stats(V, F, self.labels, topo)],
                "area_balance": area_balance(self.labels, topo.areas)}


def part_stats(V, F, labels, topo: MeshTopology | None = None) -> list[PrintPart]:
    """Faces, vertices and area (mm^2) of every part of ``labels`` (m,) int 0..p-1 on V (n,3), F (m,3)
    -> p `PrintPart` rows."""
    topo = MeshTopology(V, F) if topo is None else topo
    labels = np.asarray(labels)
    if labels.shape != (topo.m,):
        raise BolusError("part labels must give one part per triangle")
    p = int(labels.max()) + 1 if labels.size else 0
    areas = np.bincount(labels, weights=topo.areas, minlength=p)
    faces = np.bincount(labels, minlength=p)
    rows = []
    for q in range(p):
        verts = len(np.unique(topo.F[labels == q])) if faces[q] else 0
        rows.append(PrintPart(q, int(faces[q]), verts, float(areas[q])))
    return rows


def area_balance(labels, areas) -> float:
    """Largest over smallest part area for labels (m,) int 0..p-1 and face areas (m,)
    (1 = perfectly balanced; inf if a part is empty)."""
    labels = np.asarray(labels)
    a = np.bincount(labels, weights=np.asarray(areas, dtype=np.float64), minlength=int(labels.max()) + 1)
    return float(a.max() / a.min()) if a.min() > 0 else float("inf")
