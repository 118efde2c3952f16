"""Matching marks of a cut pattern: seams between pieces, darts and joins within a piece.

`pattern_marks` reads the laid-out pattern mesh (UV (n,2) mm, F (m,3), the piece of
every triangle and the source-mesh vertex of every pattern vertex) and finds which
outline edges were one edge of the skin before cutting: an outline edge (a, b) whose
source pair {sv[a], sv[b]} is an outline edge a second time.

* between two pieces it is part of a **seam**: the consecutive shared edges of one pair
  of pieces form one chain; both sides get the same number, so the user knows which
  edges to butt together;
* within one piece it is a **dart** when the chain's two sides end at one pattern vertex
  (the apex: the dart opened into a V, seed 4.1.2), else a **join**
  (a cut that made a tube or a ring into a disk), numbered like the seams.

Every mark also keeps where to draw it (`PatternMarks.UV`; for a seam the tick's place on
each side -- the same source position near the chain's middle, away from sharp corners --
and the inward normal there), so the drawing needs no mesh.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import BolusError
from ..mesh.boundary import edge_paths
from ..unfold.overlap import as_pattern_arrays

__all__ = ["Seam", "DartMark", "PatternMarks", "pattern_marks"]

#: a chain turning more than this (rad) at a vertex has a corner there; ticks keep away from it
CORNER_TURN = np.radians(30.0)
#: how far (mm along the chain) a tick keeps from a corner, at most a quarter of the chain
CORNER_CLEARANCE_MM = 8.0


@dataclass
class Seam:
    """A numbered seam (piece_a != piece_b) or join (piece_a == piece_b).

    chain_a, chain_b : (k,) pattern vertex ids, the same source vertices in the same order
    mid_a, mid_b : (2,) mm, where the tick goes on each side: the same source position, near
        the chain's arc-length middle but away from its sharp corners (`_mark_place`)
    normal_a, normal_b : (2,) unit normals there, pointing into the piece
    """

    number: int
    piece_a: int
    piece_b: int
    chain_a: np.ndarray
    chain_b: np.ndarray
    mid_a: np.ndarray = field(default_factory=lambda: np.zeros(2))
    mid_b: np.ndarray = field(default_factory=lambda: np.zeros(2))
    normal_a: np.ndarray = field(default_factory=lambda: np.zeros(2))
    normal_b: np.ndarray = field(default_factory=lambda: np.zeros(2))

    @property
    def is_join(self) -> bool:
        return self.piece_a == self.piece_b


@dataclass
class DartMark:
    """An opened dart: leg_a, leg_b (k,) pattern vertex ids from the outline to the apex (apex last)."""

    piece: int
    apex: int
    leg_a: np.ndarray
    leg_b: np.ndarray


@dataclass
class PatternMarks:
    """seams: [Seam] numbered 1..s (joins included); darts: [DartMark]; UV (n,2) mm the positions the ids index."""

    seams: list
    darts: list
    UV: np.ndarray | None = None


def _boundary_edges(F: np.ndarray):
    """Outline edges (b,2) oriented as in their triangle, and that triangle (b,)."""
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    tri = np.tile(np.arange(len(F)), 3)
    key = np.sort(E, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    once = cnt[inv.ravel()] == 1
    return E[once], tri[once]


def _turns(P: np.ndarray) -> np.ndarray:
    """(k,) turning angle (rad) of the polyline P (k,2) at each vertex (0 at both ends)."""
    d = np.diff(P, axis=0)
    ang = np.arctan2(d[:, 1], d[:, 0])
    t = np.abs((np.diff(ang) + np.pi) % (2 * np.pi) - np.pi)
    return np.r_[0.0, t, 0.0]


def _mark_place(UV, ca, cb, third_a, third_b):
    """Where the seam's tick goes on both sides, at the same source position: edge i of the chain
    and the share t along it, near the chain's arc-length middle but at least `CORNER_CLEARANCE_MM`
    (at most a quarter of the chain) from a sharp corner (a turn above `CORNER_TURN` on either side).
    Returns (mid_a, normal_a, mid_b, normal_b), normals (unit) pointing into each side's piece."""
    Pa, Pb = UV[ca], UV[cb]
    seg = np.linalg.norm(np.diff(Pa, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    half = s[-1] / 2
    corners = s[(_turns(Pa) > CORNER_TURN) | (_turns(Pb) > CORNER_TURN)]
    clear = min(CORNER_CLEARANCE_MM, s[-1] / 4)
    cand = np.r_[half, (s[:-1] + s[1:]) / 2, s[1:-1]]  # the middle, edge midpoints, inner vertices
    if len(corners):
        ok = np.abs(cand[:, None] - corners[None]).min(axis=1) >= clear
        if ok.any():
            cand = cand[ok]
    pos = cand[np.argmin(np.abs(cand - half))]
    i = int(min(np.searchsorted(s, pos, side="right") - 1, len(seg) - 1))
    t = (pos - s[i]) / seg[i] if seg[i] > 0 else 0.0
    out = []
    for P, third in ((Pa, third_a), (Pb, third_b)):
        mid = P[i] + t * (P[i + 1] - P[i])
        d = P[i + 1] - P[i]
        n = np.array([-d[1], d[0]]) / max(float(np.linalg.norm(d)), 1e-300)
        if np.dot(UV[third[i]] - P[i], n) < 0:
            n = -n
        out += [mid, n]
    return tuple(out)


def _check_input(UV, F, piece, source_vertex):
    """The input checks of `pattern_marks`: (UV (n,2) mm, F (m,3), piece (m,), sv (n,))."""
    UV = np.asarray(UV, dtype=np.float64)
    if UV.ndim == 2 and UV.shape[1] > 2:
        UV = UV[:, :2]
    UV, F = as_pattern_arrays(UV, F)
    piece = np.asarray(piece)
    sv = np.asarray(source_vertex)
    if piece.shape != (len(F),) or not np.issubdtype(piece.dtype, np.integer):
        raise BolusError(f"the pattern needs one integer piece per triangle ({len(F)}), got shape {piece.shape}")
    if sv.shape != (len(UV),) or not np.issubdtype(sv.dtype, np.integer):
        raise BolusError(f"the pattern needs one integer source vertex per vertex ({len(UV)}), got shape {sv.shape}")
    return UV, F, piece, sv


def _shared_edges(E, tri, piece, sv) -> dict:
    """Outline edges that were one source edge, grouped by the (sorted) pair of pieces:
    {(pa, pb): {(s0, s1) source edge: (i, j) its two outline edges, i on piece pa}}.
    A source edge found on the outline other than exactly twice is left out."""
    skey = np.sort(sv[E], axis=1)
    groups: dict[tuple[int, int], list[int]] = {}
    for i, k in enumerate(map(tuple, skey.tolist())):
        if k[0] != k[1]:
            groups.setdefault(k, []).append(i)
    by_pair: dict[tuple[int, int], dict[tuple[int, int], tuple[int, int]]] = {}
    for k, idx in groups.items():
        if len(idx) != 2:
            continue
        i, j = idx
        pi, pj = int(piece[tri[i]]), int(piece[tri[j]])
        if pi > pj:
            i, j, pi, pj = j, i, pj, pi
        by_pair.setdefault((pi, pj), {})[k] = (i, j)
    return by_pair


def _side_vertex(E, sv, e: int, s: int) -> int:
    """The pattern vertex of outline edge e at source vertex s."""
    return int(E[e, 0] if sv[E[e, 0]] == s else E[e, 1])


def _connected_runs(E, sv, path: list[int], pairs: list[list[int]], same_piece: bool) -> list[tuple[int, int]]:
    """A source path's edge pairs (one [side 0, side 1] per edge) split into runs [r0, r1) along
    which both sides stay connected (a chain may run on through another outline); within one
    piece the pairs are first ordered (in place) so that each side is connected."""
    if same_piece:
        for q in range(1, len(pairs)):
            s = path[q]
            if _side_vertex(E, sv, pairs[q][0], s) != _side_vertex(E, sv, pairs[q - 1][0], s):
                pairs[q].reverse()
    runs, start = [], 0
    for q in range(1, len(pairs)):
        s = path[q]
        if any(_side_vertex(E, sv, pairs[q][c], s) != _side_vertex(E, sv, pairs[q - 1][c], s) for c in (0, 1)):
            runs.append((start, q))
            start = q
    runs.append((start, len(pairs)))
    return runs


def _run_chains(E, sv, third, path, pairs, r0: int, r1: int):
    """The two sides of run [r0, r1): chains (k,) of pattern vertex ids in the source path's order,
    and for each edge the third vertex of its triangle (the piece's side)."""
    chains, thirds = [], []
    for c in (0, 1):
        ch = [_side_vertex(E, sv, pairs[q][c], path[q]) for q in range(r0, r1)]
        ch.append(_side_vertex(E, sv, pairs[r1 - 1][c], path[r1]))
        chains.append(np.array(ch, dtype=np.int64))
        thirds.append(np.array([third[pairs[q][c]] for q in range(r0, r1)]))
    return chains, thirds


def _mark_run(UV, sv, pa: int, pb: int, chains, thirds, seams_raw: list, darts: list) -> None:
    """Append the run's mark: a dart (within one piece, the sides meet at one end only: the
    apex), nothing (a slit closed at both ends) or a seam / join with its tick places."""
    ca, cb = chains
    if pa == pb and (ca[0] == cb[0]) != (ca[-1] == cb[-1]):
        if ca[0] == cb[0]:
            ca, cb = ca[::-1], cb[::-1]
        darts.append((pa, int(sv[ca[-1]]), DartMark(pa, int(ca[-1]), ca, cb)))
        return
    if pa == pb and ca[0] == cb[0]:  # a slit closed at both ends: nothing to match apart
        return
    mid_a, n_a, mid_b, n_b = _mark_place(UV, ca, cb, thirds[0], thirds[1])
    seams_raw.append(((pa, pb, int(sv[np.concatenate([ca])].min())),
                      dict(piece_a=pa, piece_b=pb, chain_a=ca, chain_b=cb, mid_a=mid_a, mid_b=mid_b,
                           normal_a=n_a, normal_b=n_b)))


def pattern_marks(UV, F, piece, source_vertex) -> PatternMarks:
    """Seams, joins and darts of the pattern mesh.

    Parameters
    ----------
    UV : (n,2) mm pattern positions (only x, y of a wider array are used)
    F : (m,3) int pattern triangles
    piece : (m,) int piece of every triangle
    source_vertex : (n,) int source-mesh vertex of every pattern vertex

    Returns
    -------
    PatternMarks: seams and joins numbered 1..s in the order (smaller piece, larger piece,
    smallest source vertex of the chain); darts in the order (piece, apex's source vertex).
    A source edge found on the outline more than twice is left unmarked (ambiguous).
    """
    UV, F, piece, sv = _check_input(UV, F, piece, source_vertex)
    if len(F) == 0:
        return PatternMarks([], [], UV.copy())
    E, tri = _boundary_edges(F)
    third = F[tri].sum(axis=1) - E.sum(axis=1)
    seams_raw, darts = [], []
    for (pa, pb), edges in sorted(_shared_edges(E, tri, piece, sv).items()):
        for path in edge_paths(list(edges)):
            src_edges = [tuple(sorted((path[q], path[q + 1]))) for q in range(len(path) - 1)]
            pairs = [list(edges[k]) for k in src_edges]
            for r0, r1 in _connected_runs(E, sv, path, pairs, pa == pb):
                chains, thirds = _run_chains(E, sv, third, path, pairs, r0, r1)
                _mark_run(UV, sv, pa, pb, chains, thirds, seams_raw, darts)
    seams_raw.sort(key=lambda t: t[0])
    seams = [Seam(number=i + 1, **kw) for i, (_, kw) in enumerate(seams_raw)]
    darts.sort(key=lambda t: t[:2])
    return PatternMarks(seams, [d for *_, d in darts], UV.copy())
