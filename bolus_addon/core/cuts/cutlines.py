"""Smooth cut lines between patches (seed 4.1.2, Figure 4-2, Table 4-2; 6.2.4, eq. 6-37).

`smooth_cuts` (V (n,3) mm, F (m,3), labels (m,)) replaces every zig-zag border between two patches by
a smooth curve on the surface, re-triangulating the faces it crosses (`SmoothCutResult`).  Modules:

- `borders`: the borders between two patches, ordered, their turning per mm;
- `curvefit`: the least-squares plane curves (eqs. 4-6..4-9, 6-37) and the signed distance to them;
- `mbo`: the smoothed path along the surface (the diffused patch indicator);
- `levelset_cut`: cutting the triangles along a level set phi = 0 (Figure 4-2 (b)), snapping,
  relabelling and the rules a cut must keep;
- `border_cut`: one border's candidate cuts, tried in order, and which is accepted;
- this module: the passes over all borders (up to `MAX_PASSES`, until one changes nothing), the
  report rows, and the checks of a region before cutting (`cut_region_check`).

Idempotent: run on its own result it changes nothing.  Input vertices keep their indices, new
ones are appended; ``vert_src`` / ``vert_weights`` (barycentric weights on an original triangle)
and ``face_parent`` let a caller interpolate any attribute onto the new geometry.

Design notes: docs/design/cuts.md.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .border_cut import ALREADY_SMOOTH, BorderReport, smooth_border
from .borders import Border, border_components, edge_keys, edge_samples, hausdorff_mm, turning_per_mm
from .curvefit import closed_curve_points, fit_closed_curve, fit_open_curve, project_to_plane, signed_distance_closed
from ..errors import BolusError
from .levelset_cut import SNAP, CutState
from ..analysis.saliency import analyse
from ..analysis.spectral import patch_stats
from ..mesh.topology import MeshTopology, check_mesh, submesh

__all__ = [
    "Border",
    "BorderReport",
    "SmoothCutResult",
    "border_components",
    "turning_per_mm",
    "project_to_plane",
    "fit_open_curve",
    "fit_closed_curve",
    "closed_curve_points",
    "signed_distance_closed",
    "smooth_cuts",
    "cut_region_check",
    "patch_table",
    "ALREADY_SMOOTH",
    "SNAP",
]

MAX_PASSES = 6  #: passes over all borders until one changes nothing (the repro meshes need at most four)
FIRST_PASS_SHARE = 0.75  #: progress: the first pass does nearly all the work, later ones share the next 20 %
LATER_PASSES_SHARE = 0.2
TRACK_SAMPLES = 5  #: points per edge when matching a later pass's border to the input border it comes from
MATCH_SAMPLES = 3  #: points per edge of the border being matched


@dataclass
class SmoothCutResult:
    """Output of `smooth_cuts` on an input with n vertices and m triangles."""

    V: np.ndarray  #: (n',3), the first n rows are the input vertices
    F: np.ndarray  #: (m',3)
    labels: np.ndarray  #: (m',) patch of each face (negative = in no patch, as in the input)
    face_parent: np.ndarray  #: (m',) input triangle each face lies in
    face_unchanged: np.ndarray  #: (m',) bool, the face is its input triangle as it was
    vert_src: np.ndarray  #: (n',3) input vertices that each vertex is a combination of
    vert_weights: np.ndarray  #: (n',3) the barycentric weights (V = sum w * V_in[src])
    vert_parent: np.ndarray  #: (n',) input triangle a new vertex lies in (-1 for input vertices)
    split: np.ndarray  #: (m,) bool, input triangles replaced by smaller ones
    borders: list[BorderReport] = field(default_factory=list)

    @property
    def new_vertex_count(self) -> int:
        return int((self.vert_parent >= 0).sum())

    @property
    def changed(self) -> bool:
        return any(b.method != "unchanged" for b in self.borders)


# ------------------------------------------------------------- checks
def _nothing_to_smooth(topo: MeshTopology, labels: np.ndarray) -> str | None:
    """Why there is no border to smooth ('there is only one patch', ...), or None."""
    if len(np.unique(labels[labels >= 0])) < 2:
        return "there is only one patch"
    P = topo.face_adjacency_pairs
    la, lb = labels[P[:, 0]], labels[P[:, 1]]
    if not ((la != lb) & (la >= 0) & (lb >= 0)).any():
        return "the patches do not share any border"
    return None


def cut_region_check(V, F, labels, vert_ids=None) -> tuple[list[str], str | None]:
    """The checks before cutting a region, on the faces in a patch only.

    Parameters
    ----------
    V : (n,3) mm; F : (m,3); labels : (m,) patch of each face (negative: in no patch;
    those faces are not checked); vert_ids : optional (n,) the user's vertex indices,
    used in messages.

    Returns
    -------
    (warnings, why): the warnings to show and, when there is nothing to smooth, why
    ('there is only one patch' or 'the patches do not share any border'), else None.
    Raises `BolusError` for zero-area triangles, non-manifold edges or bow-tie vertices
    among the patch faces (`MeshTopology.surface_warnings`).
    """
    V, F = check_mesh(V, F, "the region", nondegenerate=False)
    labels = np.asarray(labels)
    inside = labels >= 0
    Fl, ids = submesh(F, inside)
    topo = MeshTopology(V[ids], Fl)
    warnings = topo.surface_warnings(False, "the region", None if vert_ids is None else np.asarray(vert_ids)[ids])
    return warnings, _nothing_to_smooth(topo, labels[inside])


def patch_table(V, F, labels, smoothing_mm: float) -> list[dict]:
    """Table 4-1 rows (`spectral.patch_stats` as dicts) of the faces in a patch (labels >= 0).

    V (n,3) mm, F (m,3), labels (m,); angle sums on the copy smoothed over
    ``smoothing_mm`` (0: the raw mesh), areas on V.
    """
    labels = np.asarray(labels)
    inside = labels >= 0
    Fi = np.asarray(F)[inside]
    Va = analyse(V, Fi, smoothing_mm).V_analysis if smoothing_mm > 0 else V
    return [p.as_dict() for p in patch_stats(Va, Fi, labels[inside], V)]


# ------------------------------------------------------------- entry point
def smooth_cuts(V, F, labels, snap: float = SNAP, progress=None) -> SmoothCutResult:
    """Replace the patch borders by smooth cut curves (module doc, seed 4.1.2).

    Parameters
    ----------
    V : (n,3) mm.  F : (m,3) a manifold triangle mesh.
    labels : (m,) int patch of each face (negative: in no patch; those faces are never
        split or relabelled, and may be degenerate).
    snap : fraction of an edge within which a cut point moves onto the edge's end, [0, 0.5).
    progress : optional callable (fraction, text).

    Returns
    -------
    `SmoothCutResult`; the input arrays are not modified.  With nothing to change (every
    border already smooth, too short or impossible to smooth) the result is the input,
    every border 'unchanged' with its reason in ``note``, and ``result.changed`` is
    False; calling it again on its own result changes nothing.

    Raises `BolusError` naming the problem and where for NaN/inf coordinates, bad
    indices, non-manifold edges or zero-area triangles in a patch, and when there is
    nothing to smooth at all (fewer than two patches, no common border).
    """
    V, F = check_mesh(V, F, "the mesh", nondegenerate=False, manifold=True)
    labels = np.asarray(labels, dtype=np.int64).copy()
    if labels.shape != (len(F),):
        raise BolusError(f"labels must give one patch per triangle ({len(F)}), got shape {labels.shape}")
    if not 0.0 <= snap < 0.5:
        raise BolusError(f"snap must be in [0, 0.5), got {snap}")
    topo = MeshTopology(V, F)
    why = _nothing_to_smooth(topo, labels)
    if why:
        hint = " (run Segment into Patches with 2 or more patches first)" if "one patch" in why else ""
        raise BolusError(f"{why}: nothing to smooth{hint}")
    _require_nondegenerate_patches(topo, labels)
    st = CutState.start(V, F, labels)
    report = progress or (lambda f, t: None)
    tracks: list[_Track] = []
    memo: dict = {"seen": {}, "version": {}}
    for pass_no in range(MAX_PASSES):
        lo, hi = _progress_span(pass_no)
        st, changed = _one_pass(st, snap, tracks, pass_no, memo, lambda f, t: report(lo + (hi - lo) * f, t))
        if not changed:
            break
    _final_measures(st, tracks)
    split = np.ones(len(F), dtype=bool)
    split[st.parent[st.unchanged]] = False
    report(1.0, "done")
    return SmoothCutResult(st.V, st.F, st.labels, st.parent, st.unchanged, st.vsrc, st.vw, st.vparent, split,
                           [tr.report for tr in tracks])


def _require_nondegenerate_patches(topo: MeshTopology, labels: np.ndarray) -> None:
    """BolusError naming the first zero-area triangle in a patch (it has no side of a cut)."""
    bad = np.nonzero(topo.degenerate_faces() & (labels >= 0))[0]
    if len(bad):
        f = int(bad[0])
        i, j, k = (int(x) for x in topo.F[f])
        raise BolusError(f"the patches have {len(bad)} zero-area triangle(s), e.g. triangle {f} (vertices {i}, {j}, "
                         f"{k}): coincident or collinear vertices; merge them first (Mesh > Clean Up > Merge by "
                         "Distance, then Degenerate Dissolve)")


def _progress_span(pass_no: int) -> tuple[float, float]:
    """(lo, hi) share of the progress bar for a pass: the first takes FIRST_PASS_SHARE, each later half the rest."""
    if pass_no == 0:
        return 0.0, FIRST_PASS_SHARE
    return (FIRST_PASS_SHARE + LATER_PASSES_SHARE * (1 - 0.5 ** (pass_no - 1)),
            FIRST_PASS_SHARE + LATER_PASSES_SHARE * (1 - 0.5**pass_no))


# ------------------------------------------------------------- passes
@dataclass
class _Track:
    """One border of the input, followed through the passes (one report row)."""

    report: BorderReport
    edges: np.ndarray  #: (k,2) its edges in the input (input vertices never move)
    samples: np.ndarray  #: (s,3) points along them
    changed: bool = False
    first: tuple[str, str] = ("unchanged", "")  #: (method, note) of the first pass


def _nearest_track(tracks: list[_Track], border: Border, V: np.ndarray) -> _Track | None:
    """The input border of the same pair that this border of a later pass lies nearest to."""
    best, best_d = None, np.inf
    pts = edge_samples(border.edges, V, MATCH_SAMPLES)
    for tr in tracks:
        if (tr.report.a, tr.report.b) != (border.a, border.b):
            continue
        dist = float(np.median(cKDTree(tr.samples).query(pts)[0]))
        if dist < best_d:
            best, best_d = tr, dist
    return best


def _pair_borders(st: CutState, a: int, b: int) -> list[Border]:
    """`border_components` of the pair a|b only (computed on the faces of a and b)."""
    ab = (st.labels == a) | (st.labels == b)
    return border_components(MeshTopology(st.V, st.F[ab]), st.labels[ab])


def _one_pass(st: CutState, snap: float, tracks: list[_Track], pass_no: int, memo: dict,
              report) -> tuple[CutState, bool]:
    """Smooth every border of the current mesh once; returns (state, whether a cut was made).

    The first pass creates one `_Track` per border; later passes update the track each
    border descends from.  A border left unchanged before is not tried again while its
    two patches have not changed since (memo: 'seen' (a, b, edges) -> patch versions then,
    'version' patch -> number of cuts that changed it): what `smooth_border` decides
    depends on those two patches only, so it would decide the same again.
    """
    seen, version = memo["seen"], memo["version"]
    borders = border_components(MeshTopology(st.V, st.F), st.labels)
    done, total, changed = 0, len(borders), False
    last = None
    for a, b in sorted({(bd.a, bd.b) for bd in borders}):
        fresh = _pair_borders(st, a, b)  # this pair's borders now (earlier cuts may have moved junctions)
        for bd in list(fresh):
            text = f"cut between patches {a} and {b}" + (f" (pass {pass_no + 1})" if pass_no else "")
            report(done / max(total, 1), text)
            if last is not None and last.method != "unchanged" and (last.a, last.b) == (a, b):
                fresh = _pair_borders(st, a, b)  # the last cut moved things
            # the same border on the current mesh (other pairs' cuts never touch an a|b edge)
            match = [x for x in fresh if len(np.intersect1d(edge_keys(x.edges), edge_keys(bd.edges)))]
            if not match:
                continue
            key = (a, b, np.sort(edge_keys(match[0].edges)).tobytes())
            now = (version.get(a, 0), version.get(b, 0))
            done += 1
            if seen.get(key) == now:
                continue
            tr = (_Track(None, match[0].edges.copy(), edge_samples(match[0].edges, st.V, TRACK_SAMPLES))
                  if pass_no == 0 else _nearest_track(tracks, match[0], st.V))
            st, rep = smooth_border(st, match[0], fresh, snap)
            last = rep
            cut = rep.method != "unchanged"
            changed |= cut
            if cut:
                version[a], version[b] = now[0] + 1, now[1] + 1
            else:
                seen[key] = now
            _record(tracks, tr, rep, cut, pass_no, match[0], st.V)
    return st, changed


def _record(tracks: list[_Track], tr: _Track | None, rep: BorderReport, cut: bool, pass_no: int, border: Border,
            V: np.ndarray) -> None:
    """Put one border's outcome of a pass on its track (first pass: a new track)."""
    if pass_no == 0:
        tr.report, tr.changed, tr.first = rep, cut, (rep.method, rep.note)
        tracks.append(tr)
    elif cut and tr is None:  # a border no input border led to: a row of its own
        tracks.append(_Track(rep, border.edges.copy(), edge_samples(border.edges, V, TRACK_SAMPLES), True))
    elif cut:
        prev = tr.report
        method0, note0 = tr.first
        how = (f"{method0} first, then {rep.method} where the other cuts had moved its ends"
               if method0 != "unchanged" else f"{rep.method} once the other cuts had moved its ends")
        rep.note = "; ".join(x for x in ((note0 if method0 != "unchanged" else ""), how) if x)
        rep.turning_before, rep.length_before_mm = prev.turning_before, prev.length_before_mm
        rep.border_vertices = prev.border_vertices
        tr.report, tr.changed = rep, True


def _final_measures(st: CutState, tracks: list[_Track]) -> None:
    """Turning, length and shift of each track's border on the final mesh (the whole border, ends included)."""
    topo = MeshTopology(st.V, st.F)
    owned: dict[int, list[np.ndarray]] = {}
    for bd in border_components(topo, st.labels):
        tr = _nearest_track(tracks, bd, st.V)
        if tr is not None:
            owned.setdefault(id(tr), []).append(bd.edges)
    for tr in tracks:
        if id(tr) not in owned:
            continue
        E = np.vstack(owned[id(tr)])
        if len(E) == len(tr.edges) and np.array_equal(np.sort(edge_keys(E)), np.sort(edge_keys(tr.edges))):
            continue  # untouched
        rep = tr.report
        rep.turning_after, rep.length_after_mm = turning_per_mm(st.V, E, topo.vertex_normals)
        rep.max_shift_mm = hausdorff_mm(tr.edges, st.V, E, st.V)
