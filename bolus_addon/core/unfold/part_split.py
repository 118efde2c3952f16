"""A large curved patch cut into spectral parts before darts and splits (sheet pieces of a whole face).

Darts and splits (`sheet_pieces`) refine one piece at a time from the angle sums, a trial
unfolding per change: right for a nose patch of a few thousand triangles, hopeless for a whole
face left in one patch (43k triangles and about 114 rad of angle defect: every trial costs
seconds and the piece limit is reached long before the error target).  Such a patch is first
cut the way the method cuts a region (seed ch. 4, `spectral.segment`: the saliency-aware
spectral clustering, borders along the salient lines), into about

    k = ceil(sum varpi / VARPI_PER_PART)        (sum varpi: eq. 4-2 at the analysis smoothing)

parts, and each part then gets darts and splits as a patch would.  A part that still misses the
target is cut in `RESPLIT_PARTS` again (up to `RESPLIT_DEPTH` times, while it has at least
`RESPLIT_MIN_TRIANGLES` and the cut leaves no sliver; a cut that makes its worst piece no better
is undone); a part still missing is reported by name with its figures, as any piece that misses.  The borders between parts are recorded as splits (excess 0), so the
pattern numbers them as seams like any other cut.

Measured (nefertiti's face, 43,196 triangles, 113.7 rad; the ICT face with its nostrils, 13,120;
max_el 2 %): 8 rad per part gave 15 and 10 parts, every piece within 2 % / 3 % after one re-cut
each; 12 rad left a part at 2.1 % after its re-cut and took twice as long; 6 rad left a nostril
part at 3.7 % (smaller parts leave the nostril's excess to fewer darts).
"""
from __future__ import annotations

import math
import re

import numpy as np

from ..analysis import saliency, spectral
from ..mesh.boundary import edge_paths
from ..mesh.topology import MeshTopology
from .sheet_records import EA_PER_EL, Dart, SheetPieces, Split
from .unfold import labelled_patches

__all__ = ["PART_MIN_TRIANGLES", "VARPI_PER_PART", "RESPLIT_PARTS", "RESPLIT_DEPTH", "RESPLIT_MIN_TRIANGLES",
           "PART_MIN_SHARE", "PART_MIN_FACES", "part_labels", "border_paths", "solve_in_parts", "merge_parts"]

#: patches below this many triangles go straight to darts and splits (the 17 hard nose, pocket
#: and finger patches of the benchmark have at most 2,207)
PART_MIN_TRIANGLES = 8_000
#: angle defect per spectral part, rad (module doc)
VARPI_PER_PART = 8.0
#: a part that misses the target is cut in this many again ...
RESPLIT_PARTS = 2
#: ... at most this many times, and only while it has at least this many triangles
RESPLIT_DEPTH = 5
RESPLIT_MIN_TRIANGLES = 60
#: no part smaller than this share of the patch's area (smaller clusters join a neighbour) or
#: than this many triangles (else the patch is not cut): a sliver is no piece to cut from sheet
PART_MIN_SHARE = 0.05
PART_MIN_FACES = 20
#: the saliency weight of the cut (eq. 4-5), as the segment operator's default
ETA = 5.0


def part_labels(V, F, parts: int | None, sigma_mm: float, rng=0, face_groups=None) -> np.ndarray | None:
    """Spectral parts of a patch: (m,) labels 0..p-1, or None when it stays whole.

    V (n,3) mm, F (m,3); parts: how many (None: from its angle defect, module doc, and only
    from `PART_MIN_TRIANGLES` triangles); sigma_mm: the analysis smoothing (eq. 4-1 on the
    smoothed copy); face_groups (m,): polygons kept whole.  None also when the clustering gives
    a single part or a part under `PART_MIN_FACES` triangles."""
    if parts is None:
        if len(F) < PART_MIN_TRIANGLES:
            return None
        ana = saliency.analyse(V, F, sigma_mm)
        parts = math.ceil(ana.sum_varpi / VARPI_PER_PART)
    else:
        ana = None
    if parts < 2:
        return None
    seg = spectral.segment(V, F, int(parts), eta=ETA, smoothing_mm=sigma_mm, rng=rng, face_groups=face_groups,
                           analysis=ana, min_patch_fraction=min(PART_MIN_SHARE, 0.5 / parts))
    if seg.patch_count < 2 or np.bincount(seg.face_labels).min() < PART_MIN_FACES:
        return None
    return seg.face_labels


def border_paths(V, F, labels, topo: MeshTopology | None = None) -> list[tuple[int, int, np.ndarray]]:
    """The borders between labelled parts as vertex paths: [(label a, label b, path (k,) into V)].

    Every edge between triangles of labels a < b belongs to exactly one path; a path runs
    between two ends (on the patch outline or where three parts meet) or closes on itself.
    topo: the `MeshTopology` of (V, F) if the caller has it."""
    topo = MeshTopology(V, F) if topo is None else topo
    ef = topo.edge_faces
    inner = (ef >= 0).all(axis=1)
    la, lb = labels[np.maximum(ef[:, 0], 0)], labels[np.maximum(ef[:, 1], 0)]
    out = []
    on = inner & (la != lb)
    pairs = np.unique(np.c_[np.minimum(la, lb), np.maximum(la, lb)][on], axis=0)
    for a, b in pairs:
        E = topo.edges[on & (np.minimum(la, lb) == a) & (np.maximum(la, lb) == b)]
        out += [(int(a), int(b), np.asarray(p, dtype=np.int64)) for p in edge_paths(E.tolist())]
    return out


def solve_in_parts(V, F, labels, solve, sigma_mm: float, groups=None, progress=None, depth: int = 0):
    """Sheet pieces of every part, parts that miss cut again (module doc).

    V (n,3), F (m,3), labels (m,) parts 0..p-1; solve(V, F, groups, progress) -> `SheetPieces`
    of one part (darts and splits); groups (m,) or None.  Returns the list of (faces (f,) into
    F, verts (j,) into V, `SheetPieces` of that part, its paths and vert_origin still in the
    part's own numbering), one entry per final part."""
    out = []
    for _k, p, _count, F_local, verts, sub in labelled_patches(F, labels, progress, "part"):
        faces = np.flatnonzero(labels == p)
        g = None if groups is None else groups[faces]
        Vp = V[verts]
        res = solve(Vp, F_local, g, _share(sub, 0.0, 0.5))
        again = None
        if not res.met and depth < RESPLIT_DEPTH and len(faces) >= RESPLIT_MIN_TRIANGLES:
            again = part_labels(Vp, F_local, RESPLIT_PARTS, sigma_mm, face_groups=g)
        found = [] if again is None else solve_in_parts(Vp, F_local, again, solve, sigma_mm, g,
                                                         _share(sub, 0.5, 1.0), depth + 1)
        if found and (all(r.met for _f, _v, r in found) or _worst([r for _f, _v, r in found]) < _worst([res])):
            out += [(faces[f2], verts[v2], r2) for f2, v2, r2 in found]
        else:  # not cut again, or the cut made it no better: the part as it was
            out.append((faces, verts, res))
    return out


def _worst(results) -> float:
    """The worst piece of `SheetPieces` results: max(EL, EA / EA_PER_EL), plus 1 if folded or overlapping."""
    return max(max(u.EL, u.EA / EA_PER_EL) + (1.0 if u.flipped or u.overlaps else 0.0)
               for r in results for u in r.unfoldings)


def _share(progress, lo: float, hi: float):
    """progress(f, text) mapped into [lo, hi] of the caller's (None stays None)."""
    if progress is None:
        return None
    return lambda f, text: progress(lo + (hi - lo) * min(max(float(f), 0.0), 1.0), text)


def merge_parts(V, F, parts, seconds: float) -> SheetPieces:
    """One `SheetPieces` of the whole patch from `solve_in_parts`' list: pieces numbered part by
    part, vertex indices into V, the borders between parts as splits (excess 0)."""
    piece = np.empty(len(F), dtype=np.int64)
    part = np.empty(len(F), dtype=np.int64)
    unf, darts, splits, reasons = [], [], [], []
    for j, (faces, verts, res) in enumerate(parts):
        first = len(unf)
        piece[faces] = first + res.piece
        part[faces] = j
        for u in res.unfoldings:
            u.vert_origin = verts[u.vert_origin]
            unf.append(u)
        darts += [Dart(first + d.piece, verts[d.path], d.defect) for d in res.darts]
        splits += [Split((first + s.pieces[0], first + s.pieces[1]), verts[s.path], s.excess) for s in res.splits]
        if res.reason:  # the part's piece numbers made the patch's
            reasons.append(re.sub(r"\bpiece (\d+) has", lambda m, f=first: f"piece {f + int(m.group(1))} has",
                                  res.reason))
    topo = MeshTopology(V, F)
    n = topo.n
    keys = topo.edges[:, 0] * n + topo.edges[:, 1]
    for _a, _b, path in border_paths(V, F, part, topo):
        e = int(np.searchsorted(keys, min(path[0], path[1]) * n + max(path[0], path[1])))
        fa, fb = topo.edge_faces[e]
        splits.append(Split((int(piece[fa]), int(piece[fb])), path, 0.0))
    return SheetPieces(piece, unf, darts, splits, not reasons, "; ".join(reasons), seconds)
