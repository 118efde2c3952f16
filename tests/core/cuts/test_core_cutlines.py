"""Core tests of the smooth cut lines (core.cutlines, seed 4.1.2)."""
from __future__ import annotations

import numpy as np
import pytest
from paths import data_mesh
from meshgen import grid, ring_surface, spherical_cap
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bolus_addon.core.cuts.cutlines import (
    border_components,
    fit_closed_curve,
    fit_open_curve,
    project_to_plane,
    smooth_cuts,
    turning_per_mm,
)
from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.objfile import load_obj
from bolus_addon.core.analysis.spectral import segment
from bolus_addon.core.mesh.topology import MeshTopology


# ------------------------------------------------------------------ helpers
def centroids(V, F):
    return V[F].mean(axis=1)


def areas(V, F):
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)


def min_angles(V, F):
    P = V[F]
    out = np.full(len(F), 180.0)
    for k in range(3):
        u, w = P[:, (k + 1) % 3] - P[:, k], P[:, (k + 2) % 3] - P[:, k]
        c = (u * w).sum(1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        out = np.minimum(out, np.degrees(np.arccos(np.clip(c, -1, 1))))
    return out


def patch_connected(F, labels, p):
    """Edge-connectivity of the faces of patch p, computed here from scratch."""
    idx = np.nonzero(labels == p)[0]
    edges = {}
    for f in idx:
        for k in range(3):
            e = tuple(sorted((F[f, k], F[f, (k + 1) % 3])))
            edges.setdefault(e, []).append(f)
    rows, cols = [], []
    pos = {f: i for i, f in enumerate(idx)}
    for fs in edges.values():
        for a in fs[1:]:
            rows.append(pos[fs[0]])
            cols.append(pos[a])
    G = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(idx), len(idx)))
    return connected_components(G, directed=False)[0] == 1


def border_edges(F, labels, a, b):
    """Vertex pairs of the edges between faces of patch a and faces of patch b."""
    owner = {}
    for f in range(len(F)):
        for k in range(3):
            e = tuple(sorted((F[f, k], F[f, (k + 1) % 3])))
            owner.setdefault(e, []).append(labels[f])
    return np.array([e for e, ls in owner.items() if sorted(ls) == [a, b]])


def point_triangle_distance(p, A, B, C):
    """Distance of point p to triangle ABC (brute force via barycentric clamp, small meshes only)."""
    # project onto the plane and clamp by checking the three edges
    n = np.cross(B - A, C - A)
    n = n / np.linalg.norm(n)
    q = p - np.dot(p - A, n) * n
    # barycentric of q
    v0, v1, v2 = B - A, C - A, q - A
    d00, d01, d11, d20, d21 = v0 @ v0, v0 @ v1, v1 @ v1, v2 @ v0, v2 @ v1
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    u = 1 - v - w
    if min(u, v, w) >= -1e-12:
        return abs(np.dot(p - A, n))

    def seg(p, a, b):
        t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0, 1)
        return np.linalg.norm(p - (a + t * (b - a)))

    return min(seg(p, A, B), seg(p, B, C), seg(p, C, A))


def distance_to_mesh(P, V, F):
    """Distance of each point to the mesh (brute force; fine for a few hundred points)."""
    C = centroids(V, F)
    out = []
    for p in P:
        near = np.argsort(np.linalg.norm(C - p, axis=1))[:12]
        out.append(min(point_triangle_distance(p, *V[F[f]]) for f in near))
    return np.array(out)


def conic_through(x, y):
    """Coefficients (A, B, C, D, E, F) of the conic through the points; asserts they fit one."""
    s = max(np.abs(x).max(), np.abs(y).max())
    x, y = x / s, y / s
    D = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], 1)
    _, sv, Vt = np.linalg.svd(D)
    assert sv[-1] < 1e-9 * sv[0], "the points do not lie on one conic"
    return Vt[-1]


def sheet(n=30, size=100.0):
    V, F = grid(n, n, size=size)
    return V, F, size / n


def check_invariants(V, F, labels, res):
    """Rules every result must keep, checked independently of the implementation."""
    size = np.ptp(V, axis=0).max()
    new = np.arange(len(V), len(res.V))
    assert len(new) > 0
    # every new vertex lies on the original surface
    assert distance_to_mesh(res.V[new], V, F).max() < 1e-9 * size
    # input vertices keep their index and position
    np.testing.assert_array_equal(res.V[: len(V)], V)
    # area unchanged, per original triangle too
    assert abs(areas(res.V, res.F).sum() - areas(V, F).sum()) < 1e-9 * areas(V, F).sum()
    per_parent = np.bincount(res.face_parent, weights=areas(res.V, res.F), minlength=len(F))
    np.testing.assert_allclose(per_parent, areas(V, F), rtol=1e-9, atol=1e-12 * size**2)
    # same orientation as the parent triangle
    n_new = np.cross(res.V[res.F[:, 1]] - res.V[res.F[:, 0]], res.V[res.F[:, 2]] - res.V[res.F[:, 0]])
    n_old = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])[res.face_parent]
    assert ((n_new * n_old).sum(1) > 0).all()
    # same patches, each connected
    assert set(np.unique(res.labels)) == set(np.unique(labels))
    for p in np.unique(labels[labels >= 0]):
        assert patch_connected(res.F, res.labels, p)
    # a manifold mesh without T-junctions: every edge has 1 or 2 faces and the boundary
    # length is the same as before
    topo0, topo1 = MeshTopology(V, F), MeshTopology(res.V, res.F)
    assert topo1.edge_face_count.max() <= 2
    b0 = topo0.edge_lengths[topo0.boundary_edges].sum()
    b1 = topo1.edge_lengths[topo1.boundary_edges].sum()
    assert abs(b0 - b1) < 1e-9 * b0


def cut_one_border(V, F, labels, method, closed):
    """smooth_cuts with the invariants checked and one 0|1 border cut by ``method``:
    (result, its report row, the new vertices on the border (k,3))."""
    res = smooth_cuts(V, F, labels)
    check_invariants(V, F, labels, res)
    (rep,) = res.borders
    assert rep.method == method and rep.closed is closed
    verts = np.unique(border_edges(res.F, res.labels, 0, 1))
    return res, rep, res.V[verts[verts >= len(V)]]


# ------------------------------------------------------------------ curve fitting
def test_projection_matches_eqs_4_7_to_4_9():
    rng = np.random.default_rng(1)
    P = rng.normal(size=(20, 3))
    p = np.array([0.3, -0.7, 0.5])  # plane p.x + 1 = 0 of the seed
    origin = -p / (p @ p)
    ours = project_to_plane(P, p, origin)
    x1 = p[0] / (p @ p) * ((p[1] ** 2 + p[2] ** 2) / p[0] * P[:, 0] - p[1] * P[:, 1] - p[2] * P[:, 2])
    # eq. 4-7 as printed omits the constant term of the plane; with it (the +1) the
    # projection of the seed's plane is x1 - p1/|p|^2
    x1 = x1 - p[0] / (p @ p)
    y1 = p[1] / p[0] * (x1 - P[:, 0]) + P[:, 1]
    z1 = p[2] / p[0] * (x1 - P[:, 0]) + P[:, 2]
    np.testing.assert_allclose(ours, np.stack([x1, y1, z1], 1), atol=1e-12)
    np.testing.assert_allclose(ours @ p + 1.0, 0.0, atol=1e-12)


def test_line_kept_for_zigzag_and_parabola_for_a_bend():
    x = np.linspace(0, 100, 40)
    zig = 0.5 * (-1.0) ** np.arange(40)  # mesh zig-zag around a straight line
    _, order, _ = fit_open_curve(x, 2.0 + 0.1 * x + zig, noise=2.5)
    assert order == 1
    coef, order, rms = fit_open_curve(x, 0.01 * (x - 50) ** 2 + zig, noise=2.5)
    assert order == 2 and rms == pytest.approx(0.4995, rel=0.15)  # the zig-zag's own RMS is 0.5
    np.testing.assert_allclose(coef, [0.01, -1.0, 25.0], rtol=2e-3)


def test_closed_fit_of_a_circle_is_an_ellipse():
    s = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    xy = np.stack([30 * np.cos(s) + 0.3 * np.cos(7 * s), 20 * np.sin(s)], 1)
    coef, K, rms = fit_closed_curve(xy, noise=3.0)
    assert K == 1 and rms == pytest.approx(0.144, rel=0.15)  # measured (the 7th harmonic of 0.3 mm)


def test_turning_of_a_staircase_and_a_line():
    V = np.array([[i, i % 2, 0.0] for i in range(11)], dtype=float)
    E = np.stack([np.arange(10), np.arange(1, 11)], 1)
    t, L = turning_per_mm(V, E)
    assert t == pytest.approx(9 * np.pi / 2 / L)
    V[:, 1] = 0
    assert turning_per_mm(V, E)[0] == pytest.approx(0.0, abs=1e-12)


# ------------------------------------------------------------------ smooth_cuts
def test_jagged_straight_border_becomes_a_line():
    V, F, h = sheet()
    c = centroids(V, F)
    labels = (c[:, 0] > 50 + 0.3 * (c[:, 1] - 50)).astype(int)
    res, rep, P = cut_one_border(V, F, labels, "line", False)
    P = P[:, :2]
    E = border_edges(res.F, res.labels, 0, 1)
    verts = np.unique(E)
    # the new vertices are exactly on one straight line
    A = np.c_[P[:, 1], np.ones(len(P))]
    coef, *_ = np.linalg.lstsq(A, P[:, 0], rcond=None)
    assert np.abs(A @ coef - P[:, 0]).max() < 1e-9 * 100
    # snapped input vertices are within the snapping tolerance of it
    Q = res.V[verts, :2]
    assert np.abs(np.c_[Q[:, 1], np.ones(len(Q))] @ coef - Q[:, 0]).max() <= 0.05 * h * np.sqrt(2) + 1e-9
    t0 = turning_per_mm(V, border_edges(F, labels, 0, 1))[0]
    t1 = turning_per_mm(res.V, E)[0]
    assert t1 / t0 == pytest.approx(0.0067, rel=0.15)  # measured; the ends keep a little turning
    assert rep.turning_after == pytest.approx(t1)


def test_curved_border_becomes_a_parabola():
    V, F, h = sheet()
    c = centroids(V, F)
    labels = (c[:, 0] - 50 - 0.01 * (c[:, 1] - 50) ** 2 > 0).astype(int)
    _, rep, P = cut_one_border(V, F, labels, "parabola", False)
    x, y = P[:, 0], P[:, 1]
    # the new vertices lie on one conic, and that conic is a parabola (B^2 = 4AC); the
    # parabola's axis is the border's principal direction, not necessarily the y axis
    q = conic_through(x, y)
    A, B, C = q[0], q[1], q[2]
    assert abs(B * B - 4 * A * C) < 1e-6 * (A * A + B * B + C * C)
    assert rep.turning_after / rep.turning_before == pytest.approx(0.0528, rel=0.15)  # measured


def test_enclosed_patch_gets_an_ellipse():
    V, F, h = sheet()
    c = centroids(V, F)
    labels = (np.linalg.norm(c[:, :2] - [45, 55], axis=1) < 25).astype(int)
    _, rep, P = cut_one_border(V, F, labels, "ellipse", True)
    q = conic_through(P[:, 0], P[:, 1])
    assert q[1] ** 2 - 4 * q[0] * q[2] < 0  # an ellipse
    assert rep.turning_after / rep.turning_before == pytest.approx(0.152, rel=0.15)  # measured


def test_ring_around_a_tube_is_cut_by_a_plane():
    prof = np.stack([np.full(31, 40.0), np.linspace(0, 120, 31)], 1)
    V, F, _ = ring_surface(prof, na=48, pole=False)
    c = centroids(V, F)
    labels = (c[:, 2] > 60 + 0.3 * c[:, 0]).astype(int)
    _, rep, P = cut_one_border(V, F, labels, "plane section", True)
    _, sv, _ = np.linalg.svd(P - P.mean(0))
    assert sv[2] < 1e-9 * sv[0]
    assert rep.turning_after / rep.turning_before == pytest.approx(0.0249, rel=0.15)  # measured


def test_dome_loop_on_a_curved_surface():
    V, F = spherical_cap(50, 80, 4)
    c = centroids(V, F)
    labels = (np.linalg.norm(c[:, :2] - [10, 5], axis=1) < 20).astype(int)
    _, rep, _ = cut_one_border(V, F, labels, "ellipse", True)
    assert rep.turning_after / rep.turning_before == pytest.approx(0.191, rel=0.15)  # measured


def test_three_patches_cuts_stay_in_their_pair():
    V, F = grid(30, 30, size=100.0, jitter=0.2)
    c = centroids(V, F)
    labels = np.where(c[:, 0] + 3 * np.sin(c[:, 1] / 7) < 40, 0, np.where(c[:, 1] + 2 * np.cos(c[:, 0] / 5) < 50, 1, 2))
    res = smooth_cuts(V, F, labels)
    check_invariants(V, F, labels, res)
    assert {(r.a, r.b) for r in res.borders} == {(0, 1), (0, 2), (1, 2)}
    measured = {(0, 1): 0.196, (0, 2): 0.0597, (1, 2): 0.0209}  # turning after / before
    for r in res.borders:
        assert r.method == "line"
        assert r.turning_after / r.turning_before == pytest.approx(measured[(r.a, r.b)], rel=0.15)
    # faces that changed patch: only those next to the borders (measured: 165 of 2038)
    moved = res.labels != labels[res.face_parent]
    assert moved.sum() == pytest.approx(165, rel=0.15)


def test_a_third_patch_is_never_touched():
    """A jagged 0|1 border ending on patch 2, whose borders are already smooth (along mesh
    edges): patch 2 keeps exactly its faces and vertices (none split, none relabelled)."""
    V, F = grid(30, 30, size=100.0)
    c = centroids(V, F)
    labels = np.where(c[:, 0] > 70, 2, (c[:, 1] > 50 + 0.3 * (c[:, 0] - 35)).astype(int))
    res = smooth_cuts(V, F, labels)
    check_invariants(V, F, labels, res)
    rows = {(r.a, r.b): r for r in res.borders}
    assert rows[(0, 1)].method == "line"
    assert rows[(0, 2)].method == rows[(1, 2)].method == "unchanged"
    two = res.labels == 2
    np.testing.assert_array_equal(np.sort(res.face_parent[two]), np.nonzero(labels == 2)[0])
    assert res.face_unchanged[two].all()
    np.testing.assert_array_equal(res.F[two], F[res.face_parent[two]])  # same corners, same order
    np.testing.assert_array_equal(res.V[np.unique(res.F[two])], V[np.unique(F[labels == 2])])


@pytest.mark.parametrize("slope", [0.2, 0.37, 0.61])
def test_no_slivers_where_snapping_avoids_them(slope):
    # lines of these slopes pass within a few % of an edge from grid vertices
    V, F, h = sheet()
    c = centroids(V, F)
    labels = (c[:, 0] > 50 + slope * (c[:, 1] - 50)).astype(int)
    res = smooth_cuts(V, F, labels)
    check_invariants(V, F, labels, res)
    snapped = min_angles(res.V, res.F[~res.face_unchanged]).min()
    assert snapped >= 1.0
    # without the snapping tolerance the same cut makes thinner triangles
    raw = smooth_cuts(V, F, labels, snap=0.0)
    assert min_angles(raw.V, raw.F[~raw.face_unchanged]).min() < snapped


def test_faces_outside_any_patch_are_never_touched():
    V, F, h = sheet()
    c = centroids(V, F)
    labels = (c[:, 0] > 50 + 0.3 * (c[:, 1] - 50)).astype(int)
    labels[c[:, 1] > 80] = -1
    res = smooth_cuts(V, F, labels)
    out = res.labels < 0
    assert res.face_unchanged[out].all()
    assert out.sum() == (labels < 0).sum()


def test_border_components_of_a_loop_and_a_chain():
    V, F, h = sheet()
    c = centroids(V, F)
    labels = (np.linalg.norm(c[:, :2] - 50, axis=1) < 20).astype(int)
    (b,) = border_components(MeshTopology(V, F), labels)
    assert b.closed and len(b.order) == len(np.unique(b.edges))


# ------------------------------------------------------------------ refusals
def test_refuses_a_single_patch():
    V, F, _ = sheet(5)
    with pytest.raises(BolusError, match="only one patch"):
        smooth_cuts(V, F, np.zeros(len(F), dtype=int))


def test_refuses_wrong_label_shape():
    V, F, _ = sheet(5)
    with pytest.raises(BolusError, match="one patch per triangle"):
        smooth_cuts(V, F, np.zeros(3, dtype=int))


def test_every_border_too_short_changes_nothing():
    """SPEC: with nothing to change (every border too short) no error, nothing changed, the reason in the note."""
    V = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]], dtype=float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    labels = np.array([0, 1])  # the border is one edge
    res = smooth_cuts(V, F, labels)
    assert not res.changed and res.new_vertex_count == 0 and not res.split.any()
    np.testing.assert_array_equal(res.V, V)
    np.testing.assert_array_equal(res.F, F)
    np.testing.assert_array_equal(res.labels, labels)
    (rep,) = res.borders
    assert rep.method == "unchanged" and "too short" in rep.note


def test_refuses_patches_without_a_common_border():
    V, F, _ = sheet(6)
    c = centroids(V, F)
    labels = np.full(len(F), -1)
    labels[c[:, 0] < 30] = 0
    labels[c[:, 0] > 70] = 1
    with pytest.raises(BolusError, match="do not share any border"):
        smooth_cuts(V, F, labels)


# ------------------------------------------------------------------ idempotent
def assert_second_run_changes_nothing(V, F, labels):
    """Run smooth_cuts on (V, F, labels) and again on its result: the second run must change nothing."""
    first = smooth_cuts(V, F, labels)
    assert first.changed and first.new_vertex_count > 0
    second = smooth_cuts(first.V, first.F, first.labels)
    assert second.new_vertex_count == 0 and len(second.V) == len(first.V)
    np.testing.assert_array_equal(second.V, first.V)
    np.testing.assert_array_equal(second.F, first.F)
    np.testing.assert_array_equal(second.labels, first.labels)
    assert not second.changed and not second.split.any()
    assert second.borders and all(r.method == "unchanged" for r in second.borders)
    assert all(r.turning_after == r.turning_before for r in second.borders)
    return first, second


def nose_region(patches, radius=45.0):
    """The demo's treatment area (scripts/demo.py) segmented with the core: the faces of the ICT
    face within radius mm of the nose tip that face forward, one connected piece; labels -1
    elsewhere, as bolus_patch is outside an Edit Mode region."""
    V, F, poly = load_obj(data_mesh("ict_face_narrow.obj"), 10.0)  # cm -> mm, +Z forward
    tip = V[np.argmax(V[:, 2])]
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    npoly = poly.max() + 1
    pn = np.zeros((npoly, 3))
    np.add.at(pn, poly, n)
    pc = np.zeros((npoly, 3))
    np.add.at(pc, poly, centroids(V, F))
    pc /= np.bincount(poly, minlength=npoly)[:, None]
    sel = (np.linalg.norm(pc - tip, axis=1) < radius) & (pn[:, 2] > 0.1 * np.linalg.norm(pn, axis=1))
    keep = np.nonzero(sel[poly])[0]
    _, comp = MeshTopology(V, F[keep]).face_components()
    near_tip = keep[np.argmin(np.linalg.norm(centroids(V, F[keep]) - tip, axis=1))]
    region = keep[comp == comp[np.searchsorted(keep, near_tip)]]
    ids, inv = np.unique(F[region], return_inverse=True)
    seg = segment(V[ids], inv.reshape(-1, 3), patches=patches, eta=5.0, smoothing_mm=3.0, rng=0,
                  face_groups=poly[region])
    labels = np.full(len(F), -1)
    labels[region] = seg.face_labels
    return V, F, labels


def test_second_run_says_the_borders_are_already_smooth():
    V, F, h = sheet()
    c = centroids(V, F)
    labels = (c[:, 0] > 50 + 0.3 * (c[:, 1] - 50)).astype(int)
    _, second = assert_second_run_changes_nothing(V, F, labels)
    (rep,) = second.borders
    assert rep.note.startswith("already smooth")


@pytest.mark.parametrize("case", ["parabola", "ellipse", "three patches", "tube ring", "dome"])
def test_second_run_changes_nothing_on_synthetic_meshes(case):
    if case == "tube ring":
        prof = np.stack([np.full(31, 40.0), np.linspace(0, 120, 31)], 1)
        V, F, _ = ring_surface(prof, na=48, pole=False)
        c = centroids(V, F)
        labels = (c[:, 2] > 60 + 0.3 * c[:, 0]).astype(int)
    elif case == "dome":
        V, F = spherical_cap(50, 80, 4)
        c = centroids(V, F)
        labels = (np.linalg.norm(c[:, :2] - [10, 5], axis=1) < 20).astype(int)
    elif case == "three patches":
        V, F = grid(30, 30, size=100.0, jitter=0.2)
        c = centroids(V, F)
        upper = np.where(c[:, 1] + 2 * np.cos(c[:, 0] / 5) < 50, 1, 2)
        labels = np.where(c[:, 0] + 3 * np.sin(c[:, 1] / 7) < 40, 0, upper)
    else:
        V, F, _ = sheet()
        c = centroids(V, F)
        if case == "parabola":
            labels = (c[:, 0] - 50 - 0.01 * (c[:, 1] - 50) ** 2 > 0).astype(int)
        else:
            labels = (np.linalg.norm(c[:, :2] - [45, 55], axis=1) < 25).astype(int)
    first, second = assert_second_run_changes_nothing(V, F, labels)
    check_invariants(V, F, labels, first)


def test_border_already_on_mesh_edges_is_left_alone():
    """A straight border along a row of mesh edges is already a smooth cut: no error, no change."""
    V, F, h = sheet()
    c = centroids(V, F)
    labels = (c[:, 0] > 50.0).astype(int)
    res = smooth_cuts(V, F, labels)
    assert not res.changed and res.new_vertex_count == 0
    np.testing.assert_array_equal(res.F, F)
    np.testing.assert_array_equal(res.labels, labels)
    (rep,) = res.borders
    assert rep.method == "unchanged" and rep.note.startswith("already smooth")


@pytest.mark.parametrize("patches", [4, 5])
def test_second_run_changes_nothing_on_the_demo_nose(patches):
    """The demo's nose region; a second run re-cut 3 of 9 (4 patches) and 9 of 9
    (5 patches) borders and added 34 and 98 vertices."""
    V, F, labels = nose_region(patches)
    assert len(np.unique(labels[labels >= 0])) == patches
    first, _ = assert_second_run_changes_nothing(V, F, labels)
    out = first.labels < 0
    assert first.face_unchanged[out].all() and out.sum() == (labels < 0).sum()


def test_second_run_changes_nothing_on_a_segmented_real_face():
    V, F, poly = load_obj(data_mesh("ict_face_narrow.obj"), 10.0)  # cm -> mm
    seg = segment(V, F, patches=5, eta=5.0, smoothing_mm=3.0, rng=0, face_groups=poly)
    first, _ = assert_second_run_changes_nothing(V, F, seg.face_labels)
    for r in first.borders:
        assert r.turning_after < r.turning_before, r
    tb = sum(r.turning_before * r.length_before_mm for r in first.borders)
    ta = sum(r.turning_after * r.length_after_mm for r in first.borders)
    assert ta / tb == pytest.approx(0.0255, rel=0.15)  # measured: the length-weighted turning 97.5 % lower
