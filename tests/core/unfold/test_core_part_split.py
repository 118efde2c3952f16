"""A large curved patch cut into spectral parts before darts and splits (core/unfold/part_split.py):
the parts' borders as paths, a face in one patch made into pieces that each meet the target, and
patches under the size left to darts and splits alone."""
import numpy as np
import pytest
from meshgen import cone, height_field
from paths import data_mesh

from bolus_addon.core.mesh.objfile import load_obj
from bolus_addon.core.mesh.topology import MeshTopology
from bolus_addon.core.unfold import part_split, sheet_pieces as sp_mod
from bolus_addon.core.unfold.sheet_pieces import sheet_pieces

TARGET = 0.02


def edge_set(F, n):
    topo = MeshTopology(np.zeros((n, 3)), F)
    return topo, set((topo.edges[:, 0] * n + topo.edges[:, 1]).tolist())


def test_border_paths_cover_every_border_edge_once_along_mesh_edges():
    V, F = height_field(lambda x, y: 0.01 * x * y, nx=24, ny=24)
    c = V[F].mean(axis=1)
    labels = (c[:, 0] > 10).astype(int) + 2 * (c[:, 1] > -20)  # four parts, a T junction and a corner
    paths = part_split.border_paths(V, F, labels)
    topo, keys = edge_set(F, len(V))
    ef = topo.edge_faces
    inner = (ef >= 0).all(axis=1)
    want = {int(k) for k, on in zip(topo.edges[:, 0] * len(V) + topo.edges[:, 1],
                                    inner & (labels[ef[:, 0]] != labels[np.maximum(ef[:, 1], 0)])) if on}
    got = []
    for a, b, p in paths:
        assert a < b and len(p) >= 2
        k = np.minimum(p[:-1], p[1:]) * len(V) + np.maximum(p[:-1], p[1:])
        assert set(k.tolist()) <= keys  # along mesh edges
        for e in k.tolist():
            i = int(np.searchsorted(topo.edges[:, 0] * len(V) + topo.edges[:, 1], e))
            assert sorted(labels[ef[i]].tolist()) == [a, b]  # between the two parts it names
        got += k.tolist()
    assert sorted(got) == sorted(want)  # every border edge once


def test_a_patch_under_the_size_is_not_cut_into_parts():
    V, F = cone()
    assert len(F) < part_split.PART_MIN_TRIANGLES
    assert part_split.part_labels(V, F, None, 3.0) is None
    res = sheet_pieces(V, F, TARGET)
    assert len(res.unfoldings) == 1 and len(res.darts) == 1 and not res.splits


def independent_el_ea(V, u):
    """EL and EA of a piece from its own UVs and the source positions (SPEC: no scale fitted)."""
    P3, P2 = V[u.vert_origin][u.F], u.UV[u.F]
    L0 = np.linalg.norm(P3 - np.roll(P3, -1, axis=1), axis=2)
    L = np.linalg.norm(P2 - np.roll(P2, -1, axis=1), axis=2)
    A0 = 0.5 * np.linalg.norm(np.cross(P3[:, 1] - P3[:, 0], P3[:, 2] - P3[:, 0]), axis=1)
    d1, d2 = P2[:, 1] - P2[:, 0], P2[:, 2] - P2[:, 0]
    A = 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    return np.abs(L - L0).sum() / L0.sum(), np.abs(A - A0).sum() / A0.sum(), int((A <= 0).sum())


def ict_nose_region():
    """The ICT face's nose, nostrils and cheeks within 40 mm of the tip: 3,072 triangles, about
    42 rad of angle defect (mm)."""
    V, F, _ = load_obj(data_mesh("ict_face_narrow.obj"), 10.0)
    tip = V[int(np.argmax(V[:, 2]))]
    keep = np.linalg.norm(V[F] - tip, axis=2).max(axis=1) <= 40.0
    Fk = F[keep]
    _, comp = MeshTopology(V, Fk).face_components()
    Fk = Fk[comp == np.argmax(np.bincount(comp))]
    used = np.unique(Fk)
    return V[used], np.searchsorted(used, Fk)


@pytest.fixture(scope="module")
def face_in_one_patch():
    """The nose region as one patch, with the size from which a patch is cut into parts lowered
    to 1,000 triangles so the suite stays quick; also the final parts (faces of each)."""
    V, F = ict_nose_region()
    saved = part_split.PART_MIN_TRIANGLES, part_split.merge_parts
    seen = []

    def merge(V_, F_, parts, seconds):
        seen.extend(faces for faces, _verts, _res in parts)
        return saved[1](V_, F_, parts, seconds)

    part_split.PART_MIN_TRIANGLES, part_split.merge_parts = 1_000, merge
    try:
        return V, F, sheet_pieces(V, F, TARGET), seen
    finally:
        part_split.PART_MIN_TRIANGLES, part_split.merge_parts = saved


def test_a_face_in_one_patch_is_cut_into_parts_whose_pieces_meet_the_target(face_in_one_patch):
    V, F, res, parts = face_in_one_patch
    assert len(parts) >= 3 and res.met, res.reason
    assert len(res.unfoldings) >= 3
    for u in res.unfoldings:
        el, ea, flips = independent_el_ea(V, u)
        assert el <= TARGET + 1e-9 and ea <= sp_mod.EA_PER_EL * TARGET + 1e-9 and flips == 0
        assert u.overlaps == 0
    seen = np.zeros(len(F), dtype=int)
    for j, u in enumerate(res.unfoldings):
        faces = np.flatnonzero(res.piece == j)
        seen[faces] += 1
        np.testing.assert_array_equal(u.vert_origin[u.F], F[faces])
    assert (seen == 1).all()


def test_the_borders_between_parts_are_splits_between_the_pieces_either_side(face_in_one_patch):
    V, F, res, parts = face_in_one_patch
    part = np.full(len(F), -1)
    for j, faces in enumerate(parts):
        part[faces] = j
    assert (part >= 0).all() and (np.bincount(res.piece, minlength=1) > 0).all()
    topo, keys = edge_set(F, len(V))
    ekeys = topo.edges[:, 0] * len(V) + topo.edges[:, 1]
    cut = set()
    for s in res.splits:
        k = np.minimum(s.path[:-1], s.path[1:]) * len(V) + np.maximum(s.path[:-1], s.path[1:])
        assert set(k.tolist()) <= keys
        cut |= set(k.tolist())
        sides = {tuple(sorted(res.piece[topo.edge_faces[int(np.searchsorted(ekeys, e))]].tolist())) for e in k}
        assert tuple(sorted(s.pieces)) in sides  # it separates the pieces it names
    ef = topo.edge_faces
    inner = (ef >= 0).all(axis=1)
    between = ekeys[inner & (part[ef[:, 0]] != part[np.maximum(ef[:, 1], 0)])]
    assert len(between) and set(between.tolist()) <= cut  # every edge between two parts is on a recorded split


def test_a_part_that_misses_is_cut_again(monkeypatch):
    V, F = ict_nose_region()
    monkeypatch.setattr(part_split, "PART_MIN_TRIANGLES", 1_000)
    monkeypatch.setattr(part_split, "VARPI_PER_PART", 1e9)  # one part: never cut at first ...
    assert part_split.part_labels(V, F, None, 3.0) is None
    monkeypatch.setattr(part_split, "VARPI_PER_PART", 21.0)  # ... two parts, each too curved for one piece
    calls = []
    real = part_split.part_labels
    monkeypatch.setattr(part_split, "part_labels", lambda *a, **k: calls.append(a[2]) or real(*a, **k))
    res = sheet_pieces(V, F, TARGET, max_pieces=1)
    assert calls[0] is None and part_split.RESPLIT_PARTS in calls[1:]  # the first cut, then a part cut again
    assert len(np.unique(res.piece)) == len(res.unfoldings) >= 3


def test_merged_parts_name_a_piece_that_misses_by_its_number_in_the_patch():
    from types import SimpleNamespace

    from bolus_addon.core.unfold.sheet_records import SheetPieces

    V, F = height_field(lambda x, y: 0.0 * x, nx=4, ny=2)  # 16 triangles, split at x = 0
    left = np.flatnonzero(V[F].mean(axis=1)[:, 0] < 0)
    right = np.setdiff1d(np.arange(len(F)), left)

    def part(faces, pieces, reason):
        verts = np.unique(F[faces])
        u = [SimpleNamespace(vert_origin=np.arange(len(verts))) for _ in range(pieces)]
        piece = np.arange(len(faces)) % pieces
        return faces, verts, SheetPieces(piece, u, [], [], not reason, reason, 0.0)

    res = part_split.merge_parts(V, F, [part(left, 2, ""), part(right, 2, "piece 2 has EL 3.1 %, EA 2.0 %: stuck")], 0.0)
    assert not res.met and res.reason.startswith("piece 4 has EL 3.1 %")  # 2 pieces before it
    assert len(res.unfoldings) == 4 and sorted(set(res.piece.tolist())) == [0, 1, 2, 3]
    assert len(res.splits) == 1 and res.splits[0].excess == 0.0  # the one border between the parts
    a, b = sorted(res.splits[0].pieces)
    assert a in (0, 1) and b in (2, 3)


@pytest.mark.parametrize("sub_el, kept_cut", [(0.05, False), (0.01, True)])
def test_a_cut_that_makes_a_part_no_better_is_undone(monkeypatch, sub_el, kept_cut):
    """A part that misses (EL 3 %) is cut again; the cut is kept only when its pieces are better."""
    from types import SimpleNamespace

    from bolus_addon.core.unfold.sheet_records import SheetPieces

    V, F = height_field(lambda x, y: 0.0 * x, nx=12, ny=12)
    labels = (V[F].mean(axis=1)[:, 0] > 0).astype(int)
    top = {int(np.count_nonzero(labels == k)) for k in (0, 1)}

    def solve(Vp, Fp, gp, pr):
        el = 0.03 if len(Fp) in top else sub_el
        u = SimpleNamespace(EL=el, EA=el, flipped=0, overlaps=0, vert_origin=np.arange(len(Vp)))
        return SheetPieces(np.zeros(len(Fp), dtype=np.int64), [u], [], [], el <= 0.02, "" if el <= 0.02 else "x", 0.0)

    monkeypatch.setattr(part_split, "RESPLIT_DEPTH", 1)
    found = part_split.solve_in_parts(V, F, labels, solve, 3.0)
    assert (len(found) > 2) == kept_cut
    faces = np.sort(np.concatenate([f for f, _v, _r in found]))
    np.testing.assert_array_equal(faces, np.arange(len(F)))  # every triangle in exactly one part
