"""The pattern's islands and sheet pieces: one island per patch, the pieces of every island laid out."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import BolusError
from ..mesh.topology import MeshTopology, check_mesh


@dataclass
class PatchIslands:
    """islands (m,) island of every triangle, -1 outside the patches; island_patch (k,) the
    patch of every island; left_out: how many faces (face groups, e.g. polygons) lie outside."""

    islands: np.ndarray
    island_patch: np.ndarray
    left_out: int

    @property
    def count(self) -> int:
        return len(self.island_patch)


def patch_islands(V, F, tri_labels, face_groups=None, vert_ids=None) -> PatchIslands:
    """Split every patch into its edge-connected pieces.

    Parameters
    ----------
    V : (n,3) mm, F : (m,3) int - the region (checked by `topology.check_mesh`; zero-area
        triangles are refused by name, they have no shape to unfold)
    tri_labels : (m,) int - patch of every triangle, -1 outside every patch
    face_groups : (m,) int, optional - the face (polygon) of every triangle, for `left_out`
    vert_ids : (n,) int, optional - the user's index of every vertex, for the messages

    Returns
    -------
    PatchIslands; islands are numbered in the order of their lowest component id.
    """
    V, F = check_mesh(V, F, "the region", nondegenerate=False)
    topo = MeshTopology(V, F)
    topo.require_nondegenerate("the region", vert_ids)
    labels = np.asarray(tri_labels)
    if labels.shape != (len(F),) or not np.issubdtype(labels.dtype, np.integer):
        raise BolusError(f"patch labels must be one integer per triangle ({len(F)}), got shape {labels.shape}")
    outside = labels < 0
    if outside.all():
        raise BolusError("none of the region's faces belongs to a patch: run Segment on this region first")
    _, comp = topo.face_components(np.where(outside, -1, labels))
    comp = np.where(outside, -1, comp)
    uniq, islands = np.unique(comp, return_inverse=True)
    islands = islands.reshape(-1) - (1 if (uniq < 0).any() else 0)
    island_patch = np.full(int(islands.max()) + 1, -1, dtype=np.int64)
    island_patch[islands[~outside]] = labels[~outside]
    groups = np.arange(len(F)) if face_groups is None else np.asarray(face_groups)
    return PatchIslands(islands.astype(np.int64), island_patch, int(len(np.unique(groups[outside]))))


@dataclass
class SheetLayout:
    """The pieces of all islands after darts and splits (`collect_pieces`).

    islands: a `PatchIslands` whose islands are the pieces (piece of every triangle, -1
    outside; island_patch: patch of every piece); unfoldings: one per piece; darts:
    [(piece, path (k,) region vertex ids boundary -> apex, defect rad)]; splits: [(patch,
    (piece a, piece b), path (k,) region vertex ids)]; unmet: [(patch, reason)] of the
    patches whose pieces miss the target.
    """

    islands: PatchIslands
    unfoldings: list
    darts: list
    splits: list
    unmet: list

    def darts_of(self, piece: int) -> int:
        return sum(1 for d in self.darts if d[0] == piece)

    def splits_of(self, patch: int) -> int:
        return sum(1 for sp in self.splits if sp[0] == patch)


def collect_pieces(islands: PatchIslands, results: list) -> SheetLayout:
    """Number the pieces of every island's `sheet_pieces.SheetPieces` (in ``results``, one per
    island, their ``piece`` indexing the island's triangles in increasing order) one after
    the other: piece ids 0..P-1 over the whole pattern, island by island."""
    if len(results) != islands.count:
        raise BolusError(f"internal error: {len(results)} refined islands for {islands.count} islands")
    piece = np.full(len(islands.islands), -1, dtype=np.int64)
    patch_of, unfoldings, darts, splits, unmet = [], [], [], [], []
    for k, res in enumerate(results):
        rows = np.nonzero(islands.islands == k)[0]
        local = np.asarray(res.piece, dtype=np.int64)
        if local.shape != rows.shape or (len(local) and local.min() < 0) or len(res.unfoldings) != (
                int(local.max()) + 1 if len(local) else 0):
            raise BolusError(f"internal error: island {k} has {len(rows)} triangles, its pieces do not cover them")
        first = len(unfoldings)
        p = int(islands.island_patch[k])
        piece[rows] = first + local
        patch_of.extend([p] * len(res.unfoldings))
        unfoldings.extend(res.unfoldings)
        darts.extend((first + d.piece, np.asarray(d.path), float(d.defect)) for d in res.darts)
        splits.extend((p, (first + s.pieces[0], first + s.pieces[1]), np.asarray(s.path)) for s in res.splits)
        if not res.met:  # `iter_sheet_pieces` names the island it was given as "patch k": the patch is p
            reason = res.reason.removeprefix(f"patch {k}: ")
            unmet.append((p, reason))
    return SheetLayout(PatchIslands(piece, np.asarray(patch_of, dtype=np.int64), islands.left_out), unfoldings,
                       darts, splits, unmet)
