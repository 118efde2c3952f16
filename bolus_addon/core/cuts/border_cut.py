"""One border's smooth cut: the candidate cuts, tried in order, and the rules that accept one (seed 4.1.2).

`smooth_border` (a `levelset_cut.CutState`: V mm, F, labels; a `borders.Border` between patches a
and b) returns the new state and a `BorderReport`.  The first candidate:

1. the border's vertices P (k,3) in order;
2. a plane Gamma through the centroid of P, normal d = the area-weighted mean normal of the faces
   around the border (the least-squares tangent plane there);
3. P projected on Gamma (eqs. 4-6..4-9) in in-plane axes (`curvefit.plane_axes`);
4. a least-squares curve l in Gamma (eq. 6-37, `curvefit`): a line or parabola for an open
   border, an elliptic Fourier curve (order 1: the seed's ellipse) for a closed one;
5. the surface through l perpendicular to Gamma, the zero set of phi (the signed offset of a
   point's projection from l), cut into a band of radius R around the border (`levelset_cut.cut_band`).

Where that fails (`STEEP_AREA`, `STRAY_EDGES`, `MIN_GAIN`, `MIN_SHIFT`, `SMOOTH_ENOUGH`) a
planar section is tried, then a smoothed path along the surface (`mbo`, `MBO_SIGMA_EDGES`); a border
that still cannot be smoothed, or is already smooth (`ON_CURVE`), is left as it is, the report says why.

Design notes: docs/design/cuts.md.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .borders import Border, hausdorff_mm, turning_per_mm
from .curvefit import (
    closed_curve_points,
    dist_to_polygon,
    fit_closed_curve,
    fit_open_curve,
    plane_axes,
    project_to_plane,
    signed_distance_closed,
)
from ..errors import BolusError
from .levelset_cut import CutFailed, CutState, band_faces, check_cut, cut_band
from .mbo import diffused_indicator
from ..mesh.topology import MeshTopology

__all__ = ["BorderReport", "smooth_border", "ALREADY_SMOOTH"]

HEIGHT_FIELD_COS = 0.2  #: faces around the border must satisfy n.d >= this (about 78 degrees)
STEEP_AREA = 0.02  #: share of the area around the border allowed to face away (scanner noise tilts single triangles)
NORMAL_BAND_EDGES = 2.0  #: the mean normal d is taken over the faces within this many mean edges of the border
ON_CURVE = 0.1  #: border vertices within this fraction of the mean edge of their fitted curve: already that curve
STRAY_EDGES, STRAY_FRACTION = 3.0, 0.15  #: a cut may move the border max(3 h, 15 % of its length), no more
BAND_EDGES = 3.0  #: the band cut into reaches at least this many mean edges from the border ...
BAND_DEV, BAND_MARGIN_EDGES = 2.0, 2.0  #: ... and twice the fit's deviation plus two edges
BAND_GROWTH = (1.0, 2.0)  #: a cut leaving its band is tried again in a band twice as wide
ARC_PLANARITY = 0.2  #: an open border spans its own plane (an arc) when sv2 >= 0.2 sv1
ACROSS_COS = 0.5  #: a plane section crosses the surface when |its normal . d| < 0.5 (60 degrees)
MBO_SIGMA_EDGES = (2.0, 3.5, 6.0)  #: diffusion lengths tried, in mean border edges
MBO_BAND_SIGMAS = 4.0  #: a smoothed path's band: 4 sigma (+ BAND_MARGIN_EDGES) around the border
MBO_REACH_SIGMAS = 6.0  #: the diffusion runs on the faces within 2 R + 6 sigma of the border
SMOOTH_ENOUGH = 0.3  #: a cut is accepted at once when it turns <= 30 % of the border
MIN_GAIN = 0.25  #: a cut must turn at most (1 - MIN_GAIN) of the border to be worth making
MIN_SHIFT = 0.1  #: a cut moving the border less than this fraction of its mean edge is the same border
NOT_SMOOTHER = "the cut would not be measurably smoother than the border"
NEGLIGIBLE = "the cut would move the border less than a tenth of an edge"
ALREADY_SMOOTH = "already smooth"
TOO_SHORT = "too short to fit a curve (a single edge); left as it is"
SMOOTHED_PATH = "smoothed path"


@dataclass
class BorderReport:
    """What happened to one border (a row of the operator's cut table)."""

    a: int
    b: int
    closed: bool
    #: 'line', 'parabola', 'ellipse', 'closed curve (order K)', 'plane section', 'smoothed path', 'unchanged'
    method: str
    border_vertices: int
    length_before_mm: float
    length_after_mm: float
    turning_before: float  #: rad/mm, geodesic (tangent-plane) turning, see `turning_per_mm`
    turning_after: float
    max_shift_mm: float  #: largest distance of the new cut from the old border
    fit_rms_mm: float = 0.0
    note: str = ""

    def as_dict(self) -> dict:
        return dict(self.__dict__)

    @property
    def shortfall(self) -> bool:
        """Left as it is although it is not a smooth cut already (the user is warned)."""
        return self.method == "unchanged" and not self.note.startswith(ALREADY_SMOOTH)


@dataclass
class _Attempt:
    """A candidate cut: phi (a function of points; for a smoothed path its sigma in mm)."""

    name: str
    phi: Callable | float
    linear: bool  #: phi is linear along straight lines (a plane): crossings are interpolated
    R: float  #: band radius, mm
    rms: float  #: fit residual, mm


@dataclass
class _Cut:
    state: CutState
    name: str
    length: float
    turning: float
    shift: float
    rms: float


def smooth_border(st: CutState, border: Border, all_borders: list[Border],
                  snap: float) -> tuple[CutState, BorderReport]:
    """Smooth one border (module doc); returns (new state, report).  The state is unchanged if the border is."""
    topo = MeshTopology(st.V, st.F)
    turn0, len0 = turning_per_mm(st.V, border.edges, topo.vertex_normals)
    nverts = len(np.unique(border.edges))
    report = BorderReport(border.a, border.b, border.closed, "unchanged", nverts, len0, len0, turn0, turn0, 0.0)
    if nverts < 3:
        report.note = TOO_SHORT
        return st, report
    h = float(np.linalg.norm(st.V[border.edges[:, 0]] - st.V[border.edges[:, 1]], axis=1).mean())
    limit = max(STRAY_EDGES * h, STRAY_FRACTION * len0)
    d, height_field = _border_normal(st, topo, border, all_borders, h)
    attempts, reasons, smooth_note = _candidates(st, border, d, height_field, h, limit)
    if smooth_note:
        report.note = smooth_note
        return st, report
    return _try_candidates(st, topo, border, all_borders, snap, attempts, reasons, report, h, limit)


def _border_normal(st: CutState, topo: MeshTopology, border: Border, all_borders: list[Border], h: float):
    """(d, height_field): the unit area-weighted mean normal around the border (None if it
    cancels out) and whether the surface there is a height field over the plane normal to d."""
    near = band_faces(st, topo, border, all_borders, NORMAL_BAND_EDGES * h)
    normals = topo.face_normals[near]
    d = (normals * topo.areas[near, None]).sum(axis=0)
    dn = np.linalg.norm(d)
    if dn == 0:
        return None, False
    steep = topo.areas[near][(normals @ (d / dn)) < HEIGHT_FIELD_COS].sum()
    return d / dn, bool(steep <= STEEP_AREA * topo.areas[near].sum())


def _band_radius(dev: float, h: float) -> float:
    return max(BAND_EDGES * h, BAND_DEV * dev + BAND_MARGIN_EDGES * h)


def _candidates(st: CutState, border: Border, d, height_field: bool, h: float, limit: float):
    """(attempts, reasons, note): the cuts to try in order, why others were not, or an 'already smooth' note."""
    attempts: list[_Attempt] = []
    reasons: list[str] = []
    if border.order is None:
        reasons.append("the border branches")
    elif height_field:
        att, why, note = _plane_curve(st, border, d, h, limit)
        if note:
            return [], [], note
        attempts += [att] if att else []
        reasons += [why] if why else []
    else:
        reasons.append("the surface folds too much around the border for a plane projection")
    if border.order is not None and not height_field:
        more, why, note = _plane_sections(st, border, d, h, limit)
        if note:
            return [], [], note
        attempts += more
        reasons += why
    for sigma_edges in MBO_SIGMA_EDGES:
        sigma = sigma_edges * h
        attempts.append(_Attempt(SMOOTHED_PATH, sigma, True, MBO_BAND_SIGMAS * sigma + BAND_MARGIN_EDGES * h, 0.0))
    return attempts, reasons, None


def _plane_curve(st: CutState, border: Border, d: np.ndarray, h: float, limit: float):
    """(attempt | None, reason | None, note | None) for the curve fitted in the tangent plane (steps 2-5)."""
    P = st.V[border.order]
    Pg = project_to_plane(P, d, P.mean(axis=0))  # eqs. 4-6..4-9
    c, e1, e2 = plane_axes(Pg, d)
    x, y = (Pg - c) @ e1, (Pg - c) @ e2
    try:
        if border.closed:
            coef, K, rms = fit_closed_curve(np.stack([x, y], 1), h)
            dev = float(dist_to_polygon(np.stack([x, y], 1), closed_curve_points(coef)).max())
            name = "ellipse" if K == 1 else f"closed curve (order {K})"

            def phi_fn(Q, c=c, e1=e1, e2=e2, coef=coef):
                R_ = Q - c
                return signed_distance_closed(np.stack([R_ @ e1, R_ @ e2], 1), coef)

        else:
            coef, order, rms = fit_open_curve(x, y, h)
            dev = float(np.abs(np.polyval(coef, x) - y).max())
            name = "line" if order == 1 else "parabola"

            def phi_fn(Q, c=c, e1=e1, e2=e2, coef=coef):
                R_ = Q - c
                return R_ @ e2 - np.polyval(coef, R_ @ e1)

    except BolusError as exc:
        return None, str(exc), None
    if dev <= ON_CURVE * h:  # a cut we made before: cutting again would only add vertices
        return None, None, f"{ALREADY_SMOOTH} (its vertices lie on a {name} within {dev:.2g} mm)"
    if dev > limit:
        return None, f"the fitted {name} strays {dev:.1f} mm from the border", None
    return _Attempt(name, phi_fn, False, _band_radius(dev, h), rms), None, None


def _plane_sections(st: CutState, border: Border, d, h: float, limit: float):
    """(attempts, reasons, note | None) for plane sections: the least-squares plane of the
    border (a loop around a limb, an arc) and, for an open border, the plane through its
    principal line and the mean surface normal (a normal section: close to the shortest
    path across)."""
    P = st.V[border.order]
    c = P.mean(axis=0)
    _, sv, Vt = np.linalg.svd(P - c, full_matrices=False)
    planes = [Vt[2]] if (border.closed or sv[1] >= ARC_PLANARITY * sv[0]) else []
    if not border.closed and d is not None:
        ns = np.cross(Vt[0], d)
        if np.linalg.norm(ns) > 1e-6:  # the border's line is not along the normal (unit vectors)
            planes.append(ns / np.linalg.norm(ns))
    attempts, reasons = [], []
    for nrm in planes:
        dev = float(np.abs((P - c) @ nrm).max())
        across = d is not None and abs(float(nrm @ d)) < ACROSS_COS  # the plane crosses the surface
        if dev <= ON_CURVE * h and across:
            return [], [], f"{ALREADY_SMOOTH} (its vertices lie on a plane section within {dev:.2g} mm)"
        if dev <= limit:
            rms_p = float(np.sqrt(np.mean(((P - c) @ nrm) ** 2)))
            attempts.append(_Attempt("plane section", lambda Q, c=c, nrm=nrm: (Q - c) @ nrm, True,
                                     _band_radius(dev, h), rms_p))
        else:
            reasons.append(f"the border is {dev:.1f} mm away from a plane")
    return attempts, reasons, None


def _try_candidates(st, topo, border, all_borders, snap, attempts, reasons, report, h, limit):
    """Cut with each attempt in turn (each in a band, then a band twice as wide); accept the
    first that turns <= SMOOTH_ENOUGH of the border, else the smoothest valid one."""
    turn0 = report.turning_before
    fallback = None  # the smoothest cut that is valid but not yet smooth enough
    same = False  # a valid cut was found, but it is not measurably smoother than the border
    for att in attempts:
        phi = att.phi
        if att.name == SMOOTHED_PATH:  # phi given at the vertices, near the border only
            phi = diffused_indicator(st.V, st.F, st.labels, border.a, border.b, att.phi, border.edges,
                                     2.0 * att.R + MBO_REACH_SIGMAS * att.phi)
        for grow in BAND_GROWTH:
            cut, why, no_gain = _cut_once(st, topo, border, all_borders, att, phi, att.R * grow, snap, turn0, h, limit)
            same |= no_gain
            if cut is None:
                reasons.append(f"{att.name}: {why}")
                continue
            if cut.turning > SMOOTH_ENOUGH * turn0:
                if fallback is None or cut.turning < fallback.turning:
                    fallback = cut
                reasons.append(f"{att.name}: turns {cut.turning / turn0:.0%} of the border")
                break
            return _accept(report, cut, reasons)
    if fallback is not None:
        return _accept(report, fallback, reasons)
    report.note = "left as it is: " + "; ".join(dict.fromkeys(reasons))
    if same:
        report.note = f"{ALREADY_SMOOTH} (no cut we can fit is measurably smoother)"
    return st, report


def _cut_once(st, topo, border, all_borders, att: _Attempt, phi, R: float, snap: float, turn0: float, h: float,
              limit: float) -> tuple[_Cut | None, str, bool]:
    """(cut, why not, not measurably smoother): one cut in a band of radius R, checked by the rules."""
    band = band_faces(st, topo, border, all_borders, R)
    try:
        new_st, phi_v, from_face = cut_band(st, topo, band, border.a, border.b, phi, att.linear, snap)
        cut_edges, new_topo = check_cut(new_st, phi_v, border.a, border.b, band[from_face])
    except CutFailed as exc:
        return None, str(exc), False
    turn1, len1 = turning_per_mm(new_st.V, cut_edges, new_topo.vertex_normals)
    shift = hausdorff_mm(border.edges, st.V, cut_edges, new_st.V)
    if shift > limit:
        return None, f"the cut would move {shift:.1f} mm from the border", False
    if turn1 >= turn0 or turn1 > (1.0 - MIN_GAIN) * turn0:
        return None, NOT_SMOOTHER, True
    if shift < MIN_SHIFT * h:
        return None, NEGLIGIBLE, True
    return _Cut(new_st, att.name, len1, turn1, shift, att.rms), "", False


def _accept(report: BorderReport, cut: _Cut, reasons: list[str]) -> tuple[CutState, BorderReport]:
    report.method = cut.name
    report.length_after_mm = cut.length
    report.turning_after = cut.turning
    report.max_shift_mm = cut.shift
    report.fit_rms_mm = cut.rms
    if reasons:
        lead = "fell back to a smoothed path along the surface: " if cut.name == SMOOTHED_PATH else ""
        report.note = lead + "; ".join(dict.fromkeys(reasons))
    return cut.state, report
