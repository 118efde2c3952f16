"""Orienting the parts of a model for printing (the seed's Tables 6-1, 6-2; SPEC `orient_parts`).

`orient_print_parts` orients the whole model and every labelled part on its own with
`orientation.orient` and returns a `PrintPlan`: one `PartRow` per part (faces,
area, `Orientation`), the whole model's row, the support of the parts together against
the whole's, and warnings.  `skin_side_up_direction` is the direction to favour so that
the skin-contact side of a bolus shell faces up (its surface stays smooth).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import BolusError
from .measures import check_part
from .orientation import Orientation, orient
from ..mesh.topology import MeshTopology, check_mesh, submesh

__all__ = ["PartRow", "PrintPlan", "skin_side_up_direction", "orient_print_parts", "orient_parts", "row_text"]


def skin_side_up_direction(V, F, topo: MeshTopology | None = None) -> np.ndarray:
    """The direction (3,) to favour so that the skin-contact side faces up: minus the
    area-weighted mean face normal (the skin side is the one the normals point away from).

    BolusError when the normals cancel out (a closed solid has no prevailing side).
    """
    topo = check_part(V, F, topo)
    n = (topo.face_normals * topo.areas[:, None]).sum(axis=0)
    if np.linalg.norm(n) < 1e-9 * topo.areas.sum():
        raise BolusError("the surface has no prevailing side (its normals cancel out); untick 'Skin side up'")
    return -n / np.linalg.norm(n)


@dataclass
class PartRow:
    """One row of the seed's Tables 6-1, 6-2: a part (or the whole model, part -1) in its best orientation."""

    name: str
    part: int
    faces: int
    area_mm2: float
    orientation: Orientation

    def as_dict(self) -> dict:
        o = self.orientation
        return {"part": self.name, "faces": self.faces, "area_mm2": self.area_mm2,
                "direction": [float(x) for x in o.direction], "WQ": o.WQ, "WU": o.WU,
                "support_volume_mm3": o.support_volume, "objective": o.objective}


@dataclass
class PrintPlan:
    """Result of `orient_print_parts`: the whole model's row (when asked) and one row per part."""

    whole: PartRow | None
    parts: list[PartRow]
    warnings: list[str]

    @property
    def parts_support_mm3(self) -> float:
        return float(sum(r.orientation.support_volume for r in self.parts))

    @property
    def support_ratio(self) -> float | None:
        """Support of the parts together over the whole model's (None without the whole or when it needs none)."""
        if self.whole is None or not self.whole.orientation.support_volume > 0:
            return None
        return self.parts_support_mm3 / self.whole.orientation.support_volume

    def rows(self) -> list[dict]:
        return [r.as_dict() for r in ([self.whole] if self.whole else []) + self.parts]

    def table(self, **settings) -> dict:
        """JSON-ready: the settings given (layer, ...), the rows, the parts' support and its ratio."""
        return {**settings, "rows": self.rows(), "parts_support_mm3": self.parts_support_mm3,
                "support_ratio": self.support_ratio}

    def support_text(self) -> str:
        """One line: the support of the parts together, and against the whole model's when known."""
        text = f"Support of the parts together: {self.parts_support_mm3:.1f} mm³"
        if self.support_ratio is None:
            return text
        whole = self.whole.orientation.support_volume
        return text + f" = {self.support_ratio * 100:.0f} % of the whole model's {whole:.1f} mm³"


def _part_labels(labels, m: int) -> np.ndarray:
    labels = np.asarray(labels)
    if labels.shape != (m,) or not np.issubdtype(labels.dtype, np.integer):
        raise BolusError(f"part labels must be one integer per triangle ({m}), got shape {labels.shape}")
    if not (labels >= 0).any():
        raise BolusError("no triangle belongs to a print part (every label is negative)")
    return labels.astype(np.int64)


def orient_print_parts(V, F, labels, *, whole: bool = True, skin_side_up: bool = False, progress=None,
                       topo: MeshTopology | None = None, **kwargs) -> PrintPlan:
    """`orient` the whole model (if ``whole``) and each part of ``labels`` on its own.

    Parameters: V (n,3) mm, F (m,3) int, labels (m,) int: the part of each triangle,
    negative for triangles in no part (part numbers need not be consecutive);
    ``skin_side_up``: favour `skin_side_up_direction` of the whole model for every
    part; kwargs go to `orient`.  Returns a `PrintPlan` (rows by increasing part number).
    """
    report = progress or (lambda f, t: None)
    topo = MeshTopology(*check_mesh(V, F, "the model", nondegenerate=False)) if topo is None else topo
    labels = _part_labels(labels, topo.m)
    if skin_side_up:
        kwargs["favour"] = skin_side_up_direction(topo.V, topo.F, topo)
    warnings: list[str] = []
    whole_row = None
    if whole:
        report(0.02, "whole model")
        whole_row = PartRow("whole", -1, topo.m, float(topo.areas.sum()), orient(topo.V, topo.F, topo=topo, **kwargs))
    ids = np.unique(labels[labels >= 0])
    rows = []
    for k, p in enumerate(ids):
        report(0.1 + 0.9 * k / len(ids), f"part {p}")
        Fl, vids = submesh(topo.F, labels == p)
        sub = MeshTopology(topo.V[vids], Fl)
        if not sub.areas.sum() > 0:
            raise BolusError(f"print part {p} has no area (all its faces are degenerate)")
        if len(Fl) < 4:
            warnings.append(f"print part {p} has only {len(Fl)} triangles: its orientation is of little use")
        o = orient(sub.V, Fl, topo=sub, **kwargs)
        rows.append(PartRow(f"part {p}", int(p), len(Fl), float(sub.areas.sum()), o))
    report(1.0, "done")
    return PrintPlan(whole_row, rows, warnings)


def orient_parts(V, F, labels, progress=None, **kwargs) -> list[Orientation]:
    """`orient` each part of ``labels`` (m,) int 0..p-1 on its own -> p Orientations; kwargs go to `orient`."""
    V, F = check_mesh(V, F, "the model", nondegenerate=False)
    labels = np.asarray(labels)
    if labels.shape != (len(F),) or not np.issubdtype(labels.dtype, np.integer) or (labels.size and labels.min() < 0):
        raise BolusError("part labels must be one non-negative integer per triangle")
    p = int(labels.max()) + 1 if labels.size else 0
    missing = np.setdiff1d(np.arange(p), labels)
    if len(missing):
        raise BolusError(f"part {missing[0]} has no faces; number the parts 0..{p - 1} without gaps")
    plan = orient_print_parts(V, F, labels, whole=False, progress=progress, **kwargs)
    return [r.orientation for r in plan.parts]


def row_text(r: dict) -> str:
    """One row of `PrintPlan.rows` as a line for the user (areas in cm², volumes in mm³)."""
    d = r["direction"]
    return (f"{r['part']}: {r['faces']} triangles, {r['area_mm2'] / 100:.1f} cm², build direction "
            f"({d[0]:+.3f}, {d[1]:+.3f}, {d[2]:+.3f}), WQ {r['WQ']:.1f} mm³, WU {r['WU']:.1f} mm³, "
            f"support {r['support_volume_mm3']:.1f} mm³")
