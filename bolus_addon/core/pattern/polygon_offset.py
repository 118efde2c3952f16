"""Offsetting a simple polygon: the seam allowance of a pattern piece.

* `offset_polygon` - a polygon grown (or shrunk) by a distance, with miter joins cut
  square at `MITER_LIMIT` times the distance.  The raw offset curve (edges pushed out,
  miter or cut miter at convex corners, ``a -> corner -> b`` at concave ones) is, as a
  1-chain, the sum of the polygon, one rectangle per edge and one wedge per convex
  corner; so its winding number is positive exactly on their union, the grown polygon
  (the method of Clipper's offsetting).  Its self-intersections are resolved by
  splitting every segment where others cross it and keeping the pieces that separate
  winding > 0 from winding <= 0: the result is a simple polygon even where concave
  corners or narrow notches make the raw curve loop over itself.
* `winding_numbers` - winding numbers of points about a set of directed segments.
* `signed_area` - the shoelace area of a closed polygon.

Polygons are (k,2) arrays of corners in mm, the first corner not repeated at the end.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..errors import BolusError
from ..mesh.geometry2d import cross2d

__all__ = ["MITER_LIMIT", "offset_polygon", "signed_area", "winding_numbers"]

#: a miter longer than MITER_LIMIT * d is cut square at that distance (Clipper's default is 2 too)
MITER_LIMIT = 2.0
#: relative tolerance of the geometry: points closer than REL_EPS * (polygon size + |d|) are one point
REL_EPS = 1e-9
#: two directions are parallel when |sin| is below this (double precision, well above rounding)
PARALLEL_SIN = 1e-12
#: (points x segments) entries per block of the winding tests: ~16 MB of float64 per array
WINDING_BLOCK = 2_000_000
#: (segments x segments) entries per block of the intersection search: ~8 MB per array
SPLIT_BLOCK = 1_000_000


def signed_area(P) -> float:
    """Shoelace area of the closed polygon P (k,2): positive when counter-clockwise, 0 for k < 3."""
    P = np.asarray(P, dtype=np.float64)
    if len(P) < 3:
        return 0.0
    Q = P - P.mean(axis=0)
    x, y = Q[:, 0], Q[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def winding_numbers(Q, A, B) -> np.ndarray:
    """Winding numbers (t,) int of points Q (t,2) about the directed segments A -> B (s,2).

    For closed loops this is the usual winding number (0 outside); points on a segment
    may count either way.  BolusError for a non-finite point or segment end.
    """
    Q, A, B = (np.asarray(X, dtype=np.float64).reshape(-1, 2) for X in (Q, A, B))
    for what, X in (("point", Q), ("segment start", A), ("segment end", B)):
        bad = np.nonzero(~np.isfinite(X).all(axis=1))[0]
        if len(bad):
            raise BolusError(f"{what} {int(bad[0])} is not finite (NaN or infinite)")
    w = np.zeros(len(Q), dtype=np.int64)
    if len(A) == 0:
        return w
    R = B - A
    step = max(1, WINDING_BLOCK // len(A))
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
    for idx in np.array_split(order, int(np.ceil(np.sqrt(len(Q))))):
        if len(idx) == 0:
            continue
        q, t = Q[idx], T[idx]
        cand = np.flatnonzero((yhi >= q[0, 1] - eps) & (ylo <= q[-1, 1] + eps))
        if len(cand) == 0:
            continue
        a, r, RRc = A[cand], R[cand], RR[cand]
        rr = np.sqrt(RRc)
        qx, qy = q[:, 0:1], q[:, 1:2]
        cross = cross2d(r, q[:, None, :] - a)  # (c, s) > 0: q left of the segment
        up = (a[:, 1] <= qy) & (a[:, 1] + r[:, 1] > qy)
        down = (a[:, 1] + r[:, 1] <= qy) & (a[:, 1] > qy)
        tn = t / np.linalg.norm(t, axis=1, keepdims=True)
        parallel = np.abs(cross2d(tn[:, None, :], r)) <= REL_EPS * rr
        proj = (qx - a[:, 0]) * r[:, 0] + (qy - a[:, 1]) * r[:, 1]
        on = parallel & (np.abs(cross) <= eps * rr) & (proj >= 0) & (proj <= RRc)
        w[idx] = ((up & (cross > 0) & ~on).sum(axis=1) - (down & (cross < 0) & ~on).sum(axis=1))
        jump[idx] = np.where(on, np.where(tn @ r.T > 0, 1, -1), 0).sum(axis=1)
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


def _chain_segments(edges: np.ndarray, pos: np.ndarray) -> list[np.ndarray]:
    """Directed edges (b,2) between planar nodes pos (N,2), in- and out-degrees balanced -> closed loops.

    This walks the pieces of a self-intersecting offset curve, a planar segment graph
    with no triangles behind it, where several loops may meet at a node: the walk takes
    the first edge clockwise from the one it came in on (so loops touching at a node
    stay separate).  Boundary loops of a triangle mesh are `cutting.boundary_loops`.
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
            cand = order[np.searchsorted(starts, v):np.searchsorted(starts, v, side="right")]
            cand = cand[~used[cand]]
            if len(cand) == 0:  # pragma: no cover - cannot happen with balanced degrees
                raise BolusError("the offset outline does not close")
            if len(cand) > 1:
                back = pos[u] - pos[v]
                out = pos[edges[cand, 1]] - pos[v]
                turn = (np.arctan2(back[1], back[0]) - np.arctan2(out[:, 1], out[:, 0])) % (2 * np.pi)
                turn[turn <= PARALLEL_SIN] = 2 * np.pi
                cand = cand[[np.argmin(turn)]]
            e = int(cand[0])
            used[e] = True
            loop.append(v)
        loops.append(np.asarray(loop, dtype=np.int64))
    return loops


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
        # distance of the point from the chord of its neighbours, and the point between them
        straight = (np.abs(cross2d(a, b)) <= tol * np.linalg.norm(c, axis=1)) & (np.einsum("ij,ij->i", a, b) > 0)
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
    spike = (np.abs(cross) <= PARALLEL_SIN) & (cos < 0)
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
        elif np.linalg.norm(pa[i] - pb[i]) <= PARALLEL_SIN * d:  # straight on
            pts.append(pa[i])
        else:
            pts.extend([pa[i], Q[i], pb[i]])
    return np.asarray(pts)


def _split_parameters(A: np.ndarray, B: np.ndarray, eps: float) -> list[list[float]]:
    """For every segment A -> B (s,2) the parameters t in [0, 1] where it must be split:
    its ends, where other segments cross it, and other segments' ends lying on it."""
    R = B - A
    RR = np.einsum("ij,ij->i", R, R)
    s = len(A)
    splits = [[0.0, 1.0] for _ in range(s)]
    step = max(1, SPLIT_BLOCK // s)
    for lo in range(0, s, step):
        hi = min(s, lo + step)
        Ri = R[lo:hi, None, :]
        D = A[None, :, :] - A[lo:hi, None, :]  # (c, s, 2): A_j - A_i
        den = cross2d(Ri, R[None, :, :])
        num_u = cross2d(D, Ri)
        ok = np.abs(den) > PARALLEL_SIN * np.sqrt(RR[lo:hi, None] * RR[None, :])
        with np.errstate(divide="ignore", invalid="ignore"):
            t, u = cross2d(D, R[None, :, :]) / den, num_u / den
        hit = ok & (t > -REL_EPS) & (t < 1 + REL_EPS) & (u > -REL_EPS) & (u < 1 + REL_EPS)
        # other segments' end points lying on segment i (touching, collinear overlaps)
        along = np.einsum("csk,ck->cs", D, R[lo:hi]) / RR[lo:hi, None]
        touch = (np.abs(num_u) / np.sqrt(RR[lo:hi, None]) <= eps) & (along > 0) & (along < 1)
        for mask, val in ((hit, np.clip(t, 0.0, 1.0)), (touch, along)):
            ci, cj = np.nonzero(mask)
            for a, tv in zip(ci + lo, val[ci, cj]):
                splits[a].append(float(tv))
    return splits


def _sub_segments(A: np.ndarray, B: np.ndarray, splits: list[list[float]]):
    """The pieces of the segments between their split parameters: (segment (q,), t0 (q,), t1 (q,),
    P0 (q,2), P1 (q,2)), original end points copied exactly."""
    seg_of, t0, t1 = [], [], []
    for i, ts in enumerate(splits):
        ts = np.unique(ts)
        seg_of.append(np.full(len(ts) - 1, i))
        t0.append(ts[:-1])
        t1.append(ts[1:])
    seg_of, t0, t1 = np.concatenate(seg_of), np.concatenate(t0), np.concatenate(t1)
    R = B - A
    P0 = A[seg_of] + t0[:, None] * R[seg_of]
    P1 = A[seg_of] + t1[:, None] * R[seg_of]
    P0[t0 == 0] = A[seg_of[t0 == 0]]
    P1[t1 == 1] = B[seg_of[t1 == 1]]
    return seg_of, t0, t1, P0, P1


def _merge_nodes(P0: np.ndarray, P1: np.ndarray, original: np.ndarray, eps: float):
    """End points P0, P1 (q,2) closer than eps merged into nodes, original corners (2q,) bool
    taking precedence: (node of P0 (q,), node of P1 (q,), node positions (N,2))."""
    pts = np.concatenate([P0, P1])
    pairs = cKDTree(pts).query_pairs(eps, output_type="ndarray")
    n = len(pts)
    G = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(G, directed=False)
    pref = np.lexsort((np.arange(n), ~original))
    _, first = np.unique(label[pref], return_index=True)
    return label[: len(P0)], label[len(P0):], pts[pref[first]]  # label values are 0..N-1, sorted


def _region_boundary(A: np.ndarray, B: np.ndarray, inside, eps: float) -> list[np.ndarray]:
    """Boundary loops [(k,2)] of {x : inside(winding of the segments A -> B (s,2) at x)}.

    Loops have the region on their left (outer loops counter-clockwise, holes clockwise).
    """
    seg_of, t0, t1, P0, P1 = _sub_segments(A, B, _split_parameters(A, B, eps))
    e0, e1, node_pos = _merge_nodes(P0, P1, np.concatenate([t0 == 0, t1 == 1]), eps)
    nz = e0 != e1
    e0, e1, seg_of = e0[nz], e1[nz], seg_of[nz]
    if len(e0) == 0:
        return []
    # keep the pieces that separate inside from outside, with the region on their left
    R = B - A
    mid = A[seg_of] + (0.5 * (t0 + t1)[nz])[:, None] * R[seg_of]
    wL, wR = _side_windings(mid, R[seg_of], A, B, eps)
    inL, inR = inside(wL), inside(wR)
    keep = inL != inR
    E = np.where(inL[keep, None], np.stack([e0, e1], 1)[keep], np.stack([e1, e0], 1)[keep])
    if len(E) == 0:
        return []
    return [node_pos[lp] for lp in _chain_segments(np.unique(E, axis=0), node_pos)]


def offset_polygon(P, d_mm: float) -> np.ndarray:
    """Offset of the simple closed polygon P (k,2) mm by d_mm outward (> 0) or inward (< 0).

    Parameters
    ----------
    P : (k,2) - read as counter-clockwise (a clockwise P is reversed first); repeated
        corners and corners on a straight line are dropped first
    d_mm : the distance; 0 returns the cleaned, counter-clockwise P

    Returns
    -------
    (k',2) counter-clockwise simple polygon.  Convex corners get a miter, cut square at
    `MITER_LIMIT` * d_mm from the corner when longer; concave corners the exact
    intersection of the offset edges.  Growing returns the outer boundary only (a hole
    closed off by the growth is dropped); shrinking returns the largest piece left, or
    an empty (0,2) array.  BolusError for NaN/inf, a wrong shape or a polygon without
    area (fewer than three distinct, non-collinear corners).
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 2:
        raise BolusError(f"a polygon must be a (k, 2) array, got shape {P.shape}")
    bad = np.nonzero(~np.isfinite(P).all(axis=1))[0]
    if len(bad) or not np.isfinite(d_mm):
        where = f"corner {int(bad[0])} is" if len(bad) else "the offset distance is"
        raise BolusError(f"{where} not finite (NaN or infinite)")
    scale = float(np.ptp(P, axis=0).max()) + abs(d_mm) if len(P) else 0.0
    eps = REL_EPS * max(scale, REL_EPS)
    P = _simplify(P, eps)
    if len(P) < 3 or abs(signed_area(P)) <= eps * scale:
        raise BolusError("the outline to offset has no area (fewer than three distinct corners off one line)")
    if signed_area(P) < 0:
        P = P[::-1]
    if d_mm == 0:
        return P.copy()
    Q = P if d_mm > 0 else P[::-1]  # push edges to their right: outward for CCW, inward for CW
    raw = _raw_offset(Q, abs(d_mm))
    raw = raw[np.linalg.norm(raw - np.roll(raw, 1, axis=0), axis=1) > eps]
    inside = (lambda w: w > 0) if d_mm > 0 else (lambda w: w < 0)
    loops = [_simplify(L, eps) for L in _region_boundary(raw, np.roll(raw, -1, axis=0), inside, eps)]
    loops = [L for L in loops if len(L) >= 3]
    area = np.array([signed_area(L) for L in loops])
    if not len(loops) or area.max() <= eps * scale:
        return np.zeros((0, 2))
    return loops[int(np.argmax(area))]
