"""Sharp creases on the marched bolus solid: every vertex on its own face of the field, and the
chamfers marching cubes cuts across the creases replaced by vertices on the creases.

Marching cubes puts each vertex on a lattice edge by linear interpolation, so where two of the
field's terms (inner face, outer face, rim wall: `distance_field.SkinDistance.terms_and_feet`)
meet at an angle it cuts the crease off by up to half a voxel.  After Kobbelt et al.'s Extended
Marching Cubes (2001), done on the mesh rather than in the cells:

1. each vertex is labelled by its smallest term; one near the outer and end loops that would
   land outside a second face when moved onto its own is moved onto the crease of the two by
   alternating projections (the others stay as marched);
2. every edge whose ends lie on different faces gets a midpoint moved onto their crease the same
   way (the edge is left whole where that fails to converge, moves the point more than a voxel,
   or turns a new triangle over);
3. each triangle with such midpoints is split so that every new triangle lies on one face.

Hole walls (the hole term and the cutters) are left as marched.  Arrays: V (n,3) float64 mm,
F (m,3) int64 outward wound; out the same.
"""
from __future__ import annotations

import numpy as np

from ..mesh.crossings import crossing_pairs

__all__ = ["sharpen_creases", "CREASE_ROUNDS"]

#: alternating projections between two faces to reach their crease
CREASE_ROUNDS = 4
#: rounds of undoing the moves that make triangles cross (then every move is undone)
CROSS_ROUNDS = 6


class _Faces:
    """The field's three faces at points: values (k,3) and the nearest point of each face (k,3,3)
    (NaN where a face has none: the rim term of a hole, or beyond the cap)."""

    def __init__(self, skin, t, c, cap):
        self.skin, self.args = skin, (t, c, cap)

    def __call__(self, X):
        a, b, r, Pi, Po, Pw = self.skin.terms_and_feet(X, *self.args)
        return np.stack([a, b, r], axis=1), np.stack([Pi, Po, Pw], axis=1)

    def near_wall(self, X):
        """(k,) bool: points X (k,3) close enough to the outer and end loops to lie at a crease of
        the wall (within 1.5 t + 3 cap of their border)."""
        t, _, cap = self.args
        d, _ = self.skin.wall_tree.query(X, workers=2, distance_upper_bound=1.5 * t + 3 * cap)
        return np.isfinite(d)

    def project(self, X, face):
        """X (k,3) moved onto face (k,) of {0, 1, 2}; unmoved where that face has no point."""
        _, P = self(X)
        Y = P[np.arange(len(X)), face]
        return np.where(np.isfinite(Y).all(axis=1)[:, None], Y, X)

    def onto_crease(self, X, f1, f2, rounds=CREASE_ROUNDS):
        """X (k,3) moved onto the crease of faces f1 and f2 (k,) by alternating projections:
        (points (k,3), values (k,3) there)."""
        for _ in range(rounds):
            X = self.project(X, f1)
            X = self.project(X, f2)
        vals, _ = self(X)
        return X, vals


def _edge_key(a, b, n) -> np.ndarray:
    """(k,) int64 key of the undirected edges (a, b) (k,) among n vertices."""
    return np.minimum(a, b).astype(np.int64) * np.int64(n) + np.maximum(a, b)


def _labels(vals, tol):
    """Bit masks (k,) int: bit j set where term j is the smallest or within tol of 0."""
    lab = np.argmin(vals, axis=1)
    mask = (1 << lab) | ((np.abs(vals) < tol) * np.array([1, 2, 4])).sum(axis=1)
    return lab, mask


def _vertices_on_faces(faces, V, res):
    """Step 1: the vertices within 1.5 res of a second face that land outside it when moved onto
    their own face go onto the crease of the two; the others stay as marched (linear
    interpolation on a lattice edge is within O(res^2 / radius) of a smooth face, and moving
    them can fold the marched triangles): (V (n,3), labels (n,), masks (n,))."""
    tol = 1e-3 * res
    near = faces.near_wall(V)
    vals = np.full((len(V), 3), np.inf)
    vals[~near, :2] = 0.0  # far from the rim: on the inner or the outer face, never at a crease
    P = np.zeros((0, 3, 3))
    if near.any():
        vals[near], P = faces(V[near])
    lab = np.argmin(vals, axis=1)
    second = np.sort(np.abs(vals[near]), axis=1)[:, 1]
    idx = np.nonzero(near)[0][second < 1.5 * res]
    P = P[second < 1.5 * res]
    if len(idx):
        Y = P[np.arange(len(idx)), lab[idx]]
        X = np.where(np.isfinite(Y).all(axis=1)[:, None], Y, V[idx])
        cv, _ = faces(X)
        others = cv.copy()
        others[np.arange(len(idx)), lab[idx]] = np.inf
        out = np.argmin(others, axis=1)
        crease = others[np.arange(len(idx)), out] < -tol
        if crease.any():
            c = np.nonzero(crease)[0]
            Xc, cc = faces.onto_crease(X[c], lab[idx[c]], out[c])
            j = np.arange(len(c))
            ok = (np.abs(cc[j, lab[idx[c]]]) < 10 * tol) & (np.abs(cc[j, out[c]]) < 10 * tol) & \
                 (np.linalg.norm(Xc - V[idx[c]], axis=1) < res)
            idx = idx[c[ok]]
            V[idx], vals[idx] = Xc[ok], cc[ok]
    _, mask = _labels(vals, 10 * tol)
    return V, lab, mask


def _crease_midpoints(faces, V, F, lab, mask, res):
    """Step 2: the mixed edges (e,2) (ends with no face in common), their crease points (e,3),
    and which were accepted (e,)."""
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    E = E[(mask[E[:, 0]] & mask[E[:, 1]]) == 0]  # each mixed edge twice, once from each face
    n = np.int64(len(V))
    key = np.unique(_edge_key(E[:, 0], E[:, 1], n))
    E = np.stack([key // n, key % n], axis=1)
    if len(E) == 0:
        return E, np.zeros((0, 3)), np.zeros(0, dtype=bool)
    m0 = 0.5 * (V[E[:, 0]] + V[E[:, 1]])
    f1, f2 = lab[E[:, 0]], lab[E[:, 1]]
    X, cv = faces.onto_crease(m0, f1, f2)
    tol = 1e-2 * res
    i = np.arange(len(E))
    ok = (np.abs(cv[i, f1]) < tol) & (np.abs(cv[i, f2]) < tol) & (np.linalg.norm(X - m0, axis=1) < res)
    ok &= np.isfinite(X).all(axis=1)
    return E, X, ok


def _split(V, F, E, X, ok):
    """Step 3: faces split at the accepted crease points X of edges E: (V', F', parent (m',))."""
    n = len(V)
    E, X = E[ok], X[ok]
    key = _edge_key(E[:, 0], E[:, 1], n)
    order = np.argsort(key)
    key, mid = key[order], n + order
    V2 = np.concatenate([V, X])

    def midpoint(a, b):
        k = _edge_key(a, b, n)
        pos = np.clip(np.searchsorted(key, k), 0, max(len(key) - 1, 0))
        hit = (key[pos] == k) if len(key) else np.zeros(len(k), dtype=bool)
        return np.where(hit, mid[pos] if len(key) else -1, -1)

    M = np.stack([midpoint(F[:, j], F[:, (j + 1) % 3]) for j in range(3)], axis=1)  # edge j -> j+1
    out, parent = [F[(M < 0).all(axis=1)]], [np.nonzero((M < 0).all(axis=1))[0]]
    cnt = (M >= 0).sum(axis=1)
    for j in range(3):  # one split edge: j -> j+1
        s = np.nonzero((cnt == 1) & (M[:, j] >= 0))[0]
        p, q, r, m = F[s, j], F[s, (j + 1) % 3], F[s, (j + 2) % 3], M[s, j]
        out += [np.stack([p, m, r], 1), np.stack([m, q, r], 1)]
        parent += [s, s]
    for j in range(3):  # two split edges, edge j -> j+1 whole: p q whole, r beyond
        s = np.nonzero((cnt == 2) & (M[:, j] < 0))[0]
        p, q, r = F[s, j], F[s, (j + 1) % 3], F[s, (j + 2) % 3]
        m1, m2 = M[s, (j + 1) % 3], M[s, (j + 2) % 3]  # on q-r and r-p
        short = np.linalg.norm(V2[p] - V2[m1], axis=1) <= np.linalg.norm(V2[q] - V2[m2], axis=1)
        t1 = np.where(short[:, None], np.stack([p, q, m1], 1), np.stack([p, q, m2], 1))
        t2 = np.where(short[:, None], np.stack([p, m1, m2], 1), np.stack([q, m1, m2], 1))
        out += [t1, t2, np.stack([m2, m1, r], 1)]
        parent += [s, s, s]
    s = np.nonzero(cnt == 3)[0]
    a, b, c = F[s, 0], F[s, 1], F[s, 2]
    mab, mbc, mca = M[s, 0], M[s, 1], M[s, 2]
    out += [np.stack(x, 1) for x in ((a, mab, mca), (mab, b, mbc), (mca, mbc, c), (mab, mbc, mca))]
    parent += [s] * 4
    return V2, np.concatenate(out).astype(np.int64), np.concatenate(parent)


def _turned(V, F, V2, F2, parent):
    """(m',) bool: new triangles whose normal turned against their parent's (or vanished)."""
    def normals(P, T):
        return np.cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]])
    n0 = normals(V, F)[parent]
    n1 = normals(V2, F2)
    return np.einsum("ij,ij->i", n0, n1) <= 0


def _split_unturned(V, FA, E, X, ok, keys, n):
    """`_split` of the faces FA (k,3) at the crease midpoints X of the edges E marked ok, with
    the edges of every parent whose child turned over left whole (ok updated in place)."""
    for _ in range(20):  # each round leaves more edges whole: it ends
        V2, F2, parent = _split(V, FA, E, X, ok)
        bad = _turned(V, FA, V2, F2, parent)
        if not bad.any():
            return V2, F2, parent
        # the edges of the parents of turned triangles stay whole
        Fb = FA[np.unique(parent[bad])]
        Eb = np.concatenate([Fb[:, [0, 1]], Fb[:, [1, 2]], Fb[:, [2, 0]]])
        ok &= ~np.isin(keys, _edge_key(Eb[:, 0], Eb[:, 1], n))
    ok[:] = False
    return _split(V, FA, E, X, ok)


def sharpen_creases(skin, V, F, t, c, cap, res):
    """The marched solid (V (n,3), F (m,3)) with its vertices on the field's faces and its
    creases sharp (module docstring).  skin: `SkinDistance`; t, c, cap: the field's thickness,
    clearance and rim cap (mm); res: the voxel size (mm).  Returns (V', F', figures dict).

    A move that makes two triangles cross (`crossing_pairs` in float32, as an STL file and
    Blender's checks hold the positions; a vertex pulled onto a crease past a neighbour's face)
    is undone: the vertices of both go back where marching cubes put them
    and their edges stay whole, until no moved triangle crosses another."""
    faces = _Faces(skin, t, c, cap)
    V0 = V.copy()
    V, lab, mask = _vertices_on_faces(faces, np.array(V, dtype=np.float64), res)
    turned = _turned(V0, F, V, F, np.arange(len(F)))
    if turned.any():  # a vertex whose move turned a face over goes back where it was
        back = np.unique(F[turned])
        V[back] = V0[back]
        mask[back] = 1 << lab[back]
    E, X, ok = _crease_midpoints(faces, V, F, lab, mask, res)
    # only the faces with a vertex on a mixed edge can change
    touched = np.zeros(len(V), dtype=bool)
    touched[E.ravel()] = True
    A = touched[F].any(axis=1)
    FA = F[A]
    keys = _edge_key(E[:, 0], E[:, 1], len(V))
    undone = 0
    for _ in range(CROSS_ROUNDS):
        V2, F2, parent = _split_unturned(V, FA, E, X, ok, keys, len(V))
        Fall = np.concatenate([F[~A], F2])
        moved = np.any(V != V0, axis=1)  # the vertices pulled onto a crease
        among = np.concatenate([np.nonzero(moved[F[~A]].any(axis=1))[0], np.sum(~A) + np.arange(len(F2))])
        pairs = crossing_pairs(V2, Fall, among, float32=True)
        if len(pairs) == 0:
            break
        tri = np.unique(pairs)
        verts = np.unique(Fall[tri])
        verts = verts[verts < len(V)]  # the split midpoints belong to the edges below
        undone += len(tri)
        V[verts] = V0[verts]
        kids = tri[tri >= np.sum(~A)] - np.sum(~A)
        Fb = np.concatenate([FA[np.unique(parent[kids])], F[np.isin(F, verts).any(axis=1)]])
        Eb = np.concatenate([Fb[:, [0, 1]], Fb[:, [1, 2]], Fb[:, [2, 0]]])
        ok &= ~np.isin(keys, _edge_key(Eb[:, 0], Eb[:, 1], len(V)))
    else:
        ok[:] = False
        V = V0.copy()
        V2, F2, parent = _split(V, FA, E, X, ok)
        Fall = np.concatenate([F[~A], F2])
    figures = {"crease_vertices": int(((mask & (mask - 1)) != 0).sum()),
               "crease_edges_split": int(ok.sum()), "crease_edges_whole": int((~ok).sum()),
               "faces_turned_back": int(turned.sum()), "crossing_triangles_undone": undone}
    return V2, Fall, figures
