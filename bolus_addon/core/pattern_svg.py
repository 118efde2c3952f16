"""The flat pattern as an SVG at true scale (1 mm on the pattern = 1 mm on paper).

* `outline_loops` — the closed boundary loops of a flat triangle mesh: outer loops
  counter-clockwise, holes clockwise, largest first.
* `offset_polygon` — the seam allowance: a polygon grown (or shrunk) by a distance,
  with miter joins cut square at twice the distance.  The raw offset curve (edges
  pushed out, miter or cut miter at convex corners, ``a -> corner -> b`` at concave
  ones) is, as a 1-chain, the sum of the polygon, one rectangle per edge and one
  wedge per convex corner; so its winding number is positive exactly on their union,
  the grown polygon (the method of Clipper's offsetting).  Its self-intersections are
  resolved by splitting every segment where others cross it and keeping the pieces
  that separate winding > 0 from winding <= 0: the result is a simple polygon even
  where concave corners or narrow notches make the raw curve loop over itself.
* `pattern_svg` — the document: width and height in mm with a viewBox in mm, the
  pattern seen from above (+y up on paper), one ``<g id="patch-<label>">`` per island
  with its cut lines, optional dashed seam allowance and a label, a 50 mm scale bar.
* `svg_outline_paths` — the cut lines read back into pattern millimetres.
"""
from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .errors import BolusError
from .geometry2d import cross2d

__all__ = [
    "outline_loops",
    "outline_loop_indices",
    "offset_polygon",
    "signed_area",
    "pattern_svg",
    "svg_outline_paths",
    "SCALE_BAR_MM",
]

SVG_NS = "http://www.w3.org/2000/svg"
SCALE_BAR_MM = 50.0
CUT_STROKE_MM = 0.3
SEAM_STROKE_MM = 0.2
MITER_LIMIT = 2.0  # a miter longer than MITER_LIMIT * d is cut square at that distance
PRINT_NOTE = "print at 100 % (no fit-to-page)"


# --------------------------------------------------------------------------- geometry
def signed_area(P) -> float:
    """Shoelace area of the closed polygon P (k,2): positive when counter-clockwise."""
    P = np.asarray(P, dtype=np.float64)
    if len(P) < 3:
        return 0.0
    Q = P - P.mean(axis=0)
    x, y = Q[:, 0], Q[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _winding(Q: np.ndarray, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Winding numbers (t,) of points Q (t,2) about the directed segments A -> B (s,2)."""
    w = np.zeros(len(Q), dtype=np.int64)
    if len(A) == 0:
        return w
    R = B - A
    step = max(1, 2_000_000 // len(A))
    for lo in range(0, len(Q), step):
        q = Q[lo:lo + step]
        qy = q[:, 1:2]
        cross = cross2d(R, q[:, None, :] - A)  # (t, s) > 0: q left of the segment
        up = (A[:, 1] <= qy) & (B[:, 1] > qy) & (cross > 0)
        down = (B[:, 1] <= qy) & (A[:, 1] > qy) & (cross < 0)
        w[lo:lo + step] = up.sum(axis=1) - down.sum(axis=1)
    return w


def _ray_winding_x(Q: np.ndarray, T: np.ndarray, A: np.ndarray, B: np.ndarray, eps: float):
    """Winding along rays from Q (t,2) towards +x about the segments A -> B (s,2).

    Each point lies on a segment of direction T (t,2) with T_y != 0; the segments through
    the point parallel to T (it and collinear overlaps) are left out and counted
    instead in ``jump`` (t,): +1 along T, -1 against it.  Points are processed in strips
    of y so that each meets only the segments spanning its strip.
    """
    w = np.zeros(len(Q), dtype=np.int64)
    jump = np.zeros(len(Q), dtype=np.int64)
    if len(Q) == 0:
        return w, jump
    R = B - A
    RR = np.einsum("ij,ij->i", R, R)
    ylo, yhi = np.minimum(A[:, 1], B[:, 1]), np.maximum(A[:, 1], B[:, 1])
    order = np.argsort(Q[:, 1], kind="stable")
    n_strips = int(np.ceil(np.sqrt(len(Q))))
    for idx in np.array_split(order, n_strips):
        if len(idx) == 0:
            continue
        q, t = Q[idx], T[idx]
        cand = np.flatnonzero((yhi >= q[0, 1] - eps) & (ylo <= q[-1, 1] + eps))
        if len(cand) == 0:
            continue
        a, r = A[cand], R[cand]
        qx, qy = q[:, 0:1], q[:, 1:2]
        cross = cross2d(r, q[:, None, :] - a)  # (c, s) > 0: q left of the segment
        up = (a[:, 1] <= qy) & (a[:, 1] + r[:, 1] > qy)
        down = (a[:, 1] + r[:, 1] <= qy) & (a[:, 1] > qy)
        tn = t / np.linalg.norm(t, axis=1, keepdims=True)
        along_t = tn @ r.T  # (c, s)
        parallel = np.abs(cross2d(tn[:, None, :], r)) <= 1e-9 * np.sqrt(RR[cand])
        proj = (qx - a[:, 0]) * r[:, 0] + (qy - a[:, 1]) * r[:, 1]
        on = parallel & (np.abs(cross) <= eps * np.sqrt(RR[cand])) & (proj >= 0) & (proj <= RR[cand])
        w[idx] = ((up & (cross > 0) & ~on).sum(axis=1) - (down & (cross < 0) & ~on).sum(axis=1))
        jump[idx] = np.where(on, np.where(along_t > 0, 1, -1), 0).sum(axis=1)
    return w, jump


def _side_windings(Q: np.ndarray, T: np.ndarray, A: np.ndarray, B: np.ndarray, eps: float):
    """Windings just left and just right (t,) of points Q (t,2) on segments of direction T (t,2)."""
    steep = np.abs(T[:, 1]) >= np.abs(T[:, 0])
    wl, wr = np.zeros(len(Q), dtype=np.int64), np.zeros(len(Q), dtype=np.int64)
    rot = lambda X: np.stack([X[:, 1], -X[:, 0]], axis=1)  # noqa: E731  quarter turn clockwise
    for mask, f in ((steep, lambda X: X), (~steep, rot)):
        if not mask.any():
            continue
        Tm = f(T[mask])
        w, jump = _ray_winding_x(f(Q[mask]), Tm, f(A), f(B), eps)
        # the ray leaves from the +x side: the right of an upward segment, the left of a downward one
        upward = Tm[:, 1] > 0
        wl[mask] = np.where(upward, w + jump, w)
        wr[mask] = np.where(upward, w, w - jump)
    return wl, wr


def _chain(edges: np.ndarray, pos: np.ndarray) -> list[np.ndarray]:
    """Directed edges (b,2) whose in- and out-degrees balance -> closed vertex loops.

    Where several edges leave a vertex, the walk takes the first one clockwise from the
    edge it came in on (so loops touching at a vertex stay separate), and a loop closes
    as soon as it is back at its start.
    """
    b = len(edges)
    order = np.argsort(edges[:, 0], kind="stable")
    starts = edges[order, 0]
    used = np.zeros(b, dtype=bool)
    loops = []
    for e0 in range(b):
        if used[e0]:
            continue
        used[e0] = True
        start, e = edges[e0, 0], e0
        loop = [start]
        for _ in range(b):
            u, v = edges[e]
            if v == start:
                break
            lo, hi = np.searchsorted(starts, v), np.searchsorted(starts, v, side="right")
            cand = order[lo:hi]
            cand = cand[~used[cand]]
            if len(cand) == 0:
                raise BolusError(
                    "the outline does not close: the triangles are not consistently oriented "
                    "(every face must have its corners in the same turning order)")
            if len(cand) > 1:
                back = pos[u] - pos[v]
                out = pos[edges[cand, 1]] - pos[v]
                turn = (np.arctan2(back[1], back[0]) - np.arctan2(out[:, 1], out[:, 0])) % (2 * np.pi)
                turn[turn <= 1e-12] = 2 * np.pi
                cand = cand[[np.argmin(turn)]]
            e = int(cand[0])
            used[e] = True
            loop.append(v)
        else:  # pragma: no cover - cannot happen with balanced degrees
            raise BolusError("the outline does not close")
        loops.append(np.asarray(loop, dtype=np.int64))
    return loops


def _as_flat_mesh(UV, F) -> tuple[np.ndarray, np.ndarray]:
    UV = np.asarray(UV, dtype=np.float64)
    F = np.asarray(F)
    if UV.ndim != 2 or UV.shape[1] != 2:
        raise BolusError(f"pattern positions must be an (n, 2) array, got shape {UV.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise BolusError(f"pattern triangles must be a non-empty (m, 3) array, got shape {F.shape}")
    if not np.issubdtype(F.dtype, np.integer):
        raise BolusError("triangle indices must be integers")
    F = F.astype(np.int64, copy=False)
    if F.min() < 0 or F.max() >= len(UV):
        raise BolusError("a triangle refers to a vertex index outside the pattern's vertex array")
    if not np.all(np.isfinite(UV)):
        raise BolusError("the pattern has non-finite (NaN or infinite) coordinates")
    return UV, F


def outline_loop_indices(UV, F) -> list[np.ndarray]:
    """Boundary loops of the flat mesh UV (n,2), F (m,3) as vertex indices [(k_i,)].

    Boundary edges are those used by one triangle.  Loops come largest |area| first;
    outer loops are counter-clockwise, holes (inside an odd number of other loops)
    clockwise, whatever the triangles' own turning order.
    """
    UV, F = _as_flat_mesh(UV, F)
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    _, inv, counts = np.unique(np.sort(E, axis=1), axis=0, return_inverse=True, return_counts=True)
    B = E[counts[inv.ravel()] == 1]
    if len(B) == 0:
        raise BolusError("the pattern piece has no boundary (a closed surface cannot be laid flat)")
    loops = _chain(B, UV)
    area = np.array([signed_area(UV[l]) for l in loops])
    order = np.argsort(-np.abs(area), kind="stable")
    loops, area = [loops[i] for i in order], area[order]
    # nesting depth: how many larger loops contain the midpoint of the loop's first edge
    mids = np.array([0.5 * (UV[l[0]] + UV[l[1 % len(l)]]) for l in loops])
    depth = np.zeros(len(loops), dtype=np.int64)
    for j, l in enumerate(loops[:-1]):
        P = UV[l]
        w = _winding(mids[j + 1:], P, np.roll(P, -1, axis=0))
        depth[j + 1:] += w != 0
    out = []
    for l, a, dep in zip(loops, area, depth):
        want_ccw = dep % 2 == 0
        out.append(l if (a > 0) == want_ccw else np.concatenate([l[:1], l[1:][::-1]]))
    return out


def outline_loops(UV, F) -> list[np.ndarray]:
    """Closed boundary loops [(k_i,2)] of the flat mesh UV (n,2), F (m,3), first point not repeated.

    Largest |signed area| first; outer loops counter-clockwise, holes clockwise.
    """
    UV, F = _as_flat_mesh(UV, F)
    return [UV[l] for l in outline_loop_indices(UV, F)]


def _simplify(P: np.ndarray, tol: float) -> np.ndarray:
    """Closed polygon P (k,2) without repeated points and points on the line through their neighbours."""
    P = np.asarray(P, dtype=np.float64)
    while len(P) >= 3:
        keep = np.linalg.norm(P - np.roll(P, 1, axis=0), axis=1) > tol
        if not keep.all():
            P = P[keep] if keep.any() else P[:1]
            continue
        a, b = P - np.roll(P, 1, axis=0), np.roll(P, -1, axis=0) - P
        c = np.roll(P, -1, axis=0) - np.roll(P, 1, axis=0)
        cross = cross2d(a, b)
        # distance of the point from the chord of its neighbours, and the point between them
        straight = (np.abs(cross) <= tol * np.linalg.norm(c, axis=1)) & (np.einsum("ij,ij->i", a, b) > 0)
        if not straight.any():
            break
        drop, last = [], -2
        for i in np.flatnonzero(straight):  # never two neighbours at once: errors cannot add up
            if i != last + 1 and not (i == len(P) - 1 and drop and drop[0] == 0):
                drop.append(i)
                last = i
        keep = np.ones(len(P), dtype=bool)
        keep[drop] = False
        P = P[keep]
    return P


def _raw_offset(Q: np.ndarray, d: float) -> np.ndarray:
    """Closed polygon Q (k,2) with every edge pushed by d > 0 to its right -> raw curve (r,2)."""
    T = np.roll(Q, -1, axis=0) - Q
    T = T / np.linalg.norm(T, axis=1, keepdims=True)  # edge i: Q[i] -> Q[i+1]
    N = np.stack([T[:, 1], -T[:, 0]], axis=1)  # right-hand normals
    Ta, Na = np.roll(T, 1, axis=0), np.roll(N, 1, axis=0)  # edge coming into vertex i
    cross = cross2d(Ta, T)
    cos = np.einsum("ij,ij->i", Ta, T)
    pa, pb = Q + d * Na, Q + d * N
    spike = (np.abs(cross) <= 1e-12) & (cos < 0)
    convex = (cross > 0) | spike
    S = Na + N
    pts = []
    for i in range(len(Q)):
        if convex[i]:
            if not spike[i] and 1.0 + cos[i] >= 2.0 / MITER_LIMIT**2:  # miter within the limit
                pts.append(Q[i] + d * S[i] / (1.0 + cos[i]))
            else:  # cut the miter square at MITER_LIMIT * d from the corner
                u = Ta[i] if spike[i] else S[i] / np.linalg.norm(S[i])
                L = MITER_LIMIT * d
                pts.append(pa[i] + Ta[i] * (L - d * Na[i] @ u) / (Ta[i] @ u))
                pts.append(pb[i] + T[i] * (L - d * N[i] @ u) / (T[i] @ u))
        elif np.linalg.norm(pa[i] - pb[i]) <= 1e-12 * d:  # straight on
            pts.append(pa[i])
        else:
            pts.extend([pa[i], Q[i], pb[i]])
    return np.asarray(pts)


def _region_boundary(A: np.ndarray, B: np.ndarray, inside, eps: float) -> list[np.ndarray]:
    """Boundary loops of {x : inside(winding of the segments A -> B (s,2) at x)}.

    Loops have the region on their left (outer loops counter-clockwise, holes clockwise).
    """
    R = B - A
    RR = np.einsum("ij,ij->i", R, R)
    s = len(A)
    splits = [[0.0, 1.0] for _ in range(s)]
    step = max(1, 1_000_000 // s)
    for lo in range(0, s, step):
        hi = min(s, lo + step)
        Ri, Ai = R[lo:hi, None, :], A[lo:hi, None, :]
        D = A[None, :, :] - Ai  # (c, s, 2): A_j - A_i
        den = cross2d(Ri, R[None, :, :])
        num_t = cross2d(D, R[None, :, :])
        num_u = cross2d(D, Ri)
        ok = np.abs(den) > 1e-12 * np.sqrt(RR[lo:hi, None] * RR[None, :])
        with np.errstate(divide="ignore", invalid="ignore"):
            t, u = num_t / den, num_u / den
        hit = ok & (t > -1e-9) & (t < 1 + 1e-9) & (u > -1e-9) & (u < 1 + 1e-9)
        # other segments' end points lying on segment i (touching, collinear overlaps)
        along = np.einsum("csk,ck->cs", D, R[lo:hi]) / RR[lo:hi, None]
        off = np.abs(num_u) / np.sqrt(RR[lo:hi, None])  # distance of A_j from the line of segment i
        touch = (off <= eps) & (along > 0) & (along < 1)
        ci, cj = np.nonzero(hit)
        for a, tv in zip(ci + lo, np.clip(t[ci, cj], 0.0, 1.0)):
            splits[a].append(float(tv))
        ci, cj = np.nonzero(touch)
        for a, tv in zip(ci + lo, along[ci, cj]):
            splits[a].append(float(tv))
    # sub-segments
    seg_of, t0, t1 = [], [], []
    for i, ts in enumerate(splits):
        ts = np.unique(ts)
        seg_of.append(np.full(len(ts) - 1, i))
        t0.append(ts[:-1])
        t1.append(ts[1:])
    seg_of, t0, t1 = np.concatenate(seg_of), np.concatenate(t0), np.concatenate(t1)
    P0 = A[seg_of] + t0[:, None] * R[seg_of]
    P1 = A[seg_of] + t1[:, None] * R[seg_of]
    P0[t0 == 0] = A[seg_of[t0 == 0]]
    P1[t1 == 1] = B[seg_of[t1 == 1]]
    # merge end points closer than eps into nodes, original corners taking precedence
    pts = np.concatenate([P0, P1])
    original = np.concatenate([t0 == 0, t1 == 1])
    pairs = cKDTree(pts).query_pairs(eps, output_type="ndarray")
    n = len(pts)
    G = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(G, directed=False)
    pref = np.lexsort((np.arange(n), ~original))
    _, first = np.unique(label[pref], return_index=True)
    node_pos = pts[pref[first]]  # label values are 0..c-1, np.unique sorts them
    e0, e1 = label[: len(P0)], label[len(P0):]
    nz = e0 != e1
    e0, e1, seg_of = e0[nz], e1[nz], seg_of[nz]
    if len(e0) == 0:
        return []
    # keep the pieces that separate inside from outside, with the region on their left
    t_mid = 0.5 * (t0 + t1)[nz]
    mid = A[seg_of] + t_mid[:, None] * R[seg_of]
    wL, wR = _side_windings(mid, R[seg_of], A, B, eps)
    inL, inR = inside(wL), inside(wR)
    keep = inL != inR
    E = np.where(inL[keep, None], np.stack([e0, e1], 1)[keep], np.stack([e1, e0], 1)[keep])
    if len(E) == 0:
        return []
    E = np.unique(E, axis=0)
    return [node_pos[l] for l in _chain(E, node_pos)]


def offset_polygon(P, d_mm: float) -> np.ndarray:
    """Offset of the simple closed polygon P (k,2) by d_mm outward (> 0) or inward (< 0) -> (k',2).

    P is read as counter-clockwise (a clockwise P is reversed first); the result is
    counter-clockwise and simple.  Convex corners get a miter, cut square at 2 d_mm from
    the corner when longer; concave corners the exact intersection of the offset edges.
    Growing returns the outer boundary only (a hole closed off by the growth is
    dropped); shrinking returns the largest piece left, or an empty (0,2) array.
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 2:
        raise BolusError(f"a polygon must be a (k, 2) array, got shape {P.shape}")
    if not np.all(np.isfinite(P)) or not np.isfinite(d_mm):
        raise BolusError("the polygon or the offset distance is not finite")
    scale = float(np.ptp(P, axis=0).max()) + abs(d_mm) if len(P) else 0.0
    eps = 1e-9 * max(scale, 1e-9)
    P = _simplify(P, eps)
    if len(P) < 3 or abs(signed_area(P)) <= eps * scale:
        raise BolusError("the outline to offset has no area (fewer than three distinct corners)")
    if signed_area(P) < 0:
        P = P[::-1]
    if d_mm == 0:
        return P.copy()
    Q = P if d_mm > 0 else P[::-1]  # push edges to their right: outward for CCW, inward for CW
    raw = _raw_offset(Q, abs(d_mm))
    raw = raw[np.linalg.norm(raw - np.roll(raw, 1, axis=0), axis=1) > eps]
    A, B = raw, np.roll(raw, -1, axis=0)
    inside = (lambda w: w > 0) if d_mm > 0 else (lambda w: w < 0)
    loops = [_simplify(L, eps) for L in _region_boundary(A, B, inside, eps)]
    loops = [L for L in loops if len(L) >= 3]
    area = np.array([signed_area(L) for L in loops])
    if not len(loops) or area.max() <= eps * scale:
        return np.zeros((0, 2))
    return loops[int(np.argmax(area))]


# --------------------------------------------------------------------------- SVG
def _fmt(v: float, decimals: int) -> str:
    s = f"{v:.{decimals}f}"
    return s[1:] if s.startswith("-") and float(s) == 0 else s


def _path_d(P: np.ndarray, decimals: int) -> str:
    f = [f"{_fmt(x, decimals)} {_fmt(y, decimals)}" for x, y in P]
    return "M " + " L ".join(f) + " Z"


def _label_place(UV: np.ndarray, F: np.ndarray, loops: list[np.ndarray], text_w: float, text_h: float):
    """Where to put a text block of text_w x text_h mm on the island: ``(point (2,), scale)``.

    Candidates are triangle centroids and a grid of points inside the island; among those
    where the text fits best (scale 1 if it fits, else shrunk to the room left and right,
    above and below the point, never below 0.4) the one nearest the outer loop's
    centroid is taken.
    """
    P = loops[0]
    X = P - P.mean(axis=0)
    cr = X[:, 0] * np.roll(X[:, 1], -1) - np.roll(X[:, 0], -1) * X[:, 1]
    a = cr.sum() / 2
    centre = P.mean(axis=0) + (((X + np.roll(X, -1, axis=0)) * cr[:, None]).sum(0) / (6 * a) if abs(a) > 1e-12 else 0)
    A = np.concatenate(loops)
    B = np.concatenate([np.roll(L, -1, axis=0) for L in loops])
    lo, hi = A.min(axis=0), A.max(axis=0)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 42)[1:-1], np.linspace(lo[1], hi[1], 42)[1:-1])
    grid_pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    grid_pts = grid_pts[_winding(grid_pts, A, B) == 1]
    cand = np.concatenate([UV[F].mean(axis=1)[:: max(1, len(F) // 2000)], grid_pts])
    length = np.linalg.norm(B - A, axis=1)
    step = max(length.sum() / 5000, 1e-6)
    k = np.maximum(1, np.ceil(length / step).astype(np.int64))
    seg = np.repeat(np.arange(len(A)), k)
    t = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) / np.repeat(k, k)
    dist = cKDTree(A[seg] + t[:, None] * (B - A)[seg]).query(cand)[0]
    off = np.linalg.norm(cand - centre, axis=1)
    pick = np.unique(np.concatenate([np.argsort(-dist)[:60], np.argsort(off - 3 * dist)[:60]]))
    cand, off = cand[pick], off[pick]

    def room(axis):  # (c,) free length through each candidate along the axis, centred on it
        o = 1 - axis
        lo_, hi_ = np.minimum(A[:, o], B[:, o]), np.maximum(A[:, o], B[:, o])
        q = cand[:, None, :]
        hit = (lo_ <= q[..., o]) & (hi_ > q[..., o])
        with np.errstate(divide="ignore", invalid="ignore"):
            x = A[:, axis] + (q[..., o] - A[:, o]) / (B[:, o] - A[:, o]) * (B[:, axis] - A[:, axis])
        rel = np.where(hit, x - q[..., axis], np.nan)
        before = np.nanmin(np.where(rel < 0, -rel, np.inf), axis=1)
        after = np.nanmin(np.where(rel > 0, rel, np.inf), axis=1)
        return 2 * np.minimum(before, after)

    fit = np.minimum(1.0, np.minimum(0.9 * room(0) / max(text_w, 1e-9), 0.9 * room(1) / max(text_h, 1e-9)))
    best = np.flatnonzero(fit >= fit.max() * (1 - 1e-9))
    i = best[np.argmin(off[best])]
    return cand[i], float(np.clip(fit[i], 0.4, 1.0))


def _safe_id(label: str, taken: set) -> str:
    base = "patch-" + (re.sub(r"[^A-Za-z0-9_.-]", "_", label) or "_")
    name, k = base, 2
    while name in taken:
        name, k = f"{base}-{k}", k + 1
    taken.add(name)
    return name


def _metrics_text(EL, EA) -> str | None:
    parts = [f"{key} {100 * float(v):.2f} %" for key, v in (("EL", EL), ("EA", EA)) if v is not None]
    return " · ".join(parts) or None


def pattern_svg(islands, seam_allowance_mm: float = 0.0, title: str = "", margin_mm: float = 10.0,
                decimals: int = 3, path_decimals: int = 5) -> str:
    """SVG document (str) of laid-out islands at true scale.

    islands: list of dicts ``{"UV": (n,2) mm, "F": (m,3), "label": str, "EL": float,
    "EA": float}`` in pattern coordinates (already laid out); EL and EA are ratios
    (0.0123 is shown as "EL 1.23 %"), either may be missing.  The page is
    ``margin_mm`` around the pattern plus a footer with the 50 mm scale bar; its width
    and height are in mm and the viewBox in mm, +y of the pattern is up on paper.
    Numbers are written with ``decimals`` decimals, outline coordinates with
    ``path_decimals``: rounding every corner of a ragged 250-corner outline to 1 um
    changes its perimeter by up to about 0.02 mm, to 0.01 um by about 1e-4 mm.
    """
    if not len(islands):
        raise BolusError("there is no pattern piece to export")
    d = float(seam_allowance_mm)
    if not np.isfinite(d) or d < 0:
        raise BolusError(f"the seam allowance must be a length >= 0 mm, got {seam_allowance_mm}")
    m = float(margin_mm)
    if not np.isfinite(m) or m < 0:
        raise BolusError(f"the margin must be a length >= 0 mm, got {margin_mm}")
    pieces = []
    for i, isl in enumerate(islands):
        try:
            UV, F = _as_flat_mesh(isl["UV"], isl["F"])
        except KeyError as exc:
            raise BolusError(f"pattern piece {i} has no {exc.args[0]!r} array") from None
        loops = outline_loops(UV, F)
        seams = []
        if d > 0:
            for L in loops:
                if signed_area(L) > 0:
                    seams.append(offset_polygon(L, d))
                else:  # a hole: the allowance goes into it
                    S = offset_polygon(L[::-1], -d)
                    if len(S):
                        seams.append(S[::-1])
        label = str(isl.get("label", i))
        pieces.append((UV, F, loops, seams, label, _metrics_text(isl.get("EL"), isl.get("EA"))))
    allpts = np.concatenate([np.concatenate(p[2] + p[3]) for p in pieces])
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    ox, oy = round(m - lo[0], decimals), round(m + hi[1], decimals)  # paper = (x + ox, oy - y)

    def paper(P):
        P = np.asarray(P, dtype=np.float64)
        return np.stack([P[:, 0] + ox, oy - P[:, 1]], axis=1)

    content_w, content_h = hi - lo
    fs_label, fs_metrics, fs_note = 5.0, 3.5, 3.0
    y_bar = m + content_h + 10.0
    y_note = y_bar + 7.0
    y_title = y_note + 6.0
    footer_w = max(SCALE_BAR_MM + 15.0, 0.6 * fs_note * len(PRINT_NOTE), 0.6 * 4.0 * len(title))
    W = max(content_w + 2 * m, footer_w + 2 * m)
    H = (y_title if title else y_note) + m
    f = lambda v: _fmt(v, decimals)  # noqa: E731

    root = ET.Element("svg", {
        "xmlns": SVG_NS, "version": "1.1",
        "width": f"{f(W)}mm", "height": f"{f(H)}mm", "viewBox": f"0 0 {f(W)} {f(H)}",
    })
    ET.SubElement(root, "title").text = title or "Bolus pattern"
    ET.SubElement(root, "desc").text = (
        "Bolus pattern at true scale: 1 user unit = 1 mm. Solid lines are cut lines, dashed lines the "
        f"seam allowance. {PRINT_NOTE[0].upper() + PRINT_NOTE[1:]}.")
    ET.SubElement(root, "metadata", {"id": "bolus-frame"}).text = json.dumps(
        {"units": "mm", "paper_x": "x + ox", "paper_y": "oy - y", "ox": ox, "oy": oy,
         "seam_allowance_mm": d})
    g_all = ET.SubElement(root, "g", {"id": "patches"})
    taken: set = set()
    for UV, F, loops, seams, label, metrics in pieces:
        g = ET.SubElement(g_all, "g", {"id": _safe_id(label, taken), "class": "patch"})
        for L in loops:
            ET.SubElement(g, "path", {
                "class": "cut", "d": _path_d(paper(L), path_decimals), "fill": "none", "stroke": "#000000",
                "stroke-width": f(CUT_STROKE_MM), "stroke-linejoin": "round"})
        for S in seams:
            ET.SubElement(g, "path", {
                "class": "seam", "d": _path_d(paper(S), path_decimals), "fill": "none", "stroke": "#000000",
                "stroke-width": f(SEAM_STROKE_MM), "stroke-dasharray": "2 1"})
        text_w = max(0.62 * fs_label * len(label), 0.55 * fs_metrics * len(metrics or ""))
        c, k = _label_place(UV, F, loops, text_w, 10.0 if metrics else 5.0)
        c = paper(c[None])[0]
        common = {"text-anchor": "middle", "font-family": "sans-serif", "fill": "#000000"}
        ET.SubElement(g, "text", {"class": "label", "x": f(c[0]), "y": f(c[1] - (0.5 if metrics else -1.8) * k),
                                  "font-size": f(fs_label * k), "font-weight": "bold", **common}).text = label
        if metrics:
            ET.SubElement(g, "text", {"class": "metrics", "x": f(c[0]), "y": f(c[1] + 4.0 * k),
                                      "font-size": f(fs_metrics * k), **common}).text = metrics
    g = ET.SubElement(root, "g", {"id": "scale"})
    x0, x1 = m, m + SCALE_BAR_MM
    ET.SubElement(g, "line", {"id": "scale-bar", "x1": f(x0), "y1": f(y_bar), "x2": f(x1), "y2": f(y_bar),
                              "stroke": "#000000", "stroke-width": "0.5"})
    for x in (x0, x1):
        ET.SubElement(g, "line", {"class": "tick", "x1": f(x), "y1": f(y_bar - 1.5), "x2": f(x),
                                  "y2": f(y_bar + 1.5), "stroke": "#000000", "stroke-width": "0.3"})
    text = {"font-family": "sans-serif", "fill": "#000000"}
    ET.SubElement(g, "text", {"id": "scale-label", "x": f(x1 + 3.0), "y": f(y_bar + 1.2),
                              "font-size": f(fs_metrics), **text}).text = f"{SCALE_BAR_MM:g} mm"
    ET.SubElement(g, "text", {"id": "print-note", "x": f(x0), "y": f(y_note),
                              "font-size": f(fs_note), **text}).text = PRINT_NOTE
    if title:
        ET.SubElement(g, "text", {"id": "pattern-title", "x": f(x0), "y": f(y_title),
                                  "font-size": f(4.0), **text}).text = title
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


_TOKEN = re.compile(r"[A-Za-z]|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _parse_d(d: str) -> list[np.ndarray]:
    """Sub-paths [(k,2)] of an SVG path made of M/L/H/V/Z commands (absolute or relative)."""
    toks = _TOKEN.findall(d)
    subpaths, cur, pos, cmd, i = [], [], np.zeros(2), None, 0
    while i < len(toks):
        t = toks[i]
        if t.isalpha():
            cmd, i = t, i + 1
            if cmd in "Zz":
                if cur:
                    subpaths.append(np.array(cur))
                    pos = np.array(cur[0])
                cur = []
            elif cmd not in "MmLlHhVv":
                raise BolusError(f"unsupported SVG path command {cmd!r} (only straight lines are read)")
            continue
        if cmd is None or cmd in "Zz":
            raise BolusError("malformed SVG path data")
        rel = cmd.islower()
        if cmd in "MmLl":
            p = np.array([float(toks[i]), float(toks[i + 1])]) + (pos if rel else 0)
            i += 2
            if cmd in "Mm":
                if cur:
                    subpaths.append(np.array(cur))
                cur = []
                cmd = "l" if rel else "L"  # further pairs are line-tos
        else:
            v = float(toks[i]) + (pos[0 if cmd in "Hh" else 1] if rel else 0)
            i += 1
            p = np.array([v, pos[1]]) if cmd in "Hh" else np.array([pos[0], v])
        cur.append(p)
        pos = p
    if cur:
        subpaths.append(np.array(cur))
    out = []
    for P in subpaths:
        if len(P) > 1 and np.allclose(P[0], P[-1], rtol=0, atol=1e-12):
            P = P[:-1]
        out.append(P)
    return out


def svg_outline_paths(svg_text: str, kind: str = "cut") -> list[np.ndarray]:
    """Cut lines (or ``kind="seam"``) of a `pattern_svg` document as polylines [(k,2)] in pattern mm.

    Undoes the margin and the y flip recorded in the document, so the loops come back
    in the coordinates the islands were given in (to the written precision), in order.
    """
    try:
        root = ET.fromstring(svg_text)
    except ET.ParseError as exc:
        raise BolusError(f"not a readable SVG document: {exc}") from None
    ox, oy = 0.0, None
    for el in root.iter():
        if el.tag.rsplit("}", 1)[-1] == "metadata" and el.get("id") == "bolus-frame":
            frame = json.loads(el.text)
            ox, oy = float(frame["ox"]), float(frame["oy"])
    if oy is None:  # not written by pattern_svg: flip about the page height only
        oy = float(root.get("viewBox", "0 0 0 0").split()[3])
    out = []
    for el in root.iter():
        if el.tag.rsplit("}", 1)[-1] == "path" and kind in (el.get("class") or "").split():
            for P in _parse_d(el.get("d", "")):
                out.append(np.stack([P[:, 0] - ox, oy - P[:, 1]], axis=1))
    return out
