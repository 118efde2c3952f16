"""Synthetic test meshes with known geometry (numpy only)."""
from __future__ import annotations

import numpy as np


def grid(nx: int = 10, ny: int = 10, size: float = 100.0, jitter: float = 0.0, rng=0):
    """Flat triangulated square in z = 0: V ((nx+1)(ny+1), 3), F (2 nx ny, 3)."""
    xs, ys = np.meshgrid(np.linspace(0, size, nx + 1), np.linspace(0, size, ny + 1), indexing="ij")
    V = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    if jitter:
        g = np.random.default_rng(rng)
        inner = (xs.ravel() > 0) & (xs.ravel() < size) & (ys.ravel() > 0) & (ys.ravel() < size)
        V[inner, :2] += g.uniform(-jitter, jitter, (inner.sum(), 2)) * size / nx
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return V, F


def bump_quads(n: int = 16, size: float = 100.0):
    """An (n x n)-quad grid of `size` with a Gaussian bump 0.2 size high in the middle: V ((n+1)^2, 3), F (n^2, 4)."""
    xs = np.linspace(0.0, size, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    Z = 0.2 * size * np.exp(-((X - size / 2) ** 2 + (Y - size / 2) ** 2) / (0.06 * size * size))
    V = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    F = np.stack([idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()], axis=1)
    return V, F


def height_field(fn, nx=20, ny=20, size=100.0):
    """Grid with z = fn(x, y), centred on the origin."""
    V, F = grid(nx, ny, size)
    V[:, :2] -= size / 2
    V[:, 2] = fn(V[:, 0], V[:, 1])
    return V, F


def cylinder_piece(radius=50.0, angle=np.pi, length=100.0, na=16, nl=10):
    """Part of a cylinder (developable): interior angle sums are exactly 2 pi."""
    t, z = np.meshgrid(np.linspace(0, angle, na + 1), np.linspace(0, length, nl + 1), indexing="ij")
    V = np.stack([radius * np.cos(t.ravel()), radius * np.sin(t.ravel()), z.ravel()], axis=1)
    _, F = grid(na, nl)
    return V, F


def icosphere(subdivisions: int = 2, radius: float = 1.0):
    """Closed genus-0 triangle mesh on a sphere."""
    p = (1 + 5**0.5) / 2
    V = np.array(
        [[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p], [0, -1, -p], [0, 1, -p],
         [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]], dtype=float)
    F = np.array(
        [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
         [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    for _ in range(subdivisions):
        E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(E, axis=0, return_inverse=True)
        mids = len(V) + inv.reshape(3, -1).T  # (m,3): midpoints of edges 01, 12, 20
        V = np.vstack([V, 0.5 * (V[uniq[:, 0]] + V[uniq[:, 1]])])
        a, b, c = F.T
        ab, bc, ca = mids.T
        F = np.concatenate([np.stack([a, ab, ca], 1), np.stack([b, bc, ab], 1), np.stack([c, ca, bc], 1), np.stack([ab, bc, ca], 1)])
    V = radius * V / np.linalg.norm(V, axis=1, keepdims=True)
    return V, F


def ring_surface(profile_rz: np.ndarray, na: int = 48, pole: bool = True):
    """Surface of revolution from a profile of (r, z) rings, outermost first.

    With ``pole`` a final vertex on the axis closes the innermost ring (a cap).
    Returns V, F and ring (n,) the profile index of each vertex (-1 for the pole).
    """
    profile_rz = np.asarray(profile_rz, dtype=float)
    nr = len(profile_rz)
    t = np.linspace(0, 2 * np.pi, na, endpoint=False)
    V = np.concatenate([np.stack([r * np.cos(t), r * np.sin(t), np.full(na, z)], 1) for r, z in profile_rz])
    ring = np.repeat(np.arange(nr), na)
    F = []
    for i in range(nr - 1):
        for j in range(na):
            a, b = i * na + j, i * na + (j + 1) % na
            c, d = (i + 1) * na + (j + 1) % na, (i + 1) * na + j
            F += [[a, b, c], [a, c, d]]
    if pole:
        top = np.max(profile_rz[:, 1]) if profile_rz[-1, 0] > 0 else profile_rz[-1, 1]
        V = np.vstack([V, [0, 0, top]])
        ring = np.r_[ring, -1]
        last = (nr - 1) * na
        for j in range(na):
            F.append([last + j, last + (j + 1) % na, len(V) - 1])
    return V, np.asarray(F), ring


def sheet_with_dome(R=30.0, R_out=90.0, n_sheet=12, n_dome=8, na=48):
    """Flat annulus (R..R_out in z = 0) joined at r = R to a hemisphere cap of radius R.

    Returns V, F and the geodesic distance (n,) of every vertex from the junction circle
    (negative on the sheet, positive on the dome).
    """
    r_sheet = np.linspace(R_out, R, n_sheet + 1)
    phi = np.linspace(np.pi / 2, 0, n_dome + 1)[1:-1]  # dome rings strictly between equator and pole
    profile = np.concatenate([np.stack([r_sheet, np.zeros_like(r_sheet)], 1), np.stack([R * np.sin(phi), R * np.cos(phi)], 1)])
    V, F, ring = ring_surface(profile, na=na, pole=True)
    # pole sits at z = R
    V[-1] = [0, 0, R]
    geo = np.empty(len(V))
    on_sheet = ring <= n_sheet
    ring_c = np.clip(ring, 0, None)
    geo[on_sheet] = -(r_sheet[ring_c[on_sheet]] - R)
    dome = (~on_sheet) & (ring >= 0)
    geo[dome] = R * (np.pi / 2 - phi[ring[dome] - n_sheet - 1])
    geo[ring < 0] = R * np.pi / 2
    # consistent outward orientation (normals +z on the sheet)
    return V, F, geo


def spherical_cap(R=100.0, half_angle_deg=60.0, subdivisions=5):
    """Spherical cap of radius R up to the polar angle half_angle (open disk), cut from an
    icosphere (well-shaped triangles; 5 subdivisions: 20,480 faces on the whole sphere)."""
    V, F = icosphere(subdivisions, R)
    # rotate so that no icosphere vertex sits exactly on the pole axis direction bias
    C = V[F].mean(axis=1)
    keep = C[:, 2] / np.linalg.norm(C, axis=1) >= np.cos(np.radians(half_angle_deg))
    Fk = F[keep]
    used, inv = np.unique(Fk, return_inverse=True)
    return V[used], inv.reshape(-1, 3)


def cone_piece(r0=20.0, r1=60.0, height=50.0, angle=np.pi, na=24, nl=10):
    """Part of a cone (developable)."""
    t, s = np.meshgrid(np.linspace(0, angle, na + 1), np.linspace(0, 1, nl + 1), indexing="ij")
    r = r0 + (r1 - r0) * s
    V = np.stack([(r * np.cos(t)).ravel(), (r * np.sin(t)).ravel(), (height * s).ravel()], axis=1)
    _, F = grid(na, nl)
    return V, F


def grid_with_holes(nx=12, ny=12, size=120.0, holes=((4, 4, 8, 8),)):
    """Grid with rectangular holes: each hole (i0, j0, i1, j1) removes the cells i0 <= i < i1,
    j0 <= j < j1 (cell (i, j) spans x in [i, i+1] * size / nx).  Unused vertices are dropped."""
    V, F = grid(nx, ny, size)
    ci, cj = np.divmod(np.arange(nx * ny), ny)
    cell_i, cell_j = np.r_[ci, ci], np.r_[cj, cj]  # grid() lists the two triangles of every cell
    keep = np.ones(len(F), dtype=bool)
    for i0, j0, i1, j1 in holes:
        keep &= ~((cell_i >= i0) & (cell_i < i1) & (cell_j >= j0) & (cell_j < j1))
    F = F[keep]
    used = np.unique(F)
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    return V[used], remap[F]


def torus(R=60.0, r=20.0, na=32, nb=12):
    """Closed torus (genus 1) around the z axis, outward normals."""
    a, b = np.meshgrid(np.linspace(0, 2 * np.pi, na, endpoint=False), np.linspace(0, 2 * np.pi, nb, endpoint=False),
                       indexing="ij")
    V = np.stack([(R + r * np.cos(b)) * np.cos(a), (R + r * np.cos(b)) * np.sin(a), r * np.sin(b)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(na), np.arange(nb), indexing="ij")
    p00, p10 = i * nb + j, ((i + 1) % na) * nb + j
    p11, p01 = ((i + 1) % na) * nb + (j + 1) % nb, i * nb + (j + 1) % nb
    F = np.concatenate([np.stack([p00, p10, p11], -1).reshape(-1, 3), np.stack([p00, p11, p01], -1).reshape(-1, 3)])
    return V, F


def spiral_strip(turns=1.27, r0=60.0, pitch=6.0, width=12.0, na=120, nw=3):
    """Flat strip (z = 0) wound along a spiral of radius r0 - pitch * t / (2 pi): with
    pitch < width and turns > 1 the end lies over the start.  Counter-clockwise triangles,
    none flipped.  Keep na / turns non-integer (not 120 / 1.25): otherwise the angle step
    divides 2 pi, vertices of the end fall exactly on edges of the start and the outlines
    only touch instead of crossing."""
    t, w = np.meshgrid(np.linspace(0, 2 * np.pi * turns, na + 1), np.linspace(-width / 2, width / 2, nw + 1),
                       indexing="ij")
    r = r0 - pitch * t / (2 * np.pi) - w
    V = np.stack([(r * np.cos(t)).ravel(), (r * np.sin(t)).ravel(), np.zeros(t.size)], axis=1)
    _, F = grid(na, nw)
    return V, F


def box(size=(40.0, 30.0, 20.0), n: int = 4):
    """Closed axis-aligned box [0, sx] x [0, sy] x [0, sz], each side an n x n grid, outward normals."""
    size = np.asarray(size, dtype=float)
    Vs, Fs, off = [], [], 0
    for axis in range(3):
        u, v = [k for k in range(3) if k != axis]
        for side in (0.0, 1.0):
            G, Fg = grid(n, n, 1.0)
            P = np.zeros((len(G), 3))
            P[:, u], P[:, v], P[:, axis] = G[:, 0], G[:, 1], side
            Vs.append(P * size)
            Fs.append(Fg + off)
            off += len(G)
    V, F = np.concatenate(Vs), np.concatenate(Fs)
    key = np.round(V / size.max() * 1e6).astype(np.int64)
    uniq, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    V, F = V[first], inv.reshape(-1)[F]
    C = V[F].mean(axis=1) - size / 2
    nrm = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    inward = np.einsum("ij,ij->i", nrm, C) < 0
    F[inward] = F[inward][:, ::-1]
    return V, F


def graded_strip(length=200.0, width=20.0, coarse_cells=10, fine_cells=160, ny=4):
    """Flat strip in z = 0 along x: the first half in ``coarse_cells`` big cells, the second
    half in ``fine_cells`` small ones (same ny rows across).  Face count and area are far
    apart: most triangles lie in the fine half, which holds only half the area."""
    xs = np.r_[np.linspace(0.0, length / 2, coarse_cells + 1), np.linspace(length / 2, length, fine_cells + 1)[1:]]
    ys = np.linspace(0.0, width, ny + 1)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    _, F = grid(len(xs) - 1, ny)
    return V, F


def degenerate_variants(V, F):
    """Broken copies of a mesh V (n,3), F (m,3) (triangle 0 must be interior-ish), for the
    degenerate-input tests of every public core function:
    {name: (V', F', what the refusal must say, or None where the mesh is sound)}.

    coincident: a vertex duplicated onto another and used in a new triangle (zero area);
    collinear: a new triangle whose three corners lie on a line; nan / inf: one vertex
    non-finite; needle: a new triangle with a 0.01 degree angle (positive area: sound);
    nonmanifold: a third triangle on an interior edge.
    """
    V = np.asarray(V, dtype=float)
    F = np.asarray(F, dtype=np.int64)
    n = len(V)
    a, b, c = (int(x) for x in F[0])
    e = V[b] - V[a]
    out = {}
    out["coincident"] = (np.r_[V, V[b][None]], np.r_[F, [[a, b, n]]], "zero-area")
    out["collinear"] = (np.r_[V, [V[a] - e, V[a] - 2 * e]], np.r_[F, [[a, n, n + 1]]], "zero-area")
    Vn = V.copy()
    Vn[c, 0] = np.nan
    out["nan"] = (Vn, F.copy(), f"vertex {c}")
    Vi = V.copy()
    Vi[c, 2] = np.inf
    out["inf"] = (Vi, F.copy(), f"vertex {c}")
    side = np.cross(e, V[c] - V[a])
    side = np.cross(side, e)
    side /= np.linalg.norm(side) + 1e-300
    out["needle"] = (np.r_[V, [V[a] - side * np.linalg.norm(e) * 1e-4 + e * 0.5]], np.r_[F, [[b, a, n]]], None)
    E = np.sort(np.c_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]].reshape(-1, 2), axis=1)
    keys, counts = np.unique(E, axis=0, return_counts=True)
    p, q = (int(x) for x in keys[np.argmax(counts == 2)])  # an interior edge
    top = 0.5 * (V[p] + V[q]) + np.r_[0.0, 0.0, np.linalg.norm(V[q] - V[p])]
    out["nonmanifold"] = (np.r_[V, top[None]], np.r_[F, [[p, q, n]]], "non-manifold")
    return out


def freeform_patch(a=32.0, b=27.0, n_border=17, n_inner=72, bump=10.0, dip=7.0, bump_sigma=8.0, dip_sigma=7.0):
    """A free-form height-field patch like the seed's Table 4-3 example (4.4.1): V (89,3) mm, F (159,3).

    Outline: n_border points on an ellipse of half-axes a x b mm (64 x 54 mm); inside:
    n_inner points on a sunflower spiral (within 0.9 of the ellipse); Delaunay in the
    plane (scipy), faces counter-clockwise seen from +z (normals +z = outward).  Height:
    a Gaussian bump (bump mm high, sigma bump_sigma) at (-11, 4) and a dip (dip mm deep,
    sigma dip_sigma) at (12, -5).  At the defaults: 89 nodes, 247 edges, 159 faces (the
    seed's counts), raw FLV 0.68 (seed 0.65), largest varpi 0.43 (seed 0.29), area 2875 mm2
    (seed 2872).
    """
    from scipy.spatial import Delaunay

    t = 2.0 * np.pi * np.arange(n_border) / n_border
    k = np.arange(n_inner) + 0.5
    r = 0.9 * np.sqrt(k / n_inner)
    phi = k * np.pi * (3.0 - np.sqrt(5.0))
    P = np.r_[np.c_[a * np.cos(t), b * np.sin(t)], np.c_[a * r * np.cos(phi), b * r * np.sin(phi)]]
    F = Delaunay(P).simplices.astype(np.int64)
    e1, e2 = P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]]
    cw = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    F[cw] = F[cw][:, ::-1]
    x, y = P.T
    z = (bump * np.exp(-((x + 11.0) ** 2 + (y - 4.0) ** 2) / (2.0 * bump_sigma ** 2))
         - dip * np.exp(-((x - 12.0) ** 2 + (y + 5.0) ** 2) / (2.0 * dip_sigma ** 2)))
    return np.c_[P, z], F


def cone(half_angle_deg=40.0, slant=60.0, rings=25, na=64):
    """A cone with its apex (the last vertex) inside the patch: apex angle 80 degrees,
    3136 triangles, all the angle deficit 2 pi (1 - sin 40 deg) = 2.24 rad at the apex."""
    a = np.radians(half_angle_deg)
    s = np.linspace(slant, slant / rings, rings)
    V, F, _ = ring_surface(np.stack([s * np.sin(a), -s * np.cos(a)], 1), na=na, pole=True)
    V[-1] = 0.0
    return V, F


def saddle(c=80.0, n=40):
    """z = (x^2 - y^2) / c on a 100 mm square (3200 triangles): angle excess everywhere,
    EL 2.9 % in one piece."""
    return height_field(lambda x, y: (x**2 - y**2) / c, nx=n, ny=n, size=100.0)
