"""Darts and splits (core/sheet_pieces.py): a cone gets a dart, a
saddle a split, a developable cylinder nothing; every triangle in exactly one piece; the
target, the limits and bad input."""
import numpy as np
import pytest
from meshgen import cone, cylinder_piece, degenerate_variants, height_field, icosphere, ring_surface, saddle, torus

from bolus_addon.core.unfold import sheet_pieces as sp_mod
from bolus_addon.core.errors import BolusError
from bolus_addon.core.unfold.sheet_pieces import EA_PER_EL, iter_sheet_pieces, sheet_pieces
from bolus_addon.core.mesh.topology import MeshTopology
from bolus_addon.core.unfold.unfold import unfold_patch

TARGET = 0.02


def on_mesh_edges(F, path) -> bool:
    topo = MeshTopology(np.zeros((int(F.max()) + 1, 3)), F)
    keys = set((topo.edges[:, 0] * topo.n + topo.edges[:, 1]).tolist())
    a, b = np.minimum(path[:-1], path[1:]), np.maximum(path[:-1], path[1:])
    return all(int(k) in keys for k in a * topo.n + b)


def boundary_vertices(F):
    return MeshTopology(np.zeros((int(F.max()) + 1, 3)), F).boundary_vertices


def assert_partition(res, F):
    """Every source triangle in exactly one piece, each unfolding's rows its piece's triangles in order."""
    m = len(F)
    assert res.piece.shape == (m,) and res.piece.min() == 0 and res.piece.max() == len(res.unfoldings) - 1
    seen = np.zeros(m, dtype=int)
    for j, u in enumerate(res.unfoldings):
        faces = np.nonzero(res.piece == j)[0]
        seen[faces] += 1
        assert len(u.F) == len(faces)
        np.testing.assert_array_equal(u.vert_origin[u.F], F[faces])
        # edge-connected
        assert MeshTopology(np.zeros((int(F.max()) + 1, 3)), F[faces]).face_components()[0] == 1
    assert (seen == 1).all()


@pytest.fixture(scope="module")
def cone_result():
    V, F = cone()
    return V, F, sheet_pieces(V, F, TARGET)


@pytest.fixture(scope="module")
def saddle_result():
    V, F = saddle()
    return V, F, sheet_pieces(V, F, TARGET)


def test_cone_one_dart_brings_el_under_half_a_percent(cone_result):
    V, F, res = cone_result
    plain = unfold_patch(V, F)
    assert plain.EL > 0.05  # one piece without the dart: 7 %
    assert len(res.darts) == 1 and len(res.splits) == 0 and len(res.unfoldings) == 1
    u = res.unfoldings[0]
    assert u.EL < 0.005 and u.EA < 0.005 and u.flipped == 0 and u.overlaps == 0
    assert res.met and res.reason == ""
    d = res.darts[0]
    assert d.piece == 0 and d.path[-1] == len(V) - 1  # apex last
    assert boundary_vertices(F)[d.path[0]] and not boundary_vertices(F)[d.path[1:]].any()
    assert on_mesh_edges(F, d.path)
    assert d.defect > 0
    # the dart opened: its vertices (not the apex) appear twice in the pattern
    counts = np.bincount(u.vert_origin, minlength=len(V))
    assert (counts[d.path[1:-1]] == 2).all() and counts[d.path[-1]] == 1
    assert_partition(res, F)


def test_saddle_is_split_without_overlap_and_every_piece_meets_the_target(saddle_result):
    V, F, res = saddle_result
    assert unfold_patch(V, F).EL > TARGET  # one piece misses
    assert len(res.splits) >= 1 and len(res.unfoldings) == len(res.splits) + 1
    assert res.met and res.reason == ""
    for u in res.unfoldings:
        assert u.EL <= TARGET and u.EA <= EA_PER_EL * TARGET
        assert u.flipped == 0 and u.overlaps == 0
    for s in res.splits:
        a, b = s.pieces
        assert a != b and 0 <= min(a, b) and max(a, b) < len(res.unfoldings)
        assert on_mesh_edges(F, s.path) and boundary_vertices(F)[[s.path[0], s.path[-1]]].all()
        assert s.excess > 0
        if len(res.splits) == 1:  # the path runs between the two pieces, edge by edge
            topo = MeshTopology(V, F)
            keys = topo.edges[:, 0] * topo.n + topo.edges[:, 1]
            e = np.searchsorted(keys, np.minimum(s.path[:-1], s.path[1:]) * topo.n
                                + np.maximum(s.path[:-1], s.path[1:]))
            sides = np.sort(res.piece[topo.edge_faces[e]], axis=1)
            assert (sides == sorted((a, b))).all()
    assert_partition(res, F)


def test_developable_cylinder_gets_nothing():
    V, F = cylinder_piece(na=40, nl=30)
    res = sheet_pieces(V, F, TARGET)
    assert len(res.unfoldings) == 1 and res.darts == [] and res.splits == []
    assert (res.piece == 0).all() and res.met
    assert res.unfoldings[0].EL < 1e-3


def test_max_el_zero_is_unfold_patch():
    V, F = saddle(n=16)
    res = sheet_pieces(V, F, 0.0, refine_rounds=2)
    ref = unfold_patch(V, F, refine_rounds=2)
    assert len(res.unfoldings) == 1 and res.darts == [] and res.splits == [] and (res.piece == 0).all()
    u = res.unfoldings[0]
    np.testing.assert_allclose(u.UV, ref.UV)
    np.testing.assert_array_equal(u.F, ref.F)
    np.testing.assert_array_equal(u.vert_origin, ref.vert_origin)
    assert (u.EL, u.EA, u.flipped, u.overlaps) == (ref.EL, ref.EA, ref.flipped, ref.overlaps)


@pytest.mark.parametrize("bad", [-0.01, 0.0005, np.nan, np.inf, "two"])
def test_bad_max_el_is_refused(bad):
    V, F = saddle(n=6)
    with pytest.raises(BolusError, match="max_el must be 0"):
        sheet_pieces(V, F, bad)
    with pytest.raises(BolusError, match="max_el must be 0"):
        list(iter_sheet_pieces(V, F, np.zeros(len(F), dtype=int), bad))


def test_bad_limits_are_refused():
    V, F = saddle(n=6)
    with pytest.raises(BolusError, match="max_pieces"):
        sheet_pieces(V, F, TARGET, max_pieces=0)
    with pytest.raises(BolusError, match="sigma_mm"):
        sheet_pieces(V, F, TARGET, sigma_mm=-1.0)
    with pytest.raises(BolusError, match="sigma_mm"):
        sheet_pieces(V, F, TARGET, sigma_mm="wide")


def test_target_not_met_within_the_piece_limit_names_the_piece_and_why():
    V, F = saddle()
    res = sheet_pieces(V, F, TARGET, max_pieces=1)
    assert not res.met and len(res.unfoldings) == 1 and res.splits == []
    u = res.unfoldings[0]
    assert u.EL > TARGET
    assert "piece 1" in res.reason and f"EL {100 * u.EL:.1f} %" in res.reason
    assert "most pieces allowed (1)" in res.reason
    assert_partition(res, F)


def test_a_darted_and_split_mesh_keeps_every_face_in_one_piece():
    """A cone cap (deficit) beside a saddle (excess) in one patch: darts and splits together."""
    def f(x, y):  # a cone apex at (-50, 0) blended into a saddle around (50, 0)
        cone_z = -np.hypot(x + 50.0, y) * 1.2
        sad = ((x - 50.0) ** 2 - y**2) / 60.0
        w = 1.0 / (1.0 + np.exp(-x / 8.0))
        return (1 - w) * cone_z + w * sad
    V, F = height_field(f, nx=40, ny=20, size=200.0)
    V[:, 1] *= 0.5
    res = sheet_pieces(V, F, TARGET, max_pieces=4)
    assert len(res.darts) >= 1 and len(res.splits) >= 1 and res.met  # measured: 1 dart, 2 splits
    assert_partition(res, F)
    for d in res.darts:
        assert 0 <= d.piece < len(res.unfoldings) and on_mesh_edges(F, d.path)
    for u in res.unfoldings:
        assert u.EL <= TARGET and u.flipped == 0 and u.overlaps == 0


def test_iter_sheet_pieces_works_in_the_callers_indices():
    Vc, Fc = cone(rings=15, na=40)
    Vy, Fy = cylinder_piece(na=20, nl=10)
    Vy = Vy + [200.0, 0.0, 0.0]
    V = np.r_[Vy, Vc]
    F = np.r_[Fy, Fc + len(Vy)]
    labels = np.r_[np.full(len(Fy), 1), np.full(len(Fc), 0)]
    texts = []
    out = list(iter_sheet_pieces(V, F, labels, TARGET, progress=lambda f, t: texts.append((f, t))))
    assert [(k, n) for k, n, _ in out] == [(0, 2), (1, 2)]
    cone_res, cyl_res = out[0][2], out[1][2]
    assert len(cone_res.darts) == 1 and cone_res.darts[0].path[-1] == len(V) - 1
    assert cyl_res.darts == [] and cyl_res.splits == []
    for lab, (_, _, res) in zip((0, 1), out):
        faces = np.nonzero(labels == lab)[0]
        for j, u in enumerate(res.unfoldings):
            np.testing.assert_array_equal(u.vert_origin[u.F], F[faces[res.piece == j]])
    fr = [f for f, _ in texts]
    assert fr == sorted(fr) and 0.0 <= fr[0] and fr[-1] <= 1.0
    assert texts[0][1].startswith("patch 1/2:") and texts[-1][1].startswith("patch 2/2:")


def test_iter_sheet_pieces_names_the_patch_that_fails_or_misses():
    V, F = saddle()
    Vb, Fb = saddle(n=6)
    Fb = Fb.copy()
    Fb[0] = Fb[0][[0, 0, 1]]  # a repeated vertex in patch 1
    bad = np.r_[F, Fb + len(V)]
    with pytest.raises(BolusError, match="triangle"):
        list(iter_sheet_pieces(np.r_[V, Vb], bad, np.r_[np.zeros(len(F)), np.ones(len(Fb))].astype(int)))
    out = list(iter_sheet_pieces(V, F, np.full(len(F), 3), TARGET, max_pieces=1))
    assert len(out) == 1 and out[0][2].reason.startswith("patch 3: piece 1")


def test_progress_reports_steps_with_rising_fractions():
    V, F = cone(rings=15, na=40)
    calls = []
    sheet_pieces(V, F, TARGET, progress=lambda f, t: calls.append((f, t)))
    fr = [f for f, _ in calls]
    assert fr == sorted(fr) and fr[-1] == 1.0 and min(fr) >= 0.0
    assert any(t.startswith("dart 1 on piece 1") for _, t in calls)
    assert any(t.startswith("unfolding piece 1") for _, t in calls)


def test_early_decision_skips_the_full_unfold_of_a_piece_that_clearly_misses(monkeypatch):
    """The cone (EL 7 % in one piece) is darted without a full unfolding of the undarted
    cone: one full unfold in all, for the final piece."""
    calls = []
    real = sp_mod.unfold_patch

    def counting(*a, **k):
        calls.append(len(a[1]))
        return real(*a, **k)

    monkeypatch.setattr(sp_mod, "unfold_patch", counting)
    V, F = cone(rings=15, na=40)
    res = sheet_pieces(V, F, TARGET)
    assert len(res.darts) == 1 and len(calls) == 1


# ------------------------------------------------------------ degenerate input
BASE = saddle(c=40.0, n=8)
CASES = degenerate_variants(*BASE)


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("max_el", [0.0, TARGET])
def test_degenerate_input(name, max_el):
    V, F, says = CASES[name]
    if says is None:  # the needle triangle: sound
        res = sheet_pieces(V, F, max_el)
        assert_partition(res, F)
        for u in res.unfoldings:
            assert np.isfinite(u.UV).all() and np.isfinite(u.EL) and np.isfinite(u.EA)
        return
    with pytest.raises(BolusError, match=says):
        sheet_pieces(V, F, max_el)
    with pytest.raises(BolusError, match=says) as exc:
        list(iter_sheet_pieces(V, F, np.zeros(len(F), dtype=int), max_el))
    if name not in ("nan", "inf"):  # the whole mesh's coordinates are checked before any patch
        assert str(exc.value).startswith("patch 0: ")


def test_a_tight_target_splits_the_pieces_again():
    """0.6 % on a 24 x 24 saddle: the halves (0.7 %) are split again, which refines a piece that
    is not the first in the list (this crashed when pieces were compared by value)."""
    V, F = height_field(lambda x, y: (x**2 - y**2) / 80, nx=24, ny=24, size=100.0)
    res = sheet_pieces(V, F, 0.006)
    assert res.met and len(res.splits) >= 3 and len(res.unfoldings) == len(res.splits) + 1
    assert all(u.EL <= 0.006 and u.flipped == 0 and u.overlaps == 0 for u in res.unfoldings)
    assert_partition(res, F)


def test_inconsistent_winding_is_refused_before_any_work():
    V, F = saddle(n=10)
    F = F.copy()
    F[5] = F[5][::-1]
    with pytest.raises(BolusError, match="consistently oriented"):
        sheet_pieces(V, F, TARGET)


def test_without_length_refinement_the_cone_still_gets_its_dart():
    V, F = cone(rings=15, na=40)
    res = sheet_pieces(V, F, TARGET, refine_rounds=0)
    assert res.met and len(res.darts) == 1 and res.unfoldings[0].EL < 0.005


def test_iter_sheet_pieces_refuses_labels_of_the_wrong_length():
    V, F = saddle(n=6)
    with pytest.raises(BolusError, match="patch labels"):
        list(iter_sheet_pieces(V, F, np.zeros(len(F) - 1, dtype=int)))


def test_a_closed_sphere_is_opened_and_cut_into_pieces_that_meet_the_target():
    V, F = icosphere(3, 40.0)
    res = sheet_pieces(V, F, TARGET)
    assert res.met and len(res.unfoldings) >= 2 and len(res.darts) >= 1
    assert all(u.EL <= TARGET and u.flipped == 0 and u.overlaps == 0 for u in res.unfoldings)
    assert_partition(res, F)


def test_a_handle_is_refused_by_name():
    with pytest.raises(BolusError, match="handle"):
        sheet_pieces(*torus(), TARGET)


def diag_cone(n=40):
    """A cone (apex at the centre, 30 mm high, radius 50 mm) on a grid of quads split along their
    (1, 1) diagonals (height_field order: triangles k and k + n*n form quad k), cut to an ellipse
    that is narrow along (1, 1): the shortest cut from the apex to the edge runs along the
    diagonals.  Returns V, F and the quad of every triangle."""
    V, F = height_field(lambda x, y: 30.0 * (1 - np.hypot(x, y) / 50.0), nx=n, ny=n, size=100.0)
    g = np.arange(len(F)) % (len(F) // 2)
    C = V[F].mean(axis=1)
    u, v = (C[:, 0] + C[:, 1]) / 2**0.5, (C[:, 0] - C[:, 1]) / 2**0.5
    keep = (u / 25.0) ** 2 + (v / 45.0) ** 2 <= 1
    keep &= np.bincount(g, weights=keep, minlength=len(F) // 2)[g] == 2  # whole quads only
    used, inv = np.unique(F[keep], return_inverse=True)
    return V[used], inv.reshape(-1, 3), g[keep]


def quad_diagonals(F, groups) -> set:
    """The edge the two triangles of every group share."""
    out = set()
    for k in np.unique(groups):
        t = F[groups == k]
        if len(t) == 2:
            out.add(tuple(sorted(set(t[0].tolist()) & set(t[1].tolist()))))
    return out


def path_edges(path) -> set:
    return {tuple(sorted(e)) for e in zip(path[:-1].tolist(), path[1:].tolist())}


def test_face_groups_keep_every_quad_whole():
    """The Blender layer triangulates quads: with face_groups (the quad of every triangle) no dart
    or split runs along a quad's diagonal, so every quad stays whole (one pattern vertex per
    corner).  Without groups the dart of this cone runs along diagonals."""
    V, F, groups = diag_cone()
    diagonals = quad_diagonals(F, groups)
    free = sheet_pieces(V, F, 0.005)
    assert free.darts and any(path_edges(d.path) & diagonals for d in free.darts), "test setup"
    res = sheet_pieces(V, F, 0.005, face_groups=groups)
    assert res.met and res.darts
    assert not any(path_edges(d.path) & diagonals for d in res.darts)
    for g in np.unique(groups):
        assert len(set(res.piece[groups == g].tolist())) == 1
    # a split of a saddle made of quads
    V, F = saddle(n=24)
    groups = np.arange(len(F)) % (len(F) // 2)
    res = sheet_pieces(V, F, 0.006, face_groups=groups)
    assert res.met and res.splits
    assert not any(path_edges(sp.path) & quad_diagonals(F, groups) for sp in res.splits)
    for g in np.unique(groups):
        assert len(set(res.piece[groups == g].tolist())) == 1
    assert_partition(res, F)
    with pytest.raises(BolusError, match="face_groups must give an integer group for each of the"):
        sheet_pieces(V, F, 0.02, face_groups=groups[:-1])


def test_a_piece_given_up_on_still_gets_the_whole_pipeline(monkeypatch):
    """A stuck piece (here: no split allowed) is unfolded with the overlap correction (no
    target_el: a trial pattern could overlap), so it is warned but overlap-free."""
    calls = []
    real = sp_mod.unfold_patch

    def spy(*a, **kw):
        calls.append(kw.get("target_el"))
        return real(*a, **kw)

    monkeypatch.setattr(sp_mod, "unfold_patch", spy)
    V, F = saddle(n=24)
    res = sheet_pieces(V, F, 0.006, max_pieces=1)
    assert not res.met and "most pieces" in res.reason
    assert calls == [None]
    assert res.unfoldings[0].flipped == 0 and res.unfoldings[0].overlaps == 0
