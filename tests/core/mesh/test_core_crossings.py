"""Crossing triangles: against a plane-clipping test (and libigl's, where installed), pair by pair."""
import igl
import numpy as np
from meshgen import icosphere

from bolus_addon.core.mesh.crossings import crossing_pairs


def _clip_to_plane(T, n, d):
    """The segment (2,3) where triangle T (3,3) meets the plane n.x = d, or None."""
    s = T @ n - d
    pts = [T[k] + (T[(k + 1) % 3] - T[k]) * (s[k] / (s[k] - s[(k + 1) % 3]))
           for k in range(3) if s[k] * s[(k + 1) % 3] < 0]
    return np.array(pts) if len(pts) == 2 else None


def _segment_meets_triangle_2d(S, T):
    """The 2-D segment S (2,2) and triangle T (3,2) share a point (an end inside, or an edge crossing)."""
    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    for p in S:
        o = [orient(T[k], T[(k + 1) % 3], p) for k in range(3)]
        if all(x > 0 for x in o) or all(x < 0 for x in o):
            return True
    for k in range(3):
        a, b = T[k], T[(k + 1) % 3]
        if orient(a, b, S[0]) * orient(a, b, S[1]) < 0 and orient(S[0], S[1], a) * orient(S[0], S[1], b) < 0:
            return True
    return False


def _reference_crossing(V, F, i, j) -> bool:
    """Triangles i and j cross: A clipped by B's plane gives a segment that meets B, in B's plane
    (a plane-clipping test, unlike the signed-volume one under test); libigl's own exact test
    too where the installed libigl has it."""
    A, B = V[F[i]], V[F[j]]
    n = np.cross(B[1] - B[0], B[2] - B[0])
    S = _clip_to_plane(A, n, n @ B[0])
    if S is None:
        hit = False
    else:
        axes = np.delete(np.arange(3), np.argmax(np.abs(n)))  # project along B's dominant normal axis
        hit = _segment_meets_triangle_2d(S[:, axes], B[:, axes])
    if hasattr(igl, "tri_tri_intersection_test_3d"):
        args = [np.ascontiguousarray(X[k][None]) for X in (A, B) for k in range(3)]
        igl_hit, coplanar, _, _ = igl.tri_tri_intersection_test_3d(*args)
        assert hit == (bool(igl_hit) and not bool(coplanar))
    return hit


def test_two_crossing_triangles_and_a_touching_one():
    V = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0],          # in z = 0
                  [0.5, 0.5, -1], [0.5, 0.5, 1], [1.5, 1.5, 1],  # through it
                  [3, 0, 0], [4, 0, 1], [4, 1, -1]], float)   # a corner on its plane, outside it
    F = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    assert crossing_pairs(V, F).tolist() == [[0, 1]]
    # the same with only the third triangle asked about: it crosses nothing
    assert len(crossing_pairs(V, F, among=[2])) == 0
    assert crossing_pairs(V, F, among=[1]).tolist() == [[0, 1]]


def test_random_soup_agrees_with_libigl_pair_by_pair():
    rng = np.random.default_rng(7)
    centres = rng.uniform(0, 10, (300, 1, 3))
    V = (centres + rng.normal(0, 1.0, (300, 3, 3))).reshape(-1, 3)
    F = np.arange(len(V)).reshape(-1, 3)
    ours = {tuple(p) for p in crossing_pairs(V, F).tolist()}
    theirs = {(i, j) for i in range(len(F)) for j in range(i + 1, len(F)) if _reference_crossing(V, F, i, j)}
    assert len(theirs) > 20  # the soup is dense enough to test something
    assert ours == theirs


def test_a_closed_sphere_has_none_and_a_dented_one_has_some():
    V, F = icosphere(3)
    V = np.asarray(V, float) * 50.0
    F = np.asarray(F)
    assert len(crossing_pairs(V, F)) == 0
    # push one vertex through the far side of the sphere: its fan now crosses the faces there
    far = np.argmin(V @ V[0])
    V2 = V.copy()
    V2[0] = V[far] * 1.2
    pairs = crossing_pairs(V2, F, among=np.nonzero((F == 0).any(axis=1))[0])
    assert len(pairs)
    for i, j in pairs:
        assert _reference_crossing(V2, F, i, j)


def test_float32_sees_what_a_float32_file_holds():
    # a triangle whose corner pokes 1e-5 mm through a plane at z = 500 mm: a crossing in float64,
    # none once the positions are rounded to float32 (spacing 3e-5 mm there: the corner lands on
    # the plane and only touches it)
    z = 500.0
    V = np.array([[0, 0, z], [10, 0, z], [0, 10, z],
                  [1, 1, z + 1e-5], [0.5, 2, z - 5], [2, 0.5, z - 5]], float)
    F = np.array([[0, 1, 2], [3, 4, 5]])
    assert np.float32(V[3, 2]) == np.float32(z)
    assert len(crossing_pairs(V, F)) == 1
    assert len(crossing_pairs(V, F, float32=True)) == 0
