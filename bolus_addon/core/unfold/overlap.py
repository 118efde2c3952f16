"""Flipped triangles and self-overlaps of a flat pattern (seed 4.5.3).

The seed corrects overlaps that the unfolding accumulates (4.5.3, Figure 4-18); it
finds the wrongly placed vertices by their one-ring edges that "intersect with other
edges".  This module only *detects*, exactly and vectorised, what a printable pattern
must not have:

- `flipped_faces`: triangles whose signed area is negative or vanishing (a fold);
- `boundary_self_intersections`: boundary edges that cross each other (the outline of
  the pattern is not a simple curve, e.g. a strip whose ends overlap);
- `overlapping_faces`: triangles whose interiors overlap another triangle of the same
  pattern (covers interior fold-overs and overlapping islands).

Candidate pairs come from a uniform grid on bounding boxes (`candidate_pairs`); the
exact tests are orientation predicates and the separating-axis theorem, with a
tolerance of ``rel_tol`` times the mean edge length, so that touching (shared vertices,
the two sides of a cut that closes up exactly) is not an overlap.
UV (n,2) are pattern coordinates (mm), F (m,3) triangles, counter-clockwise = positive.

Degenerate input: NaN/inf coordinates, out-of-range indices and triangles repeating a
vertex raise `BolusError` naming the first (`as_pattern_arrays`); a collapsed (zero-area)
triangle, e.g. between coincident vertices, counts as flipped and never as overlapping;
needle triangles are ordinary ones; on a non-manifold edge, two triangles on the same
side are a fold-over (an overlap) and the edge is not a boundary edge.
"""
from __future__ import annotations

import numpy as np

from ..errors import BolusError
from ..mesh.geometry2d import cross2d
from ..mesh.topology import as_mesh_arrays

__all__ = [
    "as_pattern_arrays",
    "signed_areas",
    "flipped_faces",
    "boundary_edge_array",
    "candidate_pairs",
    "segment_intersections",
    "boundary_self_intersections",
    "overlapping_face_pairs",
    "overlapping_faces",
    "point_in_polygon",
    "overlap_summary",
]

#: touching is not overlapping: contacts closer than REL_TOL x the mean edge length are ignored
REL_TOL = 1e-9
#: candidate pairs tested per block (bounds the temporary (pairs x 3 x 3) arrays to ~15 MB)
_CHUNK = 200_000
#: more candidate pairs than this means triangles piled up (a collapsed pattern): refuse, ~2 GB of pairs
MAX_PAIRS = 50_000_000
#: the grid cell grows until the boxes cover at most this many cells each on average
CELLS_PER_BOX = 16
#: at most this many cells along an axis, so cell ids (x * ny + y) stay far inside int64
MAX_CELLS_PER_AXIS = 65536.0


def as_pattern_arrays(UV, F) -> tuple[np.ndarray, np.ndarray]:
    """Validate a flat mesh: UV (n,2) float64, F (m,3) int64 (m may be 0).

    The checks are `topology.as_mesh_arrays`' (integer indices in range, no triangle
    repeating a vertex, finite coordinates, naming the first offender) on UV lifted to
    z = 0.  Zero-area and flipped triangles pass: finding them is this module's job.
    """
    UV = np.asarray(UV, dtype=np.float64)
    if UV.ndim != 2 or UV.shape[1] != 2:
        raise BolusError(f"pattern coordinates must be an (n, 2) array, got shape {UV.shape}")
    _, F = as_mesh_arrays(np.c_[UV, np.zeros(len(UV))], F)
    return UV, F


def _mean_edge_length(UV, F) -> float:
    if len(F) == 0:
        return 1.0
    P = UV[F]
    L = np.linalg.norm(P - np.roll(P, -1, axis=1), axis=2).mean()
    return float(L) if L > 0 else 1.0


def signed_areas(UV, F) -> np.ndarray:
    """Signed areas (m,) of the triangles F (m,3) in UV (n,2); positive = counter-clockwise."""
    UV, F = as_pattern_arrays(UV, F)
    P = UV[F]
    return 0.5 * cross2d(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])


def flipped_faces(UV, F, rel_tol: float = 1e-12) -> np.ndarray:
    """(m,) bool: triangles turned over (clockwise) or collapsed, seed 4.5.3.

    A triangle counts when its signed area is <= rel_tol * L^2 (L the mean edge length),
    so a collapsed (zero-area) triangle is reported too.  A pattern that came out mirrored
    as a whole has every triangle flipped: mirror it (UV[:, 0] *= -1) before judging.
    """
    UV, F = as_pattern_arrays(UV, F)
    L = _mean_edge_length(UV, F)
    return signed_areas(UV, F) <= rel_tol * L * L


# ---------------------------------------------------------------- broad phase
def _grid_cells(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grid cell ranges of boxes lo/hi (b,2): first and last cell (b,2) int64 of each box.

    The cell is the median box size, doubled while boxes would cover more than
    `CELLS_PER_BOX` cells each on average (a few huge boxes must not flood the grid).
    """
    k = len(lo)
    origin = lo.min(axis=0)
    span = float((hi.max(axis=0) - origin).max())
    cell = float(np.median((hi - lo).max(axis=1)))
    if not cell > 0:
        cell = span / np.sqrt(k) if span > 0 else 1.0
    cell = max(cell, span / MAX_CELLS_PER_AXIS, 1e-300)  # keep cell ids well inside int64
    while True:
        i0 = np.floor((lo - origin) / cell).astype(np.int64)
        i1 = np.floor((hi - origin) / cell).astype(np.int64)
        ext = i1 - i0 + 1
        if (ext[:, 0] * ext[:, 1]).sum() <= CELLS_PER_BOX * k + 1024:
            return i0, i1
        cell *= 2.0


def candidate_pairs(lo, hi, tol: float = 0.0) -> np.ndarray:
    """Pairs (k,2), i < j, of boxes lo/hi (b,2) whose closed boxes overlap (within tol).

    Uniform grid broad phase (`_grid_cells`): every box is entered in the cells it
    covers and a pair is reported only in the first cell both cover, so no pair
    repeats.  Vectorised: memory and time ~ (boxes + candidate pairs); more than
    `MAX_PAIRS` candidates raise `BolusError` (triangles piled on top of each other).
    """
    lo = np.asarray(lo, dtype=np.float64) - tol
    hi = np.asarray(hi, dtype=np.float64) + tol
    bad = np.nonzero(~(np.isfinite(lo).all(axis=1) & np.isfinite(hi).all(axis=1)))[0] if lo.size else []
    if len(bad):
        raise BolusError(f"box {int(bad[0])} has a non-finite (NaN or infinite) corner")
    k = len(lo)
    if k < 2:
        return np.zeros((0, 2), dtype=np.int64)
    i0, i1 = _grid_cells(lo, hi)
    ext = i1 - i0 + 1
    cnt = ext[:, 0] * ext[:, 1]
    total = int(cnt.sum())
    item = np.repeat(np.arange(k), cnt)
    local = np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    cx = i0[item, 0] + local % ext[item, 0]
    cy = i0[item, 1] + local // ext[item, 0]
    cid = cx * (int(i1[:, 1].max()) + 1) + cy
    order = np.lexsort((item, cid))
    cid_s, it_s, cx_s, cy_s = cid[order], item[order], cx[order], cy[order]
    starts = np.r_[0, np.nonzero(np.diff(cid_s))[0] + 1]
    sizes = np.diff(np.r_[starts, total])
    c2 = np.repeat(starts + sizes, sizes) - np.arange(total) - 1  # partners after each entry in its cell
    if c2.sum() > MAX_PAIRS:
        raise BolusError(
            f"the pattern is too tangled to check for overlaps ({int(c2.sum())} candidate pairs): "
            "many triangles lie on top of each other"
        )
    a = np.repeat(np.arange(total), c2)
    b = a + 1 + (np.arange(len(a)) - np.repeat(np.cumsum(c2) - c2, c2))
    I, J = it_s[a], it_s[b]  # I < J: sorted by item inside a cell
    # report a pair only in the lowest cell both boxes cover
    keep = (cx_s[a] == np.maximum(i0[I, 0], i0[J, 0])) & (cy_s[a] == np.maximum(i0[I, 1], i0[J, 1]))
    I, J = I[keep], J[keep]
    keep = np.all((lo[I] <= hi[J]) & (lo[J] <= hi[I]), axis=1)
    return np.stack([I[keep], J[keep]], axis=1)


# ----------------------------------------------------------- boundary crossings
def boundary_edge_array(F, loops=None) -> np.ndarray:
    """Boundary edges (b,2) as vertex pairs.

    With ``loops`` (list of vertex loops, e.g. `cutting.boundary_loops`) the edges are
    (loop[i], loop[i+1]) loop after loop, closing edges included; without, the
    half-edges of F that no other triangle shares, in face order.  That is a set of
    edges, not a walk: the crossing test needs no order, so the loop walker
    (`cutting.boundary_loops`, which costs a wedge analysis) is only used when the
    caller already has its loops.
    """
    if loops is not None:
        parts = [np.stack([np.asarray(lp), np.roll(np.asarray(lp), -1)], axis=1) for lp in loops if len(lp) >= 2]
        return np.concatenate(parts).astype(np.int64) if parts else np.zeros((0, 2), dtype=np.int64)
    F = np.asarray(F, dtype=np.int64)
    he = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    n = int(F.max()) + 1 if F.size else 1
    key = np.minimum(he[:, 0], he[:, 1]) * n + np.maximum(he[:, 0], he[:, 1])
    _, inv, count = np.unique(key, return_inverse=True, return_counts=True)
    return he[count[inv.reshape(-1)] == 1]


def segment_intersections(P, E, rel_tol: float = REL_TOL, scale: float | None = None) -> np.ndarray:
    """Pairs (k,2), i < j, of segments E (b,2) over points P (n,2) that cross properly.

    Proper: each segment has the other's ends strictly on opposite sides, beyond
    rel_tol * scale^2 (scale defaults to the mean segment length).  Segments sharing a
    vertex index are skipped; touching and collinear overlaps are not reported, nor are
    zero-length segments (coincident points).  BolusError for a non-finite point.
    """
    P = np.asarray(P, dtype=np.float64)
    E = np.asarray(E, dtype=np.int64).reshape(-1, 2)
    bad = np.nonzero(~np.isfinite(P[np.unique(E)]).all(axis=1))[0] if len(E) else []
    if len(bad):
        raise BolusError(f"point {int(np.unique(E)[bad[0]])} of a segment is not finite (NaN or infinite)")
    if len(E) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    A, B = P[E[:, 0]], P[E[:, 1]]
    if scale is None:
        scale = float(np.linalg.norm(B - A, axis=1).mean()) or 1.0
    eps = rel_tol * scale * scale
    pairs = candidate_pairs(np.minimum(A, B), np.maximum(A, B))
    i, j = pairs[:, 0], pairs[:, 1]
    share = (E[i, 0] == E[j, 0]) | (E[i, 0] == E[j, 1]) | (E[i, 1] == E[j, 0]) | (E[i, 1] == E[j, 1])
    i, j = i[~share], j[~share]
    a, b, c, d = A[i], B[i], A[j], B[j]
    o1 = cross2d(b - a, c - a)
    o2 = cross2d(b - a, d - a)
    o3 = cross2d(d - c, a - c)
    o4 = cross2d(d - c, b - c)
    cross = (((o1 > eps) & (o2 < -eps)) | ((o1 < -eps) & (o2 > eps))) & (
        ((o3 > eps) & (o4 < -eps)) | ((o3 < -eps) & (o4 > eps))
    )
    return np.stack([i[cross], j[cross]], axis=1)


def boundary_self_intersections(UV, F, loops=None, rel_tol: float = REL_TOL) -> np.ndarray:
    """Crossing boundary edges of a pattern, seed 4.5.3 (edges that "intersect with other edges").

    UV (n,2), F (m,3), loops optional (see `boundary_edge_array`).  Returns (k,2) pairs
    i < j of row indices into ``boundary_edge_array(F, loops)`` whose edges properly
    cross; edges sharing a vertex are never paired.  Empty for a simple outline.
    """
    UV, F = as_pattern_arrays(UV, F)
    E = boundary_edge_array(F, loops)
    return segment_intersections(UV, E, rel_tol, _mean_edge_length(UV, F))


# ------------------------------------------------------------- face overlaps
def _sat_overlap(A, B, tol):
    """(P,) bool: interiors of triangles A, B (P,3,2) overlap by more than tol (length).

    Separating-axis test on the six edge normals; an axis of a zero-length edge is skipped.
    """
    Ax, Ay, Bx, By = A[..., 0], A[..., 1], B[..., 0], B[..., 1]
    hit = np.ones(len(A), dtype=bool)
    for T in (A, B):
        for k in range(3):
            nx = T[:, k, 1] - T[:, (k + 1) % 3, 1]  # normal of edge k -> k+1
            ny = T[:, (k + 1) % 3, 0] - T[:, k, 0]
            ln = np.hypot(nx, ny)
            ok = ln > 0
            ln = np.where(ok, ln, 1.0)
            nx, ny = (nx / ln)[:, None], (ny / ln)[:, None]
            pa = Ax * nx + Ay * ny
            pb = Bx * nx + By * ny
            depth = np.minimum(pa.max(axis=1), pb.max(axis=1)) - np.maximum(pa.min(axis=1), pb.min(axis=1))
            hit &= (depth > tol) | ~ok
    return hit


def overlapping_face_pairs(UV, F, rel_tol: float = REL_TOL) -> np.ndarray:
    """Pairs (k,2), i < j, of triangles whose interiors overlap, seed 4.5.3.

    UV (n,2), F (m,3).  Broad phase on bounding boxes, then per candidate pair:
    no shared vertex or one shared vertex: separating-axis test on the six edge normals
    (overlap deeper than rel_tol * L, L the mean edge length; touching is not overlap);
    a shared edge: the two opposite corners on the same side of it (a fold-over);
    the same three vertices: overlap unless collapsed.
    """
    UV, F = as_pattern_arrays(UV, F)
    m = len(F)
    if m < 2:
        return np.zeros((0, 2), dtype=np.int64)
    tol = rel_tol * _mean_edge_length(UV, F)
    P = UV[F]
    pairs = candidate_pairs(P.min(axis=1), P.max(axis=1))
    out = []
    for s in range(0, len(pairs), _CHUNK):
        i, j = pairs[s : s + _CHUNK, 0], pairs[s : s + _CHUNK, 1]
        eq = F[i][:, :, None] == F[j][:, None, :]  # (p,3,3)
        nshared = eq.sum(axis=(1, 2))
        hit = np.zeros(len(i), dtype=bool)
        g = nshared <= 1
        hit[g] = _sat_overlap(P[i[g]], P[j[g]], tol)
        g = np.nonzero(nshared == 2)[0]
        if len(g):
            # corner of i not in j, and corner of j not in i; the shared edge u-v
            ka = np.argmin(eq[g].any(axis=2), axis=1)
            kb = np.argmin(eq[g].any(axis=1), axis=1)
            fi, fj = F[i[g]], F[j[g]]
            opp_i = fi[np.arange(len(g)), ka]
            opp_j = fj[np.arange(len(g)), kb]
            u = fi[np.arange(len(g)), (ka + 1) % 3]
            v = fi[np.arange(len(g)), (ka + 2) % 3]
            uv = UV[v] - UV[u]
            luv = np.linalg.norm(uv, axis=1)
            luv = np.where(luv > 0, luv, np.inf)
            si = cross2d(uv, UV[opp_i] - UV[u]) / luv
            sj = cross2d(uv, UV[opp_j] - UV[u]) / luv
            hit[g] = ((si > tol) & (sj > tol)) | ((si < -tol) & (sj < -tol))
        g = nshared == 3
        if g.any():
            Pi = P[i[g]]
            hit[g] = np.abs(cross2d(Pi[:, 1] - Pi[:, 0], Pi[:, 2] - Pi[:, 0])) > tol * tol
        out.append(np.stack([i[hit], j[hit]], axis=1))
    return np.concatenate(out) if out else np.zeros((0, 2), dtype=np.int64)


def overlapping_faces(UV, F, rel_tol: float = REL_TOL) -> np.ndarray:
    """(m,) bool: triangles that overlap another triangle of the same pattern (seed 4.5.3)."""
    UV, F = as_pattern_arrays(UV, F)
    hit = np.zeros(len(F), dtype=bool)
    pairs = overlapping_face_pairs(UV, F, rel_tol)
    hit[pairs.ravel()] = True
    return hit


# ------------------------------------------------------------------- helpers
def point_in_polygon(points, polygon) -> np.ndarray:
    """(k,) bool: points (k,2) strictly inside the closed polygon (p,2), even-odd rule.

    Points exactly on the outline may go either way.  Vectorised over points x edges.
    BolusError for a non-finite polygon corner or point.
    """
    Q = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    A = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
    for what, X in (("point", Q), ("polygon corner", A)):
        bad = np.nonzero(~np.isfinite(X).all(axis=1))[0]
        if len(bad):
            raise BolusError(f"{what} {int(bad[0])} is not finite (NaN or infinite)")
    B = np.roll(A, -1, axis=0)
    inside = np.zeros(len(Q), dtype=bool)
    step = max(1, _CHUNK // max(len(Q), 1))
    for s in range(0, len(A), step):
        a, b = A[s : s + step], B[s : s + step]
        ay, by = a[None, :, 1], b[None, :, 1]
        qy, qx = Q[:, None, 1], Q[:, None, 0]
        straddle = (ay > qy) != (by > qy)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = a[None, :, 0] + (qy - ay) * (b[None, :, 0] - a[None, :, 0]) / (by - ay)
        inside ^= (np.count_nonzero(straddle & (qx < x), axis=1) % 2).astype(bool)
    return inside


def overlap_summary(UV, F, loops=None) -> dict:
    """Counts for a pattern report of UV (n,2), F (m,3) (loops: see `boundary_edge_array`).

    Returns ``{"flipped_faces": int, "overlapping_faces": int, "boundary_crossings": int,
    "ok": bool}``; ok when all three are 0.
    """
    flipped = flipped_faces(UV, F)
    over = overlapping_faces(UV, F)
    cross = boundary_self_intersections(UV, F, loops)
    return {
        "flipped_faces": int(flipped.sum()),
        "overlapping_faces": int(over.sum()),
        "boundary_crossings": int(len(cross)),
        "ok": bool(not flipped.any() and not over.any() and len(cross) == 0),
    }
