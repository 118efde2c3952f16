"""Smooth cut lines between patches (seed 4.1.2, Figure 4-2, Table 4-2; 6.2.4, eq. 6-37).

Spectral clustering leaves patch borders that zig-zag along mesh edges.  For every
border between two patches A and B, `smooth_cuts` replaces the zig-zag by a smooth
curve lying on the surface and re-triangulates the faces it crosses:

1. the border's vertices P (k,3), ordered along the border (an open chain, or a closed
   loop when one patch encloses the other);
2. a plane Gamma through them.  The seed writes Gamma as p1 x + p2 y + p3 z + 1 = 0 and
   calls it the *tangent* plane "estimated by nodes in the common boundary".  That form
   cannot express a plane through the origin, and a plane fitted to the border nodes
   alone is not unique when they are (nearly) collinear, which is exactly the case of a
   good border.  We take Gamma through the centroid of P with normal d = the
   area-weighted mean normal of the faces around the border: the least-squares tangent
   plane of the surface there, well defined for straight borders too;
3. P projected on Gamma (eqs. 4-6..4-9, written as p - ((p - c).d) d, which is what
   they compute without dividing by p1) and expressed in in-plane axes (e1 = principal
   direction of the projected nodes, e2 = d x e1);
4. a least-squares curve l in Gamma (eq. 6-37):
   - open border: y = a0 + a1 x (+ a2 x^2).  The line is kept unless the parabola
     clearly fits better: the line's RMS residual exceeds a quarter of the mean border
     edge (less than that is the mesh's own zig-zag) and the parabola lowers the RMS
     by at least 30 %;
   - closed border: an elliptic Fourier curve x(s), y(s) of order K (s starts as the
     arc-length angle of the nodes, then each node's s is moved to its nearest point
     on the fitted curve and the fit redone, four times: orthogonal distance fitting).  Order 1 *is* an ellipse, the seed's "low-order closed
     curve"; order 2 or 3 is taken only when it clearly fits better (same rule) and
     stays a simple curve;
5. the surface S through l perpendicular to Gamma (l swept along d).  Its intersection
   with the faces of A and B near the border is the new cut: S is given as the zero
   set of phi(p) (the signed offset of p's projection from l), each edge of those
   faces that changes sign gets a new vertex where phi = 0 (found by bisection, so the
   vertex lies on the edge: on the original surface, exactly), and every crossed
   triangle is split as in Figure 4-2 (b) into a triangle and a quadrilateral, the
   quadrilateral into two triangles along the diagonal with the larger smallest angle
   (the seed draws one diagonal without saying why);
6. faces are re-labelled by the side of S they lie on, only within a band around the
   border (faces of A or B whose centroid is within R of it), so that far parts of
   the patches, where the extended curve may wander, are left alone.

Snapping: a cut point within ``snap`` (a fraction of the edge) of an edge end is moved
onto that vertex (phi := 0 there), so no sliver triangles; a triangle with an angle
under 1 degree that is still created gets its nearest cut point snapped (up to a
quarter of the edge) and the split is redone.  Cut points on edges shared with a
third patch, or with faces outside the segmented region, are always snapped to a
vertex, so those faces are never split: a cut never enters another patch.

Where the projection is not valid (more than 2 % of the area around the border faces
more than ~78 degrees away from d), or the fitted curve or the new cut strays more
than max(3 h, 15 % of the border length) from the border (symmetric Hausdorff
distance, so a patch that would shrink away is caught too), or the result breaks a rule (the cut leaves the band,
a patch falls apart or vanishes, a jagged piece of border remains, the cut would
not turn measurably less than the border (at most 75 % of its turning) or would move
it less than a tenth of an edge; a valid cut that still turns more than 30 % of the
border is kept only if no later one does better), we try a planar
section (S = a plane: for a loop around a limb, or an arc, the least-squares plane of
the border; for a nearly straight open border, the plane through its line and the
mean surface normal), then a *smoothed path along the surface*: the zero set of the
patch indicator diffused on the surface (two MBO steps: implicit heat step, threshold,
heat step again; a short curve-shortening flow of the border), over a diffusion
length of 2 mean border edges, or 3.5 or 6 when the shorter one still turns more
than 30 % of the jagged border (the smoothest valid one is kept); the diffusion runs
on the faces of the two patches within 2 R + 6 sigma of the border only (R: the band).
A border that still cannot be smoothed is left as it is, and the report says why.

Idempotent (issue 9): a border is "already smooth", and left as it is, when its
vertices lie within a tenth of its mean edge of the curve (or plane section across the
surface) fitted to them, or when the cuts we can make are valid but not measurably
smoother (rules above).  A cut of a|c relabels faces near an a|b|c junction and so
moves the end of an a|b cut made before it; `smooth_cuts` therefore passes over all
borders again (up to six passes; a border is tried again only if one of its two
patches changed since) until a pass changes nothing.  Running it on its own result
then changes nothing either: same V, F and labels, every border 'unchanged'.  The
report rows give each input border's turning before, and after on the whole final
border (its ends included).

Vertices of the input keep their indices; new vertices are appended.  Each vertex
carries its barycentric weights on an original triangle (``vert_src``,
``vert_weights``) and each face its original triangle (``face_parent``), so a caller
can interpolate any attribute onto the new geometry.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import factorized
from scipy.spatial import cKDTree

from .errors import BolusError
from .saliency import cotangent_stiffness, lumped_mass
from .topology import MeshTopology, as_mesh_arrays

__all__ = [
    "Border",
    "BorderReport",
    "SmoothCutResult",
    "border_components",
    "turning_per_mm",
    "project_to_plane",
    "fit_open_curve",
    "fit_closed_curve",
    "closed_curve_points",
    "signed_distance_closed",
    "smooth_cuts",
]

SNAP = 0.05  #: cut points closer than this fraction of the edge to an end snap onto it
SLIVER_DEG = 1.0  #: smallest angle tolerated in a new triangle when snapping can avoid it
HEIGHT_FIELD_COS = 0.2  #: faces around the border must satisfy n.d >= this (about 78 degrees)
CLEARLY_BETTER = 0.7  #: a higher-order curve must lower the RMS residual to <= 70 %
NOISE_FRACTION = 0.25  #: RMS below this fraction of the mean border edge is mesh zig-zag
MAX_FOURIER = 3
PARAM_CORRECTIONS = 4  #: closed fits: parameter-correction rounds (nodes re-parameterised by their nearest curve point)
MBO_SIGMA_EDGES = (2.0, 3.5, 6.0)  #: diffusion lengths tried, in mean border edges
MBO_ITERATIONS = 2
NOT_SMOOTHER = "the cut would not be measurably smoother than the border"
NEGLIGIBLE = "the cut would move the border less than a tenth of an edge"
ALREADY_SMOOTH = "already smooth"
SMOOTH_ENOUGH = 0.3  #: a smoothed path is accepted at once when it turns <= 30 % of the border
MIN_GAIN = 0.25  #: a cut must turn at most (1 - MIN_GAIN) of the border to be worth making
MIN_SHIFT = 0.1  #: a cut moving the border less than this fraction of its mean edge is the same border
ON_CURVE = 0.1  #: border vertices within this fraction of the mean edge of their fitted curve: already that curve
MAX_PASSES = 6  #: passes over all borders until one changes nothing (a later cut moves the ends of earlier ones)


# ---------------------------------------------------------------- borders
@dataclass
class Border:
    """One connected piece of the common border of patches a < b."""

    a: int
    b: int
    edges: np.ndarray  #: (k,2) vertex pairs
    order: np.ndarray | None  #: (j,) vertices along the border (None if it branches)
    closed: bool


def border_components(topo: MeshTopology, labels: np.ndarray) -> list[Border]:
    """Every connected piece of every border between two patches (labels >= 0).

    labels (m,) int; faces with a negative label are not in any patch.
    """
    labels = np.asarray(labels)
    P = topo.face_adjacency_pairs
    E = topo.face_adjacency_edges
    la, lb = labels[P[:, 0]], labels[P[:, 1]]
    keep = (la != lb) & (la >= 0) & (lb >= 0)
    lo, hi, E = np.minimum(la, lb)[keep], np.maximum(la, lb)[keep], E[keep]
    out: list[Border] = []
    for a, b in sorted(set(zip(lo.tolist(), hi.tolist()))):
        pe = np.unique(E[(lo == a) & (hi == b)])
        edges = topo.edges[pe]
        verts, inv = np.unique(edges.ravel(), return_inverse=True)
        inv = inv.reshape(-1, 2)
        G = sp.coo_matrix((np.ones(len(inv)), (inv[:, 0], inv[:, 1])), shape=(len(verts),) * 2)
        ncomp, comp = connected_components(G, directed=False)
        for c in range(ncomp):
            ce = edges[comp[inv[:, 0]] == c]
            order, closed = _order_edges(ce)
            out.append(Border(a, b, ce, order, closed))
    return out


def _order_edges(edges: np.ndarray) -> tuple[np.ndarray | None, bool]:
    """Vertices of a connected edge set along it: (order, closed).

    A border may touch itself at a vertex (four border edges there, a "pinch" of the
    zig-zag); the walk then goes on along the edge that turns least (positions are not
    known here, so: the edge not yet used, preferring the one leading to the vertex
    with unused edges), using every edge once (Hierholzer).  order is None when the
    edges cannot be walked in one go (a real branch).
    """
    nbr: dict[int, list[int]] = {}
    for u, v in edges.tolist():
        nbr.setdefault(u, []).append(v)
        nbr.setdefault(v, []).append(u)
    odd = [k for k, v in nbr.items() if len(v) % 2 == 1]
    if len(odd) not in (0, 2):
        return None, False
    closed = not odd
    start = min(nbr) if closed else min(odd)
    # Hierholzer on the undirected multigraph
    adj = {k: list(v) for k, v in nbr.items()}
    stack, path = [start], []
    while stack:
        u = stack[-1]
        if adj[u]:
            v = adj[u].pop()
            adj[v].remove(u)
            stack.append(v)
        else:
            path.append(stack.pop())
    if len(path) != len(edges) + 1:
        return None, False
    order = np.array(path[::-1], dtype=np.int64)
    if closed:
        order = order[:-1]
    return order, closed


def turning_per_mm(V: np.ndarray, edges: np.ndarray, normals: np.ndarray | None = None) -> tuple[float, float]:
    """(mean absolute turning angle per mm (rad/mm), length (mm)) of a border edge set.

    The turning angle is taken at every vertex joining exactly two of the edges: the
    angle between the incoming and the outgoing direction.  With ``normals`` (n,3)
    (vertex normals of the surface) both directions are first projected on the
    tangent plane, so the measure is the cut's geodesic turning, the bending a
    modeler sees on the skin, without the surface's own curvature (a straight cut
    over a curved nose has none); without them it is the plain 3D angle.  Ends and
    branch points are skipped.  Summed and divided by the total length.
    """
    edges = np.asarray(edges)
    if len(edges) == 0:
        return 0.0, 0.0
    d = V[edges[:, 1]] - V[edges[:, 0]]
    length = float(np.linalg.norm(d, axis=1).sum())
    inc: dict[int, list[int]] = {}
    for i, (u, v) in enumerate(edges.tolist()):
        inc.setdefault(u, []).append(i)
        inc.setdefault(v, []).append(i)
    mids, a_end, b_end = [], [], []
    for vtx, es in inc.items():
        if len(es) != 2:
            continue
        i, j = es
        mids.append(vtx)
        a_end.append(edges[i, 1] if edges[i, 0] == vtx else edges[i, 0])
        b_end.append(edges[j, 1] if edges[j, 0] == vtx else edges[j, 0])
    if not mids:
        return 0.0, length
    mids, a_end, b_end = np.array(mids), np.array(a_end), np.array(b_end)
    di, dj = V[a_end] - V[mids], V[b_end] - V[mids]  # pointing away from the vertex
    if normals is not None:
        nrm = normals[mids]
        di = di - (di * nrm).sum(1, keepdims=True) * nrm
        dj = dj - (dj * nrm).sum(1, keepdims=True) * nrm
    c = (di * dj).sum(1) / np.maximum(np.linalg.norm(di, axis=1) * np.linalg.norm(dj, axis=1), 1e-300)
    total = float((np.pi - np.arccos(np.clip(c, -1.0, 1.0))).sum())
    return total / max(length, 1e-300), length


# ------------------------------------------------------------- curve fitting
def project_to_plane(P: np.ndarray, normal: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Orthogonal projection of points P (k,3) on the plane (normal, origin) (eqs. 4-6..4-9)."""
    d = np.asarray(normal, dtype=np.float64)
    d = d / np.linalg.norm(d)
    return P - np.outer((P - origin) @ d, d)


def _plane_axes(Pg: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origin, e1, e2): principal in-plane direction of projected points and its normal in Gamma."""
    c = Pg.mean(axis=0)
    X = Pg - c
    X = X - np.outer(X @ d, d)
    _, _, Vt = np.linalg.svd(X, full_matrices=False)
    e1 = Vt[0] - np.dot(Vt[0], d) * d
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    return c, e1, e2


def fit_open_curve(x: np.ndarray, y: np.ndarray, noise: float) -> tuple[np.ndarray, int, float]:
    """Least-squares y = f(x), linear or quadratic (eq. 6-37).

    Returns (coefficients, highest power first as in numpy.polyval; order; RMS residual).
    The quadratic is chosen only when it clearly fits better (module doc, step 4).
    """
    fits = []
    for order in (1, 2):
        if len(x) <= order:
            break
        coef = np.polyfit(x, y, order)
        rms = float(np.sqrt(np.mean((np.polyval(coef, x) - y) ** 2)))
        fits.append((coef, order, rms))
    if not fits:
        raise BolusError("a border needs at least 2 points to fit a cut line")
    best = fits[0]
    if len(fits) > 1 and best[2] > NOISE_FRACTION * noise and fits[1][2] <= CLEARLY_BETTER * best[2]:
        best = fits[1]
    return best


def _fourier_design(s: np.ndarray, K: int) -> np.ndarray:
    cols = [np.ones_like(s)]
    for k in range(1, K + 1):
        cols += [np.cos(k * s), np.sin(k * s)]
    return np.stack(cols, axis=1)


def closed_curve_points(coef: np.ndarray, samples: int = 512) -> np.ndarray:
    """Points (samples,2) of the elliptic Fourier curve with coefficients coef (2K+1, 2)."""
    K = (len(coef) - 1) // 2
    s = np.linspace(0.0, 2 * np.pi, samples, endpoint=False)
    return _fourier_design(s, K) @ coef


def _is_simple(poly: np.ndarray) -> bool:
    """True if the closed polygon (k,2) does not cross itself."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    k = len(poly)
    # segment i vs j crossing test, vectorised over all pairs
    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    A, B = a[:, None, :], b[:, None, :]
    C, D = a[None, :, :], b[None, :, :]
    o1, o2 = orient(A, B, C), orient(A, B, D)
    o3, o4 = orient(C, D, A), orient(C, D, B)
    cross = (o1 * o2 < 0) & (o3 * o4 < 0)
    i, j = np.triu_indices(k, 2)
    ok = ~((i == 0) & (j == k - 1))
    return not cross[i[ok], j[ok]].any()


def fit_closed_curve(xy: np.ndarray, noise: float) -> tuple[np.ndarray, int, float]:
    """Least-squares closed curve through an ordered loop xy (k,2) (eq. 6-37).

    Elliptic Fourier series of order K (1 = an ellipse) in the arc-length angle of
    the nodes; returns (coefficients (2K+1,2), K, RMS distance of the nodes from the
    curve).  Higher orders only when they clearly fit better and stay simple.
    """
    closed = np.vstack([xy, xy[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    s = 2 * np.pi * np.r_[0.0, np.cumsum(seg)[:-1]] / max(seg.sum(), 1e-300)
    best = None
    for K in range(1, MAX_FOURIER + 1):
        if len(xy) < 2 * (2 * K + 1):
            break
        sk = s.copy()
        for _ in range(PARAM_CORRECTIONS + 1):
            coef, *_ = np.linalg.lstsq(_fourier_design(sk, K), xy, rcond=None)
            # parameter correction: move each node's parameter to its nearest curve point
            dense = closed_curve_points(coef, 1440)
            nearest = cKDTree(dense).query(xy)[1]
            sk = 2 * np.pi * nearest / 1440.0
        curve = closed_curve_points(coef)
        rms = float(np.sqrt(np.mean(_dist_to_polygon(xy, curve) ** 2)))
        if best is None:
            best = (coef, K, rms)
            continue
        if best[2] > NOISE_FRACTION * noise and rms <= CLEARLY_BETTER * best[2] and _is_simple(curve):
            best = (coef, K, rms)
        else:
            break
    if best is None:
        raise BolusError("a closed border needs at least 6 points to fit a cut curve")
    return best


def _dist_to_polygon(q: np.ndarray, poly: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """Distance (k,) of points q (k,2) to the closed polygon poly (s,2)."""
    a = poly
    ab = np.roll(poly, -1, axis=0) - a
    ll = np.maximum((ab**2).sum(axis=1), 1e-300)
    out = np.empty(len(q))
    for s in range(0, len(q), chunk):
        p = q[s : s + chunk, None, :]
        t = np.clip(((p - a) * ab).sum(axis=2) / ll, 0.0, 1.0)
        d = p - (a + t[..., None] * ab)
        out[s : s + chunk] = np.sqrt((d**2).sum(axis=2).min(axis=1))
    return out


def _fourier_derivs(coef: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Curve point, first and second derivative (each (k,2)) at parameters s (k,)."""
    K = (len(coef) - 1) // 2
    c = np.tile(coef[0], (len(s), 1))
    d1 = np.zeros((len(s), 2))
    d2 = np.zeros((len(s), 2))
    for k in range(1, K + 1):
        a, b = coef[2 * k - 1], coef[2 * k]
        cs, sn = np.cos(k * s)[:, None], np.sin(k * s)[:, None]
        c += a * cs + b * sn
        d1 += k * (-a * sn + b * cs)
        d2 += -k * k * (a * cs + b * sn)
    return c, d1, d2


def signed_distance_closed(q: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """Signed distance (k,) of points q (k,2) to the closed Fourier curve ``coef``: negative inside.

    The nearest curve point is found on 2048 samples and refined by Newton's method on
    (c(s) - q) . c'(s) = 0, so the zero set is the exact curve, not a polygon of it;
    the sign is that of (q - c(s)) . outward normal.
    """
    ns = 2048
    grid_s = np.linspace(0.0, 2 * np.pi, ns, endpoint=False)
    dense = closed_curve_points(coef, ns)
    x, y = dense[:, 0], dense[:, 1]
    ccw = (x * np.roll(y, -1) - np.roll(x, -1) * y).sum() > 0
    s = grid_s[cKDTree(dense).query(q)[1]]
    h = 2 * np.pi / ns
    for _ in range(8):
        c, d1, d2 = _fourier_derivs(coef, s)
        r = c - q
        g = (r * d1).sum(1)
        dg = (d1 * d1).sum(1) + (r * d2).sum(1)
        step = np.where(dg > 0, -g / np.where(dg > 0, dg, 1.0), 0.0)
        s = s + np.clip(step, -h, h)
    c, d1, _ = _fourier_derivs(coef, s)
    out_normal = np.stack([d1[:, 1], -d1[:, 0]], 1) * (1.0 if ccw else -1.0)
    r = q - c
    return np.sign((r * out_normal).sum(1)) * np.linalg.norm(r, axis=1)


# ------------------------------------------------------------ the mesh state
@dataclass
class _State:
    V0: np.ndarray  # original vertices
    F0: np.ndarray
    V: np.ndarray
    F: np.ndarray
    labels: np.ndarray
    parent: np.ndarray  # (m',) original triangle of each face
    unchanged: np.ndarray  # (m',) bool face identical to its original triangle
    vsrc: np.ndarray  # (n',3) original vertices of the weights
    vw: np.ndarray  # (n',3) barycentric weights
    vparent: np.ndarray  # (n',) original triangle of each new vertex, -1 for input vertices


@dataclass
class BorderReport:
    """What happened to one border (a row of the operator's cut table)."""

    a: int
    b: int
    closed: bool
    method: str  #: 'line', 'parabola', 'ellipse', 'closed curve (order K)', 'plane section', 'smoothed path', 'unchanged'
    border_vertices: int
    length_before_mm: float
    length_after_mm: float
    turning_before: float  #: rad/mm, geodesic (tangent-plane) turning, see `turning_per_mm`
    turning_after: float
    max_shift_mm: float  #: largest distance of the new cut from the old border
    fit_rms_mm: float = 0.0
    note: str = ""

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class SmoothCutResult:
    """Output of `smooth_cuts` on an input with n vertices and m triangles."""

    V: np.ndarray  #: (n',3), the first n rows are the input vertices
    F: np.ndarray  #: (m',3)
    labels: np.ndarray  #: (m',) patch of each face (negative = in no patch, as in the input)
    face_parent: np.ndarray  #: (m',) input triangle each face lies in
    face_unchanged: np.ndarray  #: (m',) bool, the face is its input triangle as it was
    vert_src: np.ndarray  #: (n',3) input vertices that each vertex is a combination of
    vert_weights: np.ndarray  #: (n',3) the barycentric weights (V = sum w * V_in[src])
    vert_parent: np.ndarray  #: (n',) input triangle a new vertex lies in (-1 for input vertices)
    split: np.ndarray  #: (m,) bool, input triangles replaced by smaller ones
    borders: list[BorderReport] = field(default_factory=list)

    @property
    def new_vertex_count(self) -> int:
        return int((self.vert_parent >= 0).sum())

    @property
    def changed(self) -> bool:
        return any(b.method != "unchanged" for b in self.borders)


class _CutFailed(Exception):
    pass


def _weights_on(st: _State, verts: np.ndarray, tri: int) -> np.ndarray:
    """Barycentric weights (k,3) of vertices on the corners of original triangle ``tri``."""
    corners = st.F0[tri]
    src, w = st.vsrc[verts], st.vw[verts]
    out = np.zeros((len(verts), 3))
    for c in range(3):
        out[:, c] = np.where(src == corners[c], w, 0.0).sum(axis=1)
    return out


def _min_angles(P: np.ndarray) -> np.ndarray:
    """Smallest angle (deg) of triangles P (k,3,3)."""
    out = np.full(len(P), 180.0)
    for k in range(3):
        u = P[:, (k + 1) % 3] - P[:, k]
        w = P[:, (k + 2) % 3] - P[:, k]
        c = (u * w).sum(1) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1), 1e-300)
        out = np.minimum(out, np.degrees(np.arccos(np.clip(c, -1, 1))))
    return out


def _cut_band(st: _State, topo: MeshTopology, band: np.ndarray, a: int, b: int, phi_fn, linear: bool, snap: float):
    """Split the band faces along phi = 0 and relabel them; returns (new state, phi, from_face).

    phi_fn: a function of points (k,3) -> (k,), or an array of values at the vertices
    (then phi is linear along the edges).  from_face (m',): the old face each new face
    comes from.

    Raises _CutFailed (with the reason) when the cut leaves the band, does not separate
    the band into an a side and a b side, or leaves a jagged piece of the a|b border.
    """
    F, V = st.F, st.V
    bf = np.nonzero(band)[0]
    bverts = np.unique(F[bf])
    phi = np.full(len(V), np.nan)
    if callable(phi_fn):
        phi[bverts] = phi_fn(V[bverts])
    else:  # values at the vertices, linear along edges
        phi[bverts] = phi_fn[bverts]
        linear = True
    in_u = (st.labels == a) | (st.labels == b)
    # classify the edges of the band faces by their other face
    fe = topo.face_edges[bf].ravel()
    bedges = np.unique(fe)
    ef = topo.edge_faces[bedges]
    other_ok = np.ones(len(bedges), dtype=bool)  # may be crossed
    hard = np.zeros(len(bedges), dtype=bool)  # shared with a face of no concern: snap
    for col in range(2):
        f = ef[:, col]
        has = f >= 0
        outside = has & ~in_u[np.where(has, f, 0)]
        inner_nonband = has & in_u[np.where(has, f, 0)] & ~band[np.where(has, f, 0)]
        hard |= outside
        other_ok &= ~inner_nonband
    E = topo.edges[bedges]
    for _ in range(12):
        s = np.sign(phi[E])
        crossing = s[:, 0] * s[:, 1] < 0
        if (crossing & hard).any():
            for (u, v) in E[crossing & hard]:
                if abs(phi[u]) <= abs(phi[v]):
                    phi[u] = 0.0
                else:
                    phi[v] = 0.0
            continue
        if (crossing & ~other_ok).any():
            raise _CutFailed("the cut leaves the band around the border")
        ce = E[crossing]
        pu, pv = V[ce[:, 0]], V[ce[:, 1]]
        fu, fv = phi[ce[:, 0]], phi[ce[:, 1]]
        if linear:
            t = fu / (fu - fv)
        else:
            lo, hi = np.zeros(len(ce)), np.ones(len(ce))
            for _ in range(48):
                mid = 0.5 * (lo + hi)
                fm = phi_fn(pu + mid[:, None] * (pv - pu))
                same = np.sign(fm) == np.sign(fu)
                lo = np.where(same, mid, lo)
                hi = np.where(same, hi, mid)
            t = 0.5 * (lo + hi)
        near_u, near_v = t < snap, t > 1.0 - snap
        if near_u.any() or near_v.any():
            phi[ce[near_u, 0]] = 0.0
            phi[ce[near_v, 1]] = 0.0
            continue
        new_st, new_faces_P, new_face_cross, from_face = _split_faces(st, bf, phi, ce, t, a, b)
        bad = _min_angles(new_faces_P) < SLIVER_DEG
        if bad.any():
            # snap the nearest cut point of each sliver if it is within a quarter edge
            changed = False
            key = {(int(u), int(v)): k for k, (u, v) in enumerate(ce.tolist())}
            for f in np.unique(new_face_cross[bad]):
                tri = F[f]
                for k in range(3):
                    u, v = int(tri[k]), int(tri[(k + 1) % 3])
                    kk = key.get((min(u, v), max(u, v)))
                    if kk is None:
                        continue
                    tt = t[kk]
                    if tt < 0.25 and phi[ce[kk, 0]] != 0:
                        phi[ce[kk, 0]] = 0.0
                        changed = True
                    elif tt > 0.75 and phi[ce[kk, 1]] != 0:
                        phi[ce[kk, 1]] = 0.0
                        changed = True
            if changed:
                continue
        return new_st, phi, from_face
    raise _CutFailed("snapping did not settle")  # pragma: no cover - defensive


def _split_faces(st: _State, bf: np.ndarray, phi: np.ndarray, ce: np.ndarray, t: np.ndarray, a: int, b: int):
    """Re-triangulate the band faces along the cut (Figure 4-2 (b)) and relabel them."""
    n = len(st.V)
    F, V = st.F, st.V
    # new vertices, one per crossing edge (vertex n + j on edge ce[j])
    ce_key = np.minimum(ce[:, 0], ce[:, 1]) * n + np.maximum(ce[:, 0], ce[:, 1])
    order = np.argsort(ce_key)
    Fb = F[bf]
    u, v = Fb, np.roll(Fb, -1, axis=1)  # side k of face i: Fb[i, k] -> Fb[i, k+1]
    side_key = np.minimum(u, v) * n + np.maximum(u, v)
    pos = np.clip(np.searchsorted(ce_key[order], side_key), 0, max(len(ce) - 1, 0))
    hit = (ce_key[order][pos] == side_key) if len(ce) else np.zeros(side_key.shape, dtype=bool)
    # (len(bf), 3): the new vertex on each side of each band face, -1 if none
    xs = np.where(hit, n + order[pos], -1) if len(ce) else np.full(side_key.shape, -1)
    # parent triangle of each crossing edge: the first band face that has it
    fi, _ = np.nonzero(hit)
    jj = xs[hit] - n
    first = np.unique(jj, return_index=True)[1]
    e_face = np.empty(len(ce), dtype=np.int64)
    e_face[jj[first]] = bf[fi[first]]
    new_parent = st.parent[e_face]
    corners = st.F0[new_parent]  # (k,3)
    new_w = np.zeros((len(ce), 3))
    for end_, wt in ((0, 1.0 - t), (1, t)):
        src, w = st.vsrc[ce[:, end_]], st.vw[ce[:, end_]]  # (k,3) each
        for c in range(3):
            new_w[:, c] += wt * np.where(src == corners[:, c : c + 1], w, 0.0).sum(axis=1)
    new_src = corners
    new_v = np.einsum("kc,kcd->kd", new_w, st.V0[corners])
    phi_all = np.r_[phi, np.zeros(len(ce))]
    Vall = np.vstack([V, new_v])
    ncross = (xs >= 0).sum(axis=1)
    keep = np.ones(len(F), dtype=bool)
    keep[bf[ncross > 0]] = False
    rows = np.arange(len(bf))
    # one crossed side k: (p, x, r), (x, q, r)
    one = np.nonzero(ncross == 1)[0]
    k1 = np.argmax(xs[one] >= 0, axis=1)
    p1, q1, r1 = Fb[one, k1], Fb[one, (k1 + 1) % 3], Fb[one, (k1 + 2) % 3]
    x1 = xs[one, k1]
    pieces1 = np.stack([np.stack([p1, x1, r1], 1), np.stack([x1, q1, r1], 1)], 1)  # (c1,2,3)
    # two crossed sides k-1 and k around the lone vertex p = Fb[k]
    two = np.nonzero(ncross == 2)[0]
    both = (xs[two] >= 0) & (np.roll(xs[two], 1, axis=1) >= 0)  # side k and side k-1
    k2 = np.argmax(both, axis=1)
    p2, q2, r2 = Fb[two, k2], Fb[two, (k2 + 1) % 3], Fb[two, (k2 + 2) % 3]
    x2, y2 = xs[two, k2], xs[two, (k2 - 1) % 3]  # x on p-q, y on r-p
    opt1 = np.stack([np.stack([x2, q2, r2], 1), np.stack([x2, r2, y2], 1)], 1)
    opt2 = np.stack([np.stack([x2, q2, y2], 1), np.stack([q2, r2, y2], 1)], 1)
    m1 = _min_angles(Vall[opt1.reshape(-1, 3)]).reshape(-1, 2).min(axis=1) if len(two) else np.zeros(0)
    m2 = _min_angles(Vall[opt2.reshape(-1, 3)]).reshape(-1, 2).min(axis=1) if len(two) else np.zeros(0)
    rest = np.where((m1 >= m2)[:, None, None], opt1, opt2)
    pieces2 = np.concatenate([np.stack([p2, x2, y2], 1)[:, None, :], rest], axis=1)  # (c2,3,3)
    # in the order of the band faces, as the faces they replace
    count = np.zeros(len(bf), dtype=np.int64)
    count[one], count[two] = 2, 3
    start_ = np.r_[0, np.cumsum(count)[:-1]]
    new_F = np.empty((int(count.sum()), 3), dtype=np.int64)
    for i in range(2):
        new_F[start_[one] + i] = pieces1[:, i]
    for i in range(3):
        new_F[start_[two] + i] = pieces2[:, i]
    out_from = np.repeat(bf[rows], count)
    out_parent = st.parent[out_from]
    F2 = np.vstack([F[keep], new_F])
    parent2 = np.r_[st.parent[keep], out_parent]
    unchanged2 = np.r_[st.unchanged[keep], np.zeros(len(new_F), dtype=bool)]
    from_face = np.r_[np.nonzero(keep)[0], out_from]
    # labels: band faces by side of the cut
    band2 = np.zeros(len(F), dtype=bool)
    band2[bf] = True
    in_band = band2[from_face]
    side = phi_all[F2].sum(axis=1)
    old_labels = st.labels[from_face]
    Fb = F[bf]
    area0 = np.zeros(len(F))
    area0[bf] = np.linalg.norm(np.cross(V[Fb[:, 1]] - V[Fb[:, 0]], V[Fb[:, 2]] - V[Fb[:, 0]]), axis=1)
    cent_phi = phi[F[bf]].mean(axis=1)
    sa = np.sum(area0[bf] * np.sign(cent_phi) * np.where(st.labels[bf] == a, 1.0, -1.0))
    a_sign = 1.0 if sa >= 0 else -1.0
    labels2 = old_labels.copy()
    sided = in_band & (side != 0)
    labels2[sided] = np.where(np.sign(side[sided]) == a_sign, a, b)
    new_st = _State(
        st.V0,
        st.F0,
        Vall,
        F2,
        labels2,
        parent2,
        unchanged2,
        np.vstack([st.vsrc, new_src]),
        np.vstack([st.vw, new_w]),
        np.r_[st.vparent, new_parent],
    )
    pieces = Vall[new_F] if len(new_F) else np.zeros((0, 3, 3))
    return new_st, pieces, out_from, from_face


# ------------------------------------------------------------ per border
def _band(st: _State, topo: MeshTopology, border: Border, all_borders: list[Border], R: float) -> np.ndarray:
    """Faces of patches a, b whose centroid is within R of this border (and nearer to it than to another a|b border)."""
    samples, owner = [], []
    for i, other in enumerate(all_borders):
        if (other.a, other.b) != (border.a, border.b):
            continue
        p, q = st.V[other.edges[:, 0]], st.V[other.edges[:, 1]]
        for s in np.linspace(0.0, 1.0, 5):
            samples.append(p + s * (q - p))
            owner.append(np.full(len(p), i))
    pts, own = np.vstack(samples), np.concatenate(owner)
    me = next(i for i, o in enumerate(all_borders) if o is border)
    tree = cKDTree(pts)
    C = topo.centroids
    box = np.all((C >= pts.min(axis=0) - R) & (C <= pts.max(axis=0) + R), axis=1)
    faces = np.nonzero(box & ((st.labels == border.a) | (st.labels == border.b)))[0]
    dist, idx = tree.query(C[faces], distance_upper_bound=R * (1 + 1e-12) + 1e-300)
    near = np.isfinite(dist) & (dist <= R)
    out = np.zeros(len(st.F), dtype=bool)
    out[faces[near]] = own[idx[near]] == me
    return out


def _check(st: _State, phi: np.ndarray, a: int, b: int, band_faces_new: np.ndarray) -> tuple[np.ndarray, MeshTopology]:
    """(cut edges of the new a|b border, topology of the faces of a and b and their neighbours);
    raises _CutFailed if the result breaks a rule.

    Only patches a and b and the faces touching them are looked at (the vertex normals of
    their vertices are those of the whole mesh), so a cut costs the size of the pair.
    """
    ab = (st.labels == a) | (st.labels == b)
    verts = np.zeros(len(st.V), dtype=bool)
    verts[st.F[ab]] = True
    sub = np.nonzero(verts[st.F].any(axis=1))[0]
    topo = MeshTopology(st.V, st.F[sub])
    labels = st.labels[sub]
    band_faces_new = band_faces_new[sub]
    side = np.where(labels == a, 1, np.where(labels == b, 2, 0))
    comp = None
    for lab, code in ((a, 1), (b, 2)):
        mask = side == code
        if not mask.any():
            raise _CutFailed(f"patch {lab} would vanish")
        if comp is None:
            _, comp = topo.face_components(side)
        if len(np.unique(comp[mask])) > 1:
            raise _CutFailed(f"patch {lab} would fall apart")
    P = topo.face_adjacency_pairs
    E = topo.face_adjacency_edges
    la, lb = labels[P[:, 0]], labels[P[:, 1]]
    ab = ((la == a) & (lb == b)) | ((la == b) & (lb == a))
    on_cut = np.r_[phi, np.zeros(len(st.V) - len(phi))] == 0
    edges = topo.edges[E[ab]]
    touches_band = band_faces_new[P[ab, 0]] | band_faces_new[P[ab, 1]]
    if not touches_band.any():
        raise _CutFailed("the cut does not separate the two patches")
    cut = on_cut[edges[:, 0]] & on_cut[edges[:, 1]]
    if (touches_band & ~cut).any():
        raise _CutFailed("a jagged piece of the border would remain")
    return edges[touches_band], topo


def _edge_samples(E: np.ndarray, V: np.ndarray, k: int = 9) -> np.ndarray:
    p, q = V[E[:, 0]], V[E[:, 1]]
    s = np.linspace(0.0, 1.0, k)
    return (p[:, None, :] + s[None, :, None] * (q - p)[:, None, :]).reshape(-1, 3)


def _hausdorff(E_old: np.ndarray, V_old: np.ndarray, E_new: np.ndarray, V_new: np.ndarray) -> float:
    """Symmetric Hausdorff distance (mm) between the old border and the new cut (edge samples)."""
    if len(E_new) == 0 or len(E_old) == 0:
        return float("inf")
    A, B = _edge_samples(E_old, V_old), _edge_samples(E_new, V_new)
    return float(max(cKDTree(A).query(B)[0].max(), cKDTree(B).query(A)[0].max()))


def _diffused_indicator(st: _State, a: int, b: int, sigma: float, border: Border | None = None,
                        reach: float = np.inf) -> np.ndarray:
    """MBO field on the vertices of patches a and b: > 0 on the a side (module doc).

    With ``border`` and a finite ``reach`` (mm) only the faces of a and b whose centroid is
    within reach of the border take part (NaN elsewhere): the field near the border, where
    the cut is looked for, depends on the patches within a few sigma of it only (the
    implicit step's kernel decays like exp(-sqrt(2) d / sigma)).
    """
    in_u = (st.labels == a) | (st.labels == b)
    if border is not None and np.isfinite(reach):
        faces = np.nonzero(in_u)[0]
        C = st.V[st.F[faces]].mean(axis=1)
        pts = _edge_samples(border.edges, st.V, 3)
        box = np.all((C >= pts.min(axis=0) - reach) & (C <= pts.max(axis=0) + reach), axis=1)
        near = np.zeros(len(faces), dtype=bool)
        d, _ = cKDTree(pts).query(C[box], distance_upper_bound=reach)
        near[np.nonzero(box)[0]] = np.isfinite(d)
        in_u = np.zeros(len(st.F), dtype=bool)
        in_u[faces[near]] = True
    Fu = st.F[in_u]
    ids, inv = np.unique(Fu.ravel(), return_inverse=True)
    Fl = inv.reshape(-1, 3)
    Vl = st.V[ids]
    area = 0.5 * np.linalg.norm(np.cross(Vl[Fl[:, 1]] - Vl[Fl[:, 0]], Vl[Fl[:, 2]] - Vl[Fl[:, 0]]), axis=1)
    sgn = np.where(st.labels[in_u] == a, 1.0, -1.0)
    num = np.bincount(Fl.ravel(), weights=np.repeat(area * sgn, 3), minlength=len(ids))
    den = np.bincount(Fl.ravel(), weights=np.repeat(area, 3), minlength=len(ids))
    u = num / np.maximum(den, 1e-300)
    K = cotangent_stiffness(Vl, Fl)
    M = lumped_mass(Vl, Fl)
    solve = factorized((sp.diags(M) + 0.5 * sigma**2 * K).tocsc())
    for it in range(MBO_ITERATIONS):
        u = solve(M * u)
        if it < MBO_ITERATIONS - 1:
            u = np.where(u >= 0, 1.0, -1.0)
    out = np.full(len(st.V), np.nan)
    out[ids] = u
    return out


def _smooth_border(st: _State, border: Border, all_borders: list[Border], snap: float) -> tuple[_State, BorderReport]:
    a, b = border.a, border.b
    topo = MeshTopology(st.V, st.F)
    turn0, len0 = turning_per_mm(st.V, border.edges, topo.vertex_normals)
    nverts = len(np.unique(border.edges))
    report = BorderReport(a, b, border.closed, "unchanged", nverts, len0, len0, turn0, turn0, 0.0)
    if nverts < 3:
        report.note = "too short to fit a curve (a single edge); left as it is"
        return st, report
    h = float(np.linalg.norm(st.V[border.edges[:, 0]] - st.V[border.edges[:, 1]], axis=1).mean())
    attempts = []  # (method, phi_fn, linear, R, rms)
    reasons = []
    near = _band(st, topo, border, all_borders, 2.0 * h)
    normals = topo.face_normals[near]
    d = (normals * topo.areas[near, None]).sum(axis=0)
    dn = np.linalg.norm(d)
    # scanner noise tilts single triangles: allow 2 % of the area around the border to face away
    steep = topo.areas[near][(normals @ (d / max(dn, 1e-300))) < HEIGHT_FIELD_COS].sum()
    height_field = dn > 0 and steep <= 0.02 * topo.areas[near].sum()
    limit = max(3.0 * h, 0.15 * len0)
    if border.order is None:
        reasons.append("the border branches")
    elif height_field:
        d = d / dn
        P = st.V[border.order]
        Pg = project_to_plane(P, d, P.mean(axis=0))  # eqs. 4-6..4-9
        c, e1, e2 = _plane_axes(Pg, d)
        x, y = (Pg - c) @ e1, (Pg - c) @ e2
        try:
            if border.closed:
                coef, K, rms = fit_closed_curve(np.stack([x, y], 1), h)
                curve = closed_curve_points(coef)
                dev = float(_dist_to_polygon(np.stack([x, y], 1), curve).max())
                name = "ellipse" if K == 1 else f"closed curve (order {K})"

                def phi_fn(Q, c=c, e1=e1, e2=e2, coef=coef):
                    R_ = Q - c
                    return signed_distance_closed(np.stack([R_ @ e1, R_ @ e2], 1), coef)

            else:
                coef, order, rms = fit_open_curve(x, y, h)
                dev = float(np.abs(np.polyval(coef, x) - y).max())
                name = "line" if order == 1 else "parabola"

                def phi_fn(Q, c=c, e1=e1, e2=e2, coef=coef):
                    R_ = Q - c
                    return R_ @ e2 - np.polyval(coef, R_ @ e1)

            if dev <= ON_CURVE * h:  # a cut we made before: cutting again would only add vertices
                report.note = f"{ALREADY_SMOOTH} (its vertices lie on a {name} within {dev:.2g} mm)"
                return st, report
            if dev > limit:
                reasons.append(f"the fitted {name} strays {dev:.1f} mm from the border")
            else:
                attempts.append((name, phi_fn, False, max(3.0 * h, 2.0 * dev + 2.0 * h), rms))
        except BolusError as exc:
            reasons.append(str(exc))
    else:
        reasons.append("the surface folds too much around the border for a plane projection")
    if border.order is not None and not height_field:
        # plane sections: the least-squares plane of the border (a loop around a limb, an
        # arc) and, for an open border, the plane through its principal line and the mean
        # surface normal (a normal section: close to the shortest path across)
        P = st.V[border.order]
        c = P.mean(axis=0)
        _, sv, Vt = np.linalg.svd(P - c, full_matrices=False)
        planes = [Vt[2]] if (border.closed or sv[1] >= 0.2 * sv[0]) else []
        if not border.closed and dn > 0:
            ns = np.cross(Vt[0], d / dn)
            if np.linalg.norm(ns) > 1e-6:
                planes.append(ns / np.linalg.norm(ns))
        for nrm in planes:
            dev = float(np.abs((P - c) @ nrm).max())
            across = dn > 0 and abs(float(nrm @ d)) / dn < 0.5  # the plane crosses the surface
            if dev <= ON_CURVE * h and across:
                report.note = f"{ALREADY_SMOOTH} (its vertices lie on a plane section within {dev:.2g} mm)"
                return st, report
            if dev <= limit:
                rms_p = float(np.sqrt(np.mean(((P - c) @ nrm) ** 2)))
                attempts.append(("plane section", lambda Q, c=c, nrm=nrm: (Q - c) @ nrm, True,
                                 max(3.0 * h, 2.0 * dev + 2.0 * h), rms_p))
            else:
                reasons.append(f"the border is {dev:.1f} mm away from a plane")
    for sigma_edges in MBO_SIGMA_EDGES:
        sigma = sigma_edges * h
        attempts.append(("smoothed path", sigma, True, 4.0 * sigma + 2.0 * h, 0.0))
    fallback = None  # best smoothed path that is valid but not yet smooth enough
    same = False  # a valid cut was found, but it is not measurably smoother than the border
    for name, phi_fn, linear, R, rms in attempts:
        if name == "smoothed path":  # phi given at the vertices
            # the cut is looked for within 2 R of the border; 6 sigma more of the patches around it
            phi_fn = _diffused_indicator(st, a, b, phi_fn, border, 2.0 * R + 6.0 * phi_fn)
        for grow in (1.0, 2.0):
            band = _band(st, topo, border, all_borders, R * grow)
            try:
                new_st, phi, from_face = _cut_band(st, topo, band, a, b, phi_fn, linear, snap)
                cut_edges, new_topo = _check(new_st, phi, a, b, band[from_face])
            except _CutFailed as exc:
                reasons.append(f"{name}: {exc}")
                continue
            turn1, len1 = turning_per_mm(new_st.V, cut_edges, new_topo.vertex_normals)
            shift = _hausdorff(border.edges, st.V, cut_edges, new_st.V)
            if shift > limit:
                reasons.append(f"{name}: the cut would move {shift:.1f} mm from the border")
                continue
            if turn1 >= turn0 or turn1 > (1.0 - MIN_GAIN) * turn0:
                reasons.append(f"{name}: {NOT_SMOOTHER}")
                same = True
                continue
            if shift < MIN_SHIFT * h:
                reasons.append(f"{name}: {NEGLIGIBLE}")
                same = True
                continue
            result = (new_st, name, len1, turn1, shift, rms)
            if turn1 > SMOOTH_ENOUGH * turn0:
                # valid but still turning: try the next cut (or a longer diffusion) and
                # keep the smoothest valid one meanwhile
                if fallback is None or turn1 < fallback[3]:
                    fallback = result
                reasons.append(f"{name}: turns {turn1 / turn0:.0%} of the border")
                break
            return _accept(report, result, reasons)
    if fallback is not None:
        return _accept(report, fallback, reasons)
    report.note = "left as it is: " + "; ".join(dict.fromkeys(reasons))
    if same:
        report.note = f"{ALREADY_SMOOTH} (no cut we can fit is measurably smoother)"
    return st, report


def _accept(report: BorderReport, result, reasons: list[str]):
    new_st, name, len1, turn1, shift, rms = result
    report.method = name
    report.length_after_mm = len1
    report.turning_after = turn1
    report.max_shift_mm = shift
    report.fit_rms_mm = rms
    if reasons:
        report.note = ("fell back to a smoothed path along the surface: " if name == "smoothed path" else "") + "; ".join(
            dict.fromkeys(reasons))
    return new_st, report


# ------------------------------------------------------------- entry point
def smooth_cuts(V, F, labels, snap: float = SNAP, progress=None) -> SmoothCutResult:
    """Replace the patch borders by smooth cut curves (module doc, seed 4.1.2).

    V (n,3) mm, F (m,3) a manifold triangle mesh, labels (m,) int patch of each face
    (negative: in no patch; those faces are never split or relabelled).
    Returns a `SmoothCutResult`; the input arrays are not modified.  With nothing to
    change (every border already smooth, too short or impossible to smooth) the result
    is the input, every border 'unchanged' with its reason in ``note``, and
    ``result.changed`` is False; calling it again on its own result changes nothing.
    Raises BolusError when there is nothing to smooth at all (fewer than two patches,
    no common border, a non-manifold mesh).
    """
    V, F = as_mesh_arrays(V, F)
    labels = np.asarray(labels, dtype=np.int64).copy()
    if labels.shape != (len(F),):
        raise BolusError(f"labels must give one patch per triangle ({len(F)}), got shape {labels.shape}")
    if not 0.0 <= snap < 0.5:
        raise BolusError(f"snap must be in [0, 0.5), got {snap}")
    patches = np.unique(labels[labels >= 0])
    if len(patches) < 2:
        raise BolusError(
            "there is only one patch: nothing to smooth (run Segment into Patches with 2 or more patches first)"
        )
    topo = MeshTopology(V, F)
    if topo.nonmanifold_edges.any():
        raise BolusError("the mesh has non-manifold edges; cut lines need a manifold surface")
    borders = border_components(topo, labels)
    if not borders:
        raise BolusError("the patches do not share any border: nothing to smooth")
    n, m = len(V), len(F)
    eye = np.zeros((n, 3))
    eye[:, 0] = 1.0
    st = _State(
        V, F, V.copy(), F.copy(), labels, np.arange(m), np.ones(m, dtype=bool),
        np.repeat(np.arange(n)[:, None], 3, axis=1), eye, np.full(n, -1, dtype=np.int64),
    )
    report = progress or (lambda f, t: None)
    # Passes over every border until one changes nothing: a cut of a|c relabels faces near
    # the a|b|c junction and so moves the end of an a|b cut made before it; the next pass
    # smooths such ends.  The last pass changes nothing, so neither does a second call
    # on the result (idempotent: every border is then 'unchanged', "already smooth").
    tracks: list[_Track] = []
    memo: dict = {"seen": {}, "version": {}}
    for pass_no in range(MAX_PASSES):
        lo = 0.0 if pass_no == 0 else 0.75 + 0.2 * (1 - 0.5 ** (pass_no - 1))
        hi = 0.75 if pass_no == 0 else 0.75 + 0.2 * (1 - 0.5**pass_no)
        st, changed = _one_pass(st, snap, tracks, pass_no, memo, lambda f, t: report(lo + (hi - lo) * f, t))
        if not changed:
            break
    _final_measures(st, tracks)
    reports = [tr.report for tr in tracks]
    split = np.ones(m, dtype=bool)
    split[st.parent[st.unchanged]] = False
    report(1.0, "done")
    return SmoothCutResult(st.V, st.F, st.labels, st.parent, st.unchanged, st.vsrc, st.vw, st.vparent, split, reports)


@dataclass
class _Track:
    """One border of the input, followed through the passes (one report row)."""

    report: BorderReport
    edges: np.ndarray  #: (k,2) its edges in the input (input vertices never move)
    samples: np.ndarray  #: (s,3) points along them
    changed: bool = False
    first: tuple[str, str] = ("unchanged", "")  #: (method, note) of the first pass


def _nearest_track(tracks: list[_Track], border: Border, V: np.ndarray) -> _Track | None:
    """The input border of the same pair that this border of a later pass lies nearest to."""
    best, best_d = None, np.inf
    pts = _edge_samples(border.edges, V, 3)
    for tr in tracks:
        if (tr.report.a, tr.report.b) != (border.a, border.b):
            continue
        dist = float(np.median(cKDTree(tr.samples).query(pts)[0]))
        if dist < best_d:
            best, best_d = tr, dist
    return best


def _pair_borders(st: _State, a: int, b: int) -> list[Border]:
    """`border_components` of the pair a|b only (computed on the faces of a and b)."""
    ab = (st.labels == a) | (st.labels == b)
    return border_components(MeshTopology(st.V, st.F[ab]), st.labels[ab])


def _one_pass(st: _State, snap: float, tracks: list[_Track], pass_no: int, memo: dict, report) -> tuple[_State, bool]:
    """Smooth every border of the current mesh once; returns (state, whether a cut was made).

    The first pass creates one `_Track` per border; later passes update the track each
    border descends from.  A border left unchanged before is not tried again while its
    two patches have not changed since (memo: 'seen' (a, b, edges) -> patch versions then,
    'version' patch -> number of cuts that changed it): what `_smooth_border` decides
    depends on those two patches only, so it would decide the same again.
    """
    seen, version = memo["seen"], memo["version"]
    borders = border_components(MeshTopology(st.V, st.F), st.labels)
    pairs = sorted({(bd.a, bd.b) for bd in borders})
    done, total, changed = 0, len(borders), False
    last = None
    for a, b in pairs:
        # borders of this pair on the current mesh (earlier cuts may have moved junctions)
        fresh = _pair_borders(st, a, b)
        for bd in list(fresh):
            text = f"cut between patches {a} and {b}" + (f" (pass {pass_no + 1})" if pass_no else "")
            report(done / max(total, 1), text)
            if last is not None and last.method != "unchanged" and (last.a, last.b) == (a, b):
                fresh = _pair_borders(st, a, b)  # the last cut moved things
            # the same border on the current mesh (its edges are unchanged: other pairs' cuts
            # never touch an a|b edge)
            match = [x for x in fresh if (x.a, x.b) == (a, b) and len(np.intersect1d(_edge_keys(x.edges), _edge_keys(bd.edges)))]
            if not match:
                continue
            key = (a, b, np.sort(_edge_keys(match[0].edges)).tobytes())
            now = (version.get(a, 0), version.get(b, 0))
            if seen.get(key) == now:
                done += 1
                continue
            if pass_no == 0:
                tr = _Track(None, match[0].edges.copy(), _edge_samples(match[0].edges, st.V, 5))
            else:
                tr = _nearest_track(tracks, match[0], st.V)
            st, rep = _smooth_border(st, match[0], fresh, snap)
            last = rep
            done += 1
            cut = rep.method != "unchanged"
            changed |= cut
            if cut:
                version[a], version[b] = now[0] + 1, now[1] + 1
            else:
                seen[key] = now
            if pass_no == 0:
                tr.report, tr.changed, tr.first = rep, cut, (rep.method, rep.note)
                tracks.append(tr)
            elif cut and tr is None:  # a border no input border led to: a row of its own
                tracks.append(_Track(rep, match[0].edges.copy(), _edge_samples(match[0].edges, st.V, 5), True))
            elif cut:
                prev = tr.report
                method0, note0 = tr.first
                how = (f"{method0} first, then {rep.method} where the other cuts had moved its ends"
                       if method0 != "unchanged" else f"{rep.method} once the other cuts had moved its ends")
                rep.note = "; ".join(x for x in ((note0 if method0 != "unchanged" else ""), how) if x)
                rep.turning_before, rep.length_before_mm = prev.turning_before, prev.length_before_mm
                rep.border_vertices = prev.border_vertices
                tr.report, tr.changed = rep, True
    return st, changed


def _final_measures(st: _State, tracks: list[_Track]) -> None:
    """Turning, length and shift of each track's border on the final mesh (the whole border, ends included)."""
    topo = MeshTopology(st.V, st.F)
    owned: dict[int, list[np.ndarray]] = {}
    for bd in border_components(topo, st.labels):
        tr = _nearest_track(tracks, bd, st.V)
        if tr is not None:
            owned.setdefault(id(tr), []).append(bd.edges)
    for tr in tracks:
        if id(tr) not in owned:
            continue
        E = np.vstack(owned[id(tr)])
        if len(E) == len(tr.edges) and np.array_equal(np.sort(_edge_keys(E)), np.sort(_edge_keys(tr.edges))):
            continue  # untouched
        rep = tr.report
        rep.turning_after, rep.length_after_mm = turning_per_mm(st.V, E, topo.vertex_normals)
        rep.max_shift_mm = _hausdorff(tr.edges, st.V, E, st.V)


def _edge_keys(E: np.ndarray) -> np.ndarray:
    E = np.sort(E, axis=1)
    return E[:, 0] * (1 << 32) + E[:, 1]
