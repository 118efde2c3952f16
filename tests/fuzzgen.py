"""Hypothesis strategies for the fuzz tests: random triangulated surfaces and
random operator parameters.  numpy + scipy + hypothesis only (no bpy).

A surface is drawn as a *spec*, a flat dict of plain numbers (kind, counts, noise, cut plane,
hole, size in mm, scene unit, rotation, seed), and built by `build_surface(spec)` into
V (n,3) in mm and F (m,3) counter-clockwise triangles.  Keeping the spec plain means a failure
hypothesis shrinks prints as a dict that can be pasted into ``@example(spec=...)`` as a
regression case.  Kinds:

- ``grid``: a noisy height-field grid (jitter in the plane, random bumps and noise in z);
- ``cap``: a spherical cap (rings of a sphere up to a polar angle, a pole vertex; up to
  nearly the whole sphere);
- ``tube``: an open cylinder whose radius varies ring to ring (cones, bulges, necks);
- ``delaunay``: scipy's Delaunay triangulation of random points in a square or a disc,
  lifted by a random height field (hull slivers included: they are part of the fuzz).

Then, each optional: a cut (faces on one side of a random plane removed), a hole (faces within
a random disc around a face removed) -- either may split the surface into pieces or leave
bow-tie vertices -- and a random rotation.  `apply_scale` turns mm into Blender units for a
drawn scene unit (1 unit = scale_length m), so sizes from 0.1 mm to 1 m come through the
scene's unit setting as a user's file would carry them.
"""
from __future__ import annotations

import os

import numpy as np
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st

import meshgen

KINDS = ("grid", "cap", "tube", "delaunay")
SCALE_LENGTHS = (1.0, 0.1, 0.01, 0.001)  # metres, decimetres, centimetres, millimetres per unit

# ------------------------------------------------------------------------ profiles
#: `make test`: few cases, the same every run (derandomize), no example database on disk
settings.register_profile(
    "bolus-ci", derandomize=True, database=None, deadline=None, print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)
#: `make fuzz` (BOLUS_FUZZ=1): many random cases; a failure is printed with its spec and a blob
settings.register_profile(
    "bolus-fuzz", derandomize=False, database=None, deadline=None, print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)
FUZZ = os.environ.get("BOLUS_FUZZ", "") not in ("", "0")
PROFILE = "bolus-fuzz" if FUZZ else "bolus-ci"
#: largest triangle count of a drawn surface (before cuts and holes); BOLUS_FUZZ_MAX_FACES=400 for a
#: `make fuzz` on larger meshes (about twice the time)
MAX_FACES = int(os.environ.get("BOLUS_FUZZ_MAX_FACES", "200"))


def fuzz_settings(ci_examples: int, fuzz_examples: int):
    """`settings` for one fuzz test: ci_examples cases under `make test`, fuzz_examples under `make fuzz`.
    (A per-test decorator: loading a profile globally would change other hypothesis tests.)
    BOLUS_FUZZ_SHRINK=0 reports the first failing case as drawn (shrinking runs the operators
    hundreds of times: minutes per failure)."""
    kw = {}
    if os.environ.get("BOLUS_FUZZ_SHRINK", "1") == "0":
        kw["phases"] = [Phase.explicit, Phase.reuse, Phase.generate]
    return settings(settings.get_profile(PROFILE), max_examples=fuzz_examples if FUZZ else ci_examples, **kw)


#: surfaces on which the fuzzing found a failure (kept as regression cases by the tests):
#: bowtie -- a Delaunay disc whose hole leaves a bow-tie vertex: segment refuses it (non-manifold
#: vertex), unfold (no patches: the whole mesh as one) raised "ValueError: need at least one array to
#: concatenate" in sheet_pieces._piece_mesh (cut_to_disk split the vertex without a cut path)
FOUND = {
    "bowtie": {"kind": "delaunay", "seed": 439, "n": 99, "disc": True, "bumps": 3, "bump_height": 0.07363425829935366,
               "noise": 0.024485452693366425, "hole": [0.0, 0.09112641504376853], "size_mm": 11.031495948920108,
               "scale_length": 0.01},
}


# ------------------------------------------------------------------------ surface specs
def _unit(x):
    return st.floats(0.0, x, allow_nan=False, allow_infinity=False)


@st.composite
def surface_specs(draw, kinds=KINDS, max_faces: int | None = None, min_faces: int = 50, cuts: bool = True):
    """A spec dict for `build_surface` (see the module docstring); its triangle count before a cut
    or hole lies in [min_faces, max_faces] (cuts and holes remove some, never all)."""
    max_faces = MAX_FACES if max_faces is None else max_faces
    kind = draw(st.sampled_from(kinds))
    spec: dict = {"kind": kind, "seed": draw(st.integers(0, 2**16))}
    if kind == "grid":
        nx = draw(st.integers(4, 14))
        lo = max(1, -(-min_faces // (2 * nx)))
        ny = draw(st.integers(lo, max(lo, max_faces // (2 * nx))))
        spec.update(nx=nx, ny=ny, aspect=draw(st.floats(0.3, 3.0)), jitter=draw(_unit(0.45)),
                    bumps=draw(st.integers(0, 3)), bump_height=draw(st.floats(-0.6, 0.6)), noise=draw(_unit(0.05)))
    elif kind == "cap":
        na = draw(st.integers(6, 24))
        per_ring = 2 * na
        lo = max(2, -(-(min_faces - na) // per_ring) + 1)
        nr = draw(st.integers(lo, max(lo, (max_faces - na) // per_ring + 1)))
        spec.update(na=na, nr=nr, half_angle_deg=draw(st.floats(15.0, 178.0)), noise=draw(_unit(0.05)))
    elif kind == "tube":
        na = draw(st.integers(5, 24))
        per_ring = 2 * na
        lo = max(2, -(-min_faces // per_ring) + 1)
        nr = draw(st.integers(lo, max(lo, max_faces // per_ring + 1)))
        spec.update(na=na, nr=nr, length=draw(st.floats(0.2, 4.0)), taper=draw(st.floats(-0.8, 0.8)),
                    wobble=draw(_unit(0.4)), noise=draw(_unit(0.05)))
    else:
        # Delaunay of n points: about 2n triangles
        n = draw(st.integers(max(8, min_faces // 2 + 3), max(9, max_faces // 2)))
        spec.update(n=n, disc=draw(st.booleans()), bumps=draw(st.integers(0, 3)),
                    bump_height=draw(st.floats(-0.6, 0.6)), noise=draw(_unit(0.05)))
    if cuts and draw(st.booleans()):
        spec["cut"] = [draw(st.floats(-1, 1)) for _ in range(3)] + [draw(st.floats(-0.4, 0.4))]
    if cuts and draw(st.booleans()):
        spec["hole"] = [draw(st.floats(0.0, 1.0)), draw(st.floats(0.05, 0.35))]
    spec["size_mm"] = draw(st.floats(-1.0, 3.0).map(lambda e: float(10.0 ** e)))  # 0.1 mm .. 1 m
    spec["scale_length"] = draw(st.sampled_from(SCALE_LENGTHS))
    if draw(st.booleans()):
        spec["rotation"] = [draw(st.floats(-1, 1)) for _ in range(4)]
        spec["rotate_object"] = draw(st.booleans())  # rotation in the object's matrix, not the data
    return spec


def _bumps(rng, x, y, count, height):
    z = np.zeros_like(x)
    for _ in range(count):
        cx, cy = rng.uniform(-0.5, 0.5, 2)
        s = rng.uniform(0.1, 0.4)
        z += height * rng.uniform(0.5, 1.0) * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * s * s))
    return z


def _ccw_up(P2, F):
    e1, e2 = P2[F[:, 1]] - P2[F[:, 0]], P2[F[:, 2]] - P2[F[:, 0]]
    cw = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    F = F.copy()
    F[cw] = F[cw][:, ::-1]
    return F


def _base(spec: dict, rng) -> tuple[np.ndarray, np.ndarray]:
    """The uncut surface with unit-ish extent (about 1 across)."""
    kind = spec["kind"]
    if kind == "grid":
        nx, ny = spec["nx"], spec["ny"]
        V, F = meshgen.grid(nx, ny, 1.0, jitter=spec["jitter"], rng=int(rng.integers(2**31)))
        V[:, 0] -= 0.5
        V[:, 1] = (V[:, 1] - 0.5) * spec["aspect"]
        V[:, 2] = _bumps(rng, V[:, 0], V[:, 1], spec["bumps"], spec["bump_height"])
        V[:, 2] += rng.normal(0, spec["noise"] / max(nx, ny), len(V))
        return V, F
    if kind == "cap":
        na, nr = spec["na"], spec["nr"]
        phi = np.radians(np.linspace(spec["half_angle_deg"], 0.0, nr + 1)[:-1])  # outermost ring first
        prof = np.stack([np.sin(phi), np.cos(phi)], 1) * 0.5
        V, F, _ = meshgen.ring_surface(prof, na=na, pole=True)
        V[-1] = [0.0, 0.0, 0.5]
        V += rng.normal(0, spec["noise"] / na, V.shape)
        return V, F
    if kind == "tube":
        na, nr = spec["na"], spec["nr"]
        s = np.linspace(0.0, 1.0, nr)
        r = 0.25 * (1.0 + spec["taper"] * (s - 0.5) * 2) * (1.0 + spec["wobble"] * rng.uniform(-1, 1, nr))
        r = np.maximum(r, 0.02)
        prof = np.stack([r, s * spec["length"] * 0.5], 1)
        V, F, _ = meshgen.ring_surface(prof, na=na, pole=False)
        V += rng.normal(0, spec["noise"] / na, V.shape)
        return V, F
    from scipy.spatial import Delaunay

    n = spec["n"]
    if spec["disc"]:
        t, rr = rng.uniform(0, 2 * np.pi, n), 0.5 * np.sqrt(rng.uniform(0, 1, n))
        P = np.stack([rr * np.cos(t), rr * np.sin(t)], 1)
    else:
        P = rng.uniform(-0.5, 0.5, (n, 2))
    F = _ccw_up(P, Delaunay(P).simplices.astype(np.int64))
    z = _bumps(rng, P[:, 0], P[:, 1], spec["bumps"], spec["bump_height"]) + rng.normal(0, spec["noise"] / 10, n)
    return np.c_[P, z], F


def _compact(V, F):
    used, inv = np.unique(F, return_inverse=True)
    return V[used], inv.reshape(-1, 3)


def _quaternion_matrix(q) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    nq = np.linalg.norm(q)
    if nq < 1e-6:
        return np.eye(3)
    w, x, y, z = q / nq
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def rotation_matrix(spec: dict) -> np.ndarray:
    """(3,3) the spec's rotation (identity without one)."""
    return _quaternion_matrix(spec["rotation"]) if "rotation" in spec else np.eye(3)


def build_surface(spec: dict) -> tuple[np.ndarray, np.ndarray]:
    """V (n,3) in mm (largest extent spec['size_mm'], centred on the origin, rotated unless the
    rotation goes into the object), F (m,3) int64 triangles, no unused vertices, m >= 1."""
    rng = np.random.default_rng(spec["seed"])
    V, F = _base(spec, rng)
    C = V[F].mean(axis=1)
    keep = np.ones(len(F), dtype=bool)
    if "cut" in spec:
        nrm = np.asarray(spec["cut"][:3], dtype=float)
        if np.linalg.norm(nrm) > 1e-6:
            side = C @ (nrm / np.linalg.norm(nrm)) > spec["cut"][3]
            if (keep & ~side).sum() >= max(4, len(F) // 5):  # never remove nearly everything
                keep &= ~side
    if "hole" in spec:
        where, radius = spec["hole"]
        centre = C[min(int(where * len(F)), len(F) - 1)]
        ext = np.ptp(V, axis=0).max()
        inside = np.linalg.norm(C - centre, axis=1) < radius * ext
        if (keep & ~inside).sum() >= max(4, len(F) // 5):
            keep &= ~inside
    V, F = _compact(V, F[keep])
    V = V - 0.5 * (V.min(axis=0) + V.max(axis=0))
    ext = np.ptp(V, axis=0).max()
    V = V * (spec["size_mm"] / max(ext, 1e-12))
    if not spec.get("rotate_object", False):
        V = V @ rotation_matrix(spec).T
    return V, F.astype(np.int64)


def apply_scale(V_mm: np.ndarray, spec: dict) -> np.ndarray:
    """Blender units for the spec's scene unit: 1 unit = scale_length m = 1000 scale_length mm."""
    return V_mm / (1000.0 * spec["scale_length"])


# ------------------------------------------------------------------------ operator parameters
def _f(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def _rare(common: str, rare: str, one_in: int):
    """`common`, or `rare` about once in one_in draws under `make fuzz` and never under `make test`: the
    slow choices (explicit unfolding, L-PSO, GMM: 5-50 s on 300 faces) would take the whole time budget."""
    if not FUZZ:
        return st.just(common)
    return st.integers(0, one_in - 1).map(lambda i: rare if i == 0 else common)


def preview_params():
    return st.fixed_dictionaries({"smoothing_mm": _f(0.0, 10.0),
                                  "color_by": st.sampled_from(["FLATTENABILITY", "SALIENCY"])})


def segment_params():
    return st.fixed_dictionaries({"patches": st.integers(1, 8), "eta": _f(0.0, 20.0), "seed": st.integers(0, 1000),
                                  "smoothing_mm": _f(0.0, 10.0), "method": _rare("KMEANS", "GMM", 25)})


def unfold_params():
    return st.fixed_dictionaries({"max_el": st.one_of(st.just(0.0), _f(0.1, 10.0), _f(0.0, 10.0)),
                                  "sheet_thickness_mm": st.one_of(st.just(0.0), _f(0.0, 10.0)),
                                  "method": _rare("LBFGS", "EXPLICIT", 100), "refine": st.booleans(),
                                  "gap_mm": _f(0.0, 30.0)})


def export_pattern_params():
    return st.fixed_dictionaries({"file_format": st.sampled_from(["SVG", "DXF", "PDF"]),
                                  "page": st.sampled_from(["NONE", "A4", "LETTER"]),
                                  "seam_allowance_mm": _f(0.0, 10.0),
                                  "label": st.sampled_from(["", "P-0042", "Ünïcode ✓ 12"])})


def improve_params():
    return st.fixed_dictionaries({"max_gap_mm": _f(0.05, 5.0), "method": _rare("GRADIENT", "LPSO", 30),
                                  "seed": st.integers(0, 1000)})


def print_segment_params():
    return st.fixed_dictionaries({"parts": st.integers(1, 8), "method": st.sampled_from(["ABCUT", "RATIOCUT", "LEARNED"]),
                                  "seed": st.integers(0, 1000)})


def orient_params():
    return st.fixed_dictionaries({"layer_mm": _f(0.05, 1.0), "skin_side_up": st.booleans()})


@st.composite
def shell_params(draw):
    """make_shell parameters at a coarse resolution: mostly valid (the wall spans 4-6 voxels), now and
    then one the operator must refuse (a resolution too coarse for the wall, a clearance >= thickness)."""
    t = draw(_f(1.0, 25.0))
    c = draw(st.sampled_from([0.0, 0.0, 0.0, 0.5, 0.5, 2.0] * 3 + [30.0]))
    wall = max(t - c, 0.1)
    res = wall / draw(st.sampled_from([4.0, 5.0, 6.0, 4.0, 5.0, 6.0] * 2 + [3.0]))
    return {"thickness_mm": t, "clearance_mm": c, "resolution_mm": res, "label": draw(st.sampled_from(["", "", "ID7"]))}


def area_params():
    """radius_mm as a fraction of the surface's size (the test scales it), now and then 0 (refused)."""
    return st.fixed_dictionaries({"radius_frac": st.tuples(st.integers(0, 9), _f(0.05, 1.5)).map(
                                      lambda t: 0.0 if t[0] == 0 else t[1]),
                                  "exclude_cavities": st.booleans(),
                                  # the 3D cursor: near a vertex (index fraction, offset along the size) or anywhere
                                  "at_vertex": st.one_of(_f(0.0, 1.0), _f(0.0, 1.0), st.none()),
                                  "offset": st.tuples(*[_f(-0.7, 0.7)] * 3)})
