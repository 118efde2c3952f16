"""The treatment area around a point: `treatment_area` (SPEC `select_area`).

For V (n,3) mm, F (m,3), a centre (3,) mm and a radius (mm):

1. p, the surface point nearest to the centre (`geodesic.closest_point_on_mesh`); refused when the
   centre is farther from the surface than ``max_cursor_mm`` (default: the radius);
2. d, the distance along the surface from p (`geodesic.geodesic_distance`);
3. the border: the level line d = radius, cut through the faces (`levelset_cut.cut_band`);
4. cavities (``exclude_cavities``): faces whose openness (`visibility`) is below
   ``openness_threshold`` (`OPENNESS_THRESHOLD`) are left out, the area cut a second time along
   the level line openness = threshold (`cavity_faces`);
5. the selected area: the faces inside both cuts that are edge-connected to p.

The `Area` keeps the map back to the input (as `levelset_cut.CutState`): the parent triangle of
each face and barycentric weights of each vertex, so a writer can interpolate every attribute
(`mesh_cuts.apply_cuts` reads the same field names as a `cutlines.SmoothCutResult`).

Design notes: docs/design/cuts.md.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..mesh.boundary import boundary_loops
from ..errors import BolusError
from ..mesh.geodesic import barycentric, closest_point_on_mesh, geodesic_distance
from .levelset_cut import CutFailed, CutState, cut_band
from ..mesh.topology import MeshTopology, as_mesh_arrays, check_mesh, face_areas, submesh
from .visibility import DEFAULT_DIRECTIONS, openness

__all__ = ["Area", "treatment_area", "cavity_faces", "geodesic_distance", "OPENNESS_THRESHOLD"]

#: faces less open than this (fraction of the sky above them they can see) are cavity faces
OPENNESS_THRESHOLD = 0.2
#: the back side is taken as the outside when its mean openness exceeds the front's by this much
FLIP_MARGIN = 0.25
#: faces up to this many radii along the surface may hide a face of the area
OCCLUDER_REACH = 1.5

_IN, _OUT, _FAR = 0, 1, 2  # face classes during the cuts


@dataclass
class Area:
    """A treatment area cut into an input mesh of n vertices and m triangles."""

    V: np.ndarray  #: (n',3) mm, the first n rows are the input vertices
    F: np.ndarray  #: (m',3) triangles (every input triangle not crossed by a cut is kept)
    selected: np.ndarray  #: (m',) bool the area's faces
    parent: np.ndarray  #: (m',) input triangle each face lies in
    vsrc: np.ndarray  #: (n',3) input vertices each vertex is a combination of
    vw: np.ndarray  #: (n',3) barycentric weights (V' = sum vw * V[vsrc])
    vert_parent: np.ndarray  #: (n',) input triangle a new vertex lies in, -1 for input vertices
    split: np.ndarray  #: (m,) bool input triangles replaced by smaller ones
    cavity: np.ndarray  #: (m',) bool faces within the radius left out as cavity
    distance: np.ndarray  #: (n',) mm along the surface from the source point (inf beyond the reach)
    source_point: np.ndarray  #: (3,) the surface point nearest the centre
    source_face: int  #: its input triangle
    centre_distance_mm: float  #: how far the centre was from the surface
    area_mm2: float
    cavity_area_mm2: float
    holes: int  #: border loops of the area other than its outer one
    warnings: list[str] = field(default_factory=list)

    @property
    def cavity_fraction(self) -> float:
        """Cavity area over the area within the radius (selected + cavity)."""
        tot = self.area_mm2 + self.cavity_area_mm2
        return self.cavity_area_mm2 / tot if tot > 0 else 0.0

    # the names `mesh_cuts.apply_cuts` reads (those of cutlines.SmoothCutResult)
    @property
    def labels(self) -> np.ndarray:
        return self.selected.astype(np.int64)

    @property
    def face_parent(self) -> np.ndarray:
        return self.parent

    @property
    def vert_src(self) -> np.ndarray:
        return self.vsrc

    @property
    def vert_weights(self) -> np.ndarray:
        return self.vw


def _on_new_vertices(st: CutState, values: np.ndarray) -> np.ndarray:
    """Values (n,) at the input vertices, interpolated at the vertices of st (n',); inf stays inf."""
    return (np.where(st.vw > 0, values[st.vsrc], 0.0) * st.vw).sum(axis=1)


def _cut(st: CutState, band: np.ndarray, phi: np.ndarray, what: str) -> CutState:
    """st cut along phi = 0 in the band faces (labels _IN / _OUT there), relabelled by side."""
    bv = np.unique(st.F[band])
    if not len(bv) or not ((phi[bv] < 0).any() and (phi[bv] > 0).any()):
        return st
    try:
        st2, _, _ = cut_band(st, MeshTopology(st.V, st.F), band, _IN, _OUT, phi, linear=True)
    except CutFailed as exc:  # pragma: no cover - the band is every face the line can cross
        raise BolusError(f"the {what} could not be cut through the faces ({exc}); try another radius") from None
    return st2


def cavity_faces(V, F, faces=None, *, threshold: float = OPENNESS_THRESHOLD, directions: int = DEFAULT_DIRECTIONS,
                 progress=None) -> np.ndarray:
    """(m,) bool: faces (of ``faces``, default all) less open than ``threshold`` on the outer side.

    V (n,3) mm, F (m,3): the surface (all of it may hide a face).  The outer side is the
    normals' side unless the back is much more open (`_outer_openness`, `visibility.openness`)."""
    V, F = check_mesh(V, F, "the surface")
    faces = np.arange(len(F)) if faces is None else np.asarray(faces, dtype=np.int64)
    o, _ = _outer_openness(V, F, faces, directions, progress)
    out = np.zeros(len(F), dtype=bool)
    out[faces] = o < threshold
    return out


def _outer_openness(V, F, faces, directions, progress) -> tuple[np.ndarray, bool]:
    """(openness (k,) of ``faces`` on the outer side, flipped).

    The outer side is the side of the normals (right-hand winding; the project's
    convention: skin normals point away from the body), unless the other side is more
    open by more than FLIP_MARGIN on the area-weighted mean (a mesh wound inside out,
    e.g. a closed head whose normals point inward): then that side, and flipped=True."""
    front, back = openness(V, F, faces, directions=directions, progress=progress)
    A = face_areas(V, F[faces])
    tot = max(float(A.sum()), 1e-300)
    if (A @ back - A @ front) / tot > FLIP_MARGIN:
        return back, True
    return front, False


def _vertex_openness(V, F, faces, o_face) -> np.ndarray:
    """Openness (n,) at the vertices: area-weighted mean of the measured faces around each
    (1 where none), averaged once more over the faces (a light smoothing of the sampling noise)."""
    n = len(V)
    A = face_areas(V, F[faces])

    def to_vertices(vals):
        num = np.bincount(F[faces].ravel(), weights=np.repeat(A * vals, 3), minlength=n)
        den = np.bincount(F[faces].ravel(), weights=np.repeat(A, 3), minlength=n)
        return np.where(den > 0, num / np.maximum(den, 1e-300), 1.0)

    ov = to_vertices(o_face)
    return to_vertices(ov[F[faces]].mean(axis=1))


def treatment_area(V, F, centre, radius_mm: float = 45.0, exclude_cavities: bool = True, progress=None, *,
                   openness_threshold: float = OPENNESS_THRESHOLD, directions: int = DEFAULT_DIRECTIONS,
                   max_cursor_mm: float | None = None) -> Area:
    """The area within ``radius_mm`` along the surface of the surface point nearest ``centre``.

    Parameters
    ----------
    V : (n,3) mm; F : (m,3) the surface (refused: NaN/inf anywhere; zero-area triangles
    and non-manifold edges within reach of the area, farther ones do not matter);
    centre : (3,) mm; radius_mm > 0;
    exclude_cavities : leave out faces less open than ``openness_threshold``;
    max_cursor_mm : the farthest the centre may be from the surface (default radius_mm);
    progress : callable(fraction, text) or None.

    Returns an `Area`.  Raises `BolusError` (nothing computed) for a bad radius, a
    centre too far from the surface, or an area of no faces.
    """
    radius = float(radius_mm)
    if not np.isfinite(radius) or radius <= 0:
        raise BolusError(f"the radius must be a positive number of millimetres, got {radius_mm}")
    c = np.asarray(centre, dtype=np.float64).reshape(-1)
    if c.shape != (3,) or not np.isfinite(c).all():
        raise BolusError(f"the centre must be a finite 3D point, got {centre}")
    V, F = as_mesh_arrays(V, F)  # shapes, indices, NaN/inf anywhere
    if len(F) == 0:
        raise BolusError("the surface has no triangles")
    report = progress if progress is not None else (lambda f, t: None)
    report(0.0, "nearest surface point")
    p, f0, how_far = closest_point_on_mesh(V, F, c)
    limit = radius if max_cursor_mm is None else float(max_cursor_mm)
    if how_far > limit:
        raise BolusError(
            f"the centre (3D cursor) is {how_far:.1f} mm from the nearest point of the surface, farther than "
            f"{limit:g} mm: place the cursor on the skin (Shift+right-click on the surface) and try again")
    report(0.05, "distance along the surface")
    d = _distance_near(V, F, p, f0, radius, OCCLUDER_REACH * radius if exclude_cavities else radius)
    # 1. the outer border: d = radius
    finite = np.isfinite(d)
    dom = finite[F].all(axis=1)
    phi1 = np.where(finite, d - radius, 1.0)
    labels = np.where(dom, np.where(phi1[F].mean(axis=1) < 0, _IN, _OUT), _FAR)
    band1 = dom & (phi1[F].min(axis=1) <= 0)
    st = _cut(CutState.start(V, F, labels), band1, phi1, "area's border (distance = radius)")
    inside = st.labels == _IN
    if not inside.any():
        raise BolusError(f"no face lies within {radius:g} mm of the cursor along the surface: choose a larger radius")
    # 2. cavities: openness = threshold
    cav = np.zeros(len(st.F), dtype=bool)
    flipped = False
    if exclude_cavities:
        report(0.2, "openness (cavities)")
        meas = np.unique(st.parent[inside])  # input faces holding the area
        occl = np.nonzero(dom)[0]
        pos = np.searchsorted(occl, meas)
        o_face, flipped = _outer_openness(V, F[occl], pos, directions, lambda fr, t: report(0.2 + 0.6 * fr, t))
        ov = _vertex_openness(V, F, meas, o_face)
        phi2 = float(openness_threshold) - _on_new_vertices(st, ov)  # > 0 in a cavity
        labels2 = np.where(inside, np.where(phi2[st.F].mean(axis=1) > 0, _OUT, _IN), _FAR)
        st = _cut(replace(st, labels=labels2), inside, phi2, "cavity border (openness = threshold)")
        cav = st.labels == _OUT
        inside = st.labels == _IN
    report(0.9, "the area")
    area = _finish(V, F, st, inside, cav, d, p, f0, how_far, radius)
    if exclude_cavities and flipped:
        area.warnings.append("the surface's normals point into the body (its back side is the more open one): "
                             "cavities were looked for on the back side; recalculate the normals outside "
                             "(Mesh > Normals > Recalculate Outside)")
    if not (d[finite] > radius).any():
        area.warnings.append(f"the whole connected surface lies within {radius:g} mm of the cursor: nothing was cut "
                             "at the radius")
    return area


def _distance_near(V, F, p, f0, radius, base_reach) -> np.ndarray:
    """Distance along the surface (n,) from p on triangle f0, up to the reach (inf beyond).

    Only the triangles within the reach of p (straight-line distance, which never exceeds
    the distance along the surface) are used and checked (zero-area triangles, non-manifold
    edges: refused there, with the mesh's vertex indices); a defect far away does not matter.
    The reach is base_reach, and at least the radius plus two of the longest edges there, so
    every face the level line d = radius crosses has all its corners' distances."""
    dist_v = np.linalg.norm(V - p, axis=1)
    near = (dist_v[F].min(axis=1) <= base_reach)
    near[f0] = True
    longest = float(np.linalg.norm(V[F[near]] - V[np.roll(F[near], 1, axis=1)], axis=2).max())
    reach = max(base_reach, radius + 2.0 * longest)
    near = (dist_v[F].min(axis=1) <= reach)
    near[f0] = True
    Fb, ids = submesh(F, near)
    topo = MeshTopology(V[ids], Fb)
    topo.require_nondegenerate("the surface near the cursor", vert_ids=ids)
    bad = np.nonzero(topo.nonmanifold_edges)[0]
    if len(bad):
        i, j = (int(ids[x]) for x in topo.edges[bad[0]])
        raise BolusError(f"the surface near the cursor has {len(bad)} non-manifold edge(s) (shared by more than two "
                         f"triangles), e.g. the edge between vertices {i} and {j}; Select > Select All by Trait > "
                         "Non Manifold shows them: delete the extra faces there")
    d = np.full(len(V), np.inf)
    d[ids] = geodesic_distance(V[ids], Fb, p, int(np.count_nonzero(near[:f0])), max_mm=reach)
    return d


def _finish(V, F, st, inside, cav, d, p, f0, how_far, radius) -> Area:
    """The area: inside faces edge-connected to the source point; figures and warnings."""
    topo = MeshTopology(st.V, st.F)
    if not inside.any():
        raise BolusError(f"every face within {radius:g} mm of the cursor is a cavity face: place the cursor on open "
                         "skin or choose a larger radius")
    kids = np.nonzero(inside & (st.parent == f0))[0]
    if len(kids):
        w = barycentric(np.repeat(p[None], len(kids), 0), st.V[st.F[kids]])
        src = int(kids[np.argmax(w.min(axis=1))])
    else:  # the point itself lies in a cavity: the nearest open face
        cand = np.nonzero(inside)[0]
        src = int(cand[np.argmin(np.linalg.norm(topo.centroids[cand] - p, axis=1))])
    _, comp = topo.face_components(np.where(inside, 1, np.where(cav, 2, 0)))
    selected = inside & (comp == comp[src])
    _, comp01 = topo.face_components(np.where(inside | cav, 1, 0))
    # left out within the radius: cavity faces and the open specks among them (a pocket's floor seen through
    # its mouth) that are not edge-connected to the area
    cavity = (inside | cav) & (comp01 == comp01[src]) & ~selected
    A = topo.areas
    split = np.zeros(len(F), dtype=bool)
    split[st.parent[~st.unchanged]] = True
    loops = boundary_loops(st.F[selected])
    warnings = []
    mesh_border = MeshTopology(V, F).boundary_vertices
    on_border = np.zeros(len(st.V), dtype=bool)
    on_border[: len(V)] = mesh_border
    if loops and any(on_border[lp].sum() >= 2 for lp in loops):
        warnings.append(f"the area reaches the border of the mesh: the surface ends within {radius:g} mm of the "
                        "cursor, so the area is cut short there")
    return Area(
        V=st.V, F=st.F, selected=selected, parent=st.parent, vsrc=st.vsrc, vw=st.vw, vert_parent=st.vparent,
        split=split, cavity=cavity, distance=_on_new_vertices(st, d), source_point=p, source_face=int(f0),
        centre_distance_mm=float(how_far), area_mm2=float(A[selected].sum()), cavity_area_mm2=float(A[cavity].sum()),
        holes=max(len(loops) - 1, 0), warnings=warnings,
    )
