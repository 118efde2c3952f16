"""Printing features and the orientation search, eqs. 6-1..6-20 (SPEC "Print orientation")."""
import numpy as np
import pytest
from paths import ASSETS
from meshgen import box, grid, icosphere, ring_surface, sheet_with_dome, spherical_cap, torus

from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.objfile import load_obj
from bolus_addon.core.printing.orientation import (
    cusp_height,
    face_support,
    fibonacci_sphere,
    normal_curvature,
    orient,
    overhang_faces,
    place_on_plate,
    print_objective,
    rotation_to_z,
    surface_quality,
)
from bolus_addon.core.mesh.topology import MeshTopology

Z = np.array([0.0, 0.0, 1.0])


def _random_rotation(seed):
    Q, R = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q if np.linalg.det(Q) > 0 else -Q


def _four_triangles():
    """Four triangles of area 50 mm^2 with normals +z, -z, (0, .6, -.8) and (0, .8, -.6)."""
    V = np.array([
        [0, 0, 0], [10, 0, 0], [0, 10, 0],  # n = +z, centroid z = 0
        [0, 0, 20], [0, 10, 20], [10, 0, 20],  # n = -z, centroid z = 20
        [0, 0, 30], [0, 8, 36], [10, 0, 30],  # n = (0, .6, -.8), centroid z = 32
        [0, 0, 50], [0, 6, 58], [10, 0, 50],  # n = (0, .8, -.6), centroid z = 52.67
    ], dtype=float)
    return V, np.arange(12).reshape(4, 3)


def test_hand_computed_values_on_four_triangles():
    V, F = _four_triangles()
    t = MeshTopology(V, F)
    np.testing.assert_allclose(t.areas, 50.0)
    np.testing.assert_allclose(t.face_normals, [[0, 0, 1], [0, 0, -1], [0, 0.6, -0.8], [0, 0.8, -0.6]], atol=1e-12)
    # b = +z: plate z0 = 0; overhangs: the -z face and the one at 0.8 (> cos 45 = 0.707), not the one at 0.6
    np.testing.assert_allclose(cusp_height(t.face_normals, Z), [0.2, 0.2, 0.16, 0.12])  # eq. 6-1
    E, EM = surface_quality(V, F, Z)  # eqs. 6-2, 6-3
    np.testing.assert_allclose(E, [10.0, 10.0, 8.0, 6.0])
    assert EM == pytest.approx(34.0)
    assert overhang_faces(t.face_normals, Z).tolist() == [False, True, True, False]
    np.testing.assert_allclose(face_support(V, F, Z), [0.0, 50 * 20, 50 * 32, 0.0])  # eqs. 6-9..6-11
    o = print_objective(V, F, [Z, -Z, 2 * Z])
    np.testing.assert_allclose(o.WQ, [34.0, 34.0, 34.0])  # eq. 6-7: 0.2 * 50 * (1 + 1 + .8 + .6)
    # b = -z: plate at z = 58 (the top vertex), only the +z face overhangs, 58 mm above it
    np.testing.assert_allclose(o.WU, [50 * 20 + 50 * 32, 50 * 58, 50 * 20 + 50 * 32])  # eq. 6-14
    np.testing.assert_allclose(o.support_volume, [50 * 20 + 50 * 0.8 * 32, 50 * 58, 50 * 20 + 50 * 0.8 * 32])
    np.testing.assert_allclose(o.objective, o.WQ + o.WU)
    # the plate is the lowest vertex, not the lowest centroid; layer height scales WQ only
    o2 = print_objective(V, F, [0.0, 0.0, 1.0], h=0.1)
    assert o2.WQ[0] == pytest.approx(17.0) and o2.WU[0] == pytest.approx(2600.0)


def test_chunked_evaluation_matches_one_block():
    V, F, _ = sheet_with_dome(n_sheet=6, n_dome=6, na=24)
    B = fibonacci_sphere(300)
    a = print_objective(V, F, B, chunk=1 << 24)
    b = print_objective(V, F, B, chunk=len(F))  # one direction per block
    for x, y in ((a.WQ, b.WQ), (a.WU, b.WU), (a.support_volume, b.support_volume)):
        np.testing.assert_allclose(x, y, rtol=1e-10, atol=1e-8)
    # translation does not change anything
    c = print_objective(V + [500.0, -300.0, 1000.0], F, B)
    np.testing.assert_allclose(a.objective, c.objective, rtol=1e-8)


def test_flat_plate_stands_on_edge():
    """Eq. 6-1: a plate is best printed with its normal perpendicular to b (WQ = 0, no overhang)."""
    V, F = grid(10, 10, 100.0)
    r = orient(V, F)
    assert abs(r.direction @ Z) < 1e-6
    assert r.WQ < 1e-6 and r.WU == 0.0 and r.support_volume == 0.0
    flat_down = print_objective(V, F, Z).objective[0]
    assert flat_down == pytest.approx(0.2 * 100 * 100)


def test_open_hemisphere_prints_rim_down():
    V, F = spherical_cap(50.0, 90.0, 3)  # outward normals, open at z = 0
    r = orient(V, F)
    up, down = print_objective(V, F, [Z, -Z]).objective
    assert 0.63 < r.direction[2] < 0.86  # the opening faces the plate (0.745 measured: the lowest of the ties)
    assert r.WU < 1e-9 * r.objective and r.support_volume < 1e-9 * r.objective
    assert r.objective <= up * (1 + 1e-9)
    assert 19.7 < down / r.objective < 26.6  # rim up: the whole outside needs support (23.1x measured)


def test_clean_hemisphere_prints_exactly_rim_down():
    # a hemisphere whose rim lies exactly in z = 0: WQ = h pi R^2 in every direction, so
    # every direction of the no-overhang cone ties; the lowest print is rim down
    phi = np.linspace(0.0, np.pi / 2, 13)[:-1]
    profile = np.stack([50.0 * np.cos(phi), 50.0 * np.sin(phi)], 1)  # (r, z) from the rim up
    V, F, _ = ring_surface(profile, na=64, pole=True)
    V[-1] = [0.0, 0.0, 50.0]
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    if (n * (V[F].mean(1))).sum() < 0:  # outward normals
        F = F[:, ::-1]
    r = orient(V, F)
    assert r.direction[2] > 0.999
    assert r.WU < 1e-9 * r.objective


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_rotated_box_comes_back_face_down(seed):
    V, F = box((40.0, 30.0, 20.0), 4)
    R = _random_rotation(seed)
    r = orient(V @ R.T, F)
    normals = R.T  # rows: the rotated box axes
    assert np.abs(normals @ r.direction).max() > 1 - 1e-9
    # the smallest side (30 x 20) on the plate: WQ = h * 2 * 600, nothing overhangs above the plate
    assert r.WQ == pytest.approx(0.2 * 2 * 600.0, rel=1e-9)
    assert r.WU < 1e-6 and abs(abs(r.direction @ R[:, 0]) - 1) < 1e-9


#: measured: exact evaluations of orient and its objective over the dense search's best
#: (torus 2,596 and 0.400: 20,000 random directions miss its narrow dips; dome 3,881 and 0.999;
#: face part 1,959 and 0.958); pinned at +15 %, the ratio never above SPEC's 1.01
_SEARCH_FIGURES = {"torus": (2596, 0.400), "dome": (3881, 0.999), "face_part": (1959, 0.958)}


@pytest.mark.parametrize("which", ["torus", "dome", "face_part"])
def test_search_is_within_one_percent_of_a_dense_random_search(which):
    if which == "torus":
        V, F = torus(60.0, 20.0, 32, 12)
        V = V @ _random_rotation(7).T
    elif which == "dome":
        V, F, _ = sheet_with_dome(n_sheet=8, n_dome=8, na=32)
        V = V @ _random_rotation(8).T
    else:
        V, F, _ = load_obj(ASSETS / "ict_face_narrow.obj", scale=10.0)  # cm -> mm
        keep = V[F].mean(axis=1)[:, 1] > np.percentile(V[:, 1], 60)  # the upper part of the face
        F = F[keep]
    r = orient(V, F, rng=0)
    B = np.random.default_rng(12345).standard_normal((20_000, 3))
    dense = print_objective(V, F, B).objective.min()
    evaluations, ratio = _SEARCH_FIGURES[which]
    assert r.objective <= min(1.01, 1.15 * ratio) * dense
    assert r.evaluations <= 1.15 * evaluations  # far fewer exact evaluations than the dense search (20,000)
    again = print_objective(V, F, r.direction)
    assert again.objective[0] == pytest.approx(r.objective, rel=1e-9)
    assert again.support_volume[0] == pytest.approx(r.support_volume, rel=1e-9, abs=1e-9)


def test_favour_keeps_the_favoured_side_up():
    V, F = spherical_cap(50.0, 90.0, 3)
    r = orient(V, F, favour=-Z)  # the inside of the cap must not look down
    assert r.direction @ -Z >= -1e-9
    assert r.objective > orient(V, F).objective  # the constraint costs something here
    r2 = orient(V, F, favour=-Z, favour_min_cos=0.5)
    assert r2.direction @ -Z >= 0.5 - 1e-9


def test_rotation_to_z_and_placement():
    rng = np.random.default_rng(0)
    dirs = list(rng.standard_normal((20, 3))) + [Z, -Z, [1e-12, 0, -1], [0, 1e-9, 1], [1, 0, 0]]
    for b in dirs:
        b = np.asarray(b, float)
        R = rotation_to_z(b)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(R @ (b / np.linalg.norm(b)), Z, atol=1e-12)
    V, F = icosphere(2, 30.0)
    V = V * [1.0, 2.0, 0.5] + [10.0, -20.0, 300.0]
    b = np.array([0.3, -0.5, 0.8])
    W, R, t = place_on_plate(V, b)
    assert W[:, 2].min() == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(W, V @ R.T + t)
    np.testing.assert_allclose(MeshTopology(W, F).edge_lengths, MeshTopology(V, F).edge_lengths, rtol=1e-12)
    # the chosen direction becomes +Z: the objective of the placed mesh at +Z is unchanged
    assert print_objective(W, F, Z).objective[0] == pytest.approx(print_objective(V, F, b).objective[0], rel=1e-9)


def test_normal_curvature_on_spheres_and_planes():
    V, F = icosphere(3, 40.0)
    k = normal_curvature(V, F)
    np.testing.assert_allclose(k.vertex, -1 / 40.0, rtol=0.02)  # convex, outward normals: negative
    np.testing.assert_allclose(k.face, -1 / 40.0, rtol=0.02)  # eq. 6-18
    assert not k.concave().any()  # eq. 6-19
    inside = normal_curvature(V, F[:, ::-1])
    np.testing.assert_allclose(inside.face, 1 / 40.0, rtol=0.02)
    assert inside.concave(0.01).all()
    assert ((k.face_normalised >= 0) & (k.face_normalised <= 1)).all()  # eq. 6-20
    Vg, Fg = grid(6, 6, 60.0, jitter=0.2)
    assert np.abs(normal_curvature(Vg, Fg).vertex).max() < 1e-12


def test_orient_parts_orients_each_part_alone():
    V, F = box((40.0, 30.0, 20.0), 3)
    C = V[F].mean(axis=1)
    labels = (C[:, 0] > 20).astype(int)  # two open halves
    res = orient_parts(V, F, labels)
    assert len(res) == 2
    for i, r in enumerate(res):
        Fi = F[labels == i]
        assert r.objective == pytest.approx(print_objective(V, Fi, r.direction).objective[0], rel=1e-9)
    with pytest.raises(BolusError):
        orient_parts(V, F, labels[:-1])


def test_bad_input_is_refused():
    V, F = grid(2, 2, 10.0)
    with pytest.raises(BolusError, match="zero area"):
        orient(np.zeros_like(V), F)
    with pytest.raises(BolusError, match="no faces"):
        orient(V, np.zeros((0, 3), dtype=int))
    with pytest.raises(BolusError):
        print_objective(V, F, [0.0, 0.0, 0.0])
    with pytest.raises(BolusError):
        orient(V, F, h=0.0)
    with pytest.raises(BolusError):
        orient(V, F, favour=[0.0, 0.0, 0.0])
    with pytest.raises(BolusError):
        rotation_to_z([np.nan, 0, 1])
    with pytest.raises(ValueError):  # BolusError is a ValueError
        orient(V, F[:, :2])


# ------------------------------------------------------------ degenerate input
from meshgen import degenerate_variants  # noqa: E402

from bolus_addon.core.printing.measures import PrintTerms, open_surface_note  # noqa: E402
from bolus_addon.core.printing.parts import PrintPlan, orient_parts, orient_print_parts, skin_side_up_direction

_BOX = box((40.0, 30.0, 20.0), 3)
_DEGENERATE = degenerate_variants(*_BOX)
_B = fibonacci_sphere(64)


@pytest.mark.parametrize("name", sorted(_DEGENERATE))
def test_print_measures_on_degenerate_meshes(name):
    """NaN/inf are refused naming the vertex; zero-area, needle and non-manifold triangles are
    sound: each face counts with its area (a zero-area face adds nothing), the plate is the lowest vertex."""
    V, F, says = _DEGENERATE[name]
    calls = [lambda: print_objective(V, F, _B), lambda: face_support(V, F, Z), lambda: surface_quality(V, F, Z),
             lambda: normal_curvature(V, F), lambda: orient(V, F), lambda: orient_parts(V, F, np.zeros(len(F), int)),
             lambda: orient_print_parts(V, F, np.zeros(len(F), int)), lambda: skin_side_up_direction(V, F),
             lambda: place_on_plate(V, Z)]
    if name in ("nan", "inf"):
        for call in calls:
            with pytest.raises(BolusError, match=says):
                call()
        return
    Vc, Fc = _BOX
    o, clean = print_objective(V, F, _B), print_objective(Vc, Fc, _B)
    extra = MeshTopology(V, F[len(Fc):])  # the triangles degenerate_variants added
    z0 = (V[np.unique(F)] @ _B.T).min(axis=0)
    dq = 0.2 * np.abs(extra.face_normals @ _B.T).T @ extra.areas
    np.testing.assert_allclose(o.WQ, clean.WQ + dq, rtol=1e-12, atol=1e-9)  # eq. 6-7 face by face
    if name in ("coincident", "needle"):  # no new lowest point (the needle's tip lies inside the box's side)
        np.testing.assert_allclose(z0, (Vc @ _B.T).min(axis=0), atol=1e-9)
    for x in (o.WQ, o.WU, o.support_volume, normal_curvature(V, F).vertex, face_support(V, F, Z)):
        assert np.isfinite(x).all()
    r = orient(V, F)
    assert np.isfinite(r.objective) and r.objective <= 1.01 * o.objective.min()
    if name == "coincident":  # a zero-area face changes nothing
        np.testing.assert_allclose(o.objective, clean.objective, rtol=1e-12)
        assert r.objective == pytest.approx(orient(Vc, Fc).objective, rel=1e-9)


def test_zero_area_part_and_bad_labels_are_refused_by_name():
    V, F = grid(3, 3, 30.0)
    V0 = V.copy()
    V0[:, :] = V0[:, :1] * [1.0, 0.0, 0.0]  # every vertex on the x axis: all faces of zero area
    for call in (lambda: orient(V0, F), lambda: print_objective(V0, F, Z), lambda: skin_side_up_direction(V0, F)):
        with pytest.raises(BolusError, match="the part has zero area"):
            call()
    lab = np.zeros(len(F), int)
    with pytest.raises(BolusError, match="one integer per triangle"):
        orient_print_parts(V, F, lab[:-1])
    with pytest.raises(BolusError, match="no triangle belongs to a print part"):
        orient_print_parts(V, F, lab - 1)
    with pytest.raises(BolusError, match="part 1 has no faces"):
        orient_parts(V, F, np.where(np.arange(len(F)) > 4, 2, 0))
    V2 = V.copy()
    V2[F[:2].ravel()] = V2[F[0, 0]]  # part 1 = two triangles collapsed onto one point
    lab2 = np.r_[1, 1, np.zeros(len(F) - 2, int)]
    with pytest.raises(BolusError, match="print part 1 has no area"):
        orient_print_parts(V2, F, lab2)


def test_orient_print_parts_rows_gaps_outside_faces_and_skin_side():
    V, F = box((40.0, 30.0, 20.0), 3)
    C = V[F].mean(axis=1)
    labels = np.where(C[:, 0] > 20, 3, 0)  # parts 0 and 3 (a gap), ...
    labels[C[:, 2] > 19.9] = -1  # ... the top face in no part
    plan = orient_print_parts(V, F, labels)
    assert isinstance(plan, PrintPlan) and [r.part for r in plan.parts] == [0, 3]
    assert plan.whole.faces == len(F) and plan.whole.orientation.objective == pytest.approx(orient(V, F).objective)
    for r in plan.parts:
        Fi = F[labels == r.part]
        assert r.faces == len(Fi) and r.area_mm2 == pytest.approx(MeshTopology(V, Fi).areas.sum())
        assert r.orientation.objective == pytest.approx(orient(V, Fi).objective, rel=1e-12)
    assert plan.parts_support_mm3 == pytest.approx(sum(r.orientation.support_volume for r in plan.parts))
    rows = plan.rows()
    assert [r["part"] for r in rows] == ["whole", "part 0", "part 3"]
    assert rows[1]["support_volume_mm3"] == plan.parts[0].orientation.support_volume
    # the whole box needs no support standing on a side: no ratio
    assert plan.whole.orientation.support_volume == 0.0 and plan.support_ratio is None
    # a tiny part is oriented but flagged
    lab3 = np.zeros(len(F), int)
    lab3[:2] = 1
    assert any("part 1 has only 2 triangles" in w for w in orient_print_parts(V, F, lab3, whole=False).warnings)
    # skin side up: the cap's normals point out, so its inside (the skin) faces up
    Vc, Fc = spherical_cap(50.0, 90.0, 3)
    d = skin_side_up_direction(Vc, Fc)
    np.testing.assert_allclose(d, -Z, atol=1e-9)
    up = orient_print_parts(Vc, Fc, np.zeros(len(Fc), int), skin_side_up=True, whole=False).parts[0].orientation
    assert up.direction @ d >= -1e-12 and up.objective == pytest.approx(orient(Vc, Fc, favour=d).objective)
    with pytest.raises(BolusError, match="no prevailing side"):
        skin_side_up_direction(*icosphere(2, 30.0))


def test_open_surface_note_and_terms_near_match_exact():
    assert open_surface_note(MeshTopology(*box())) is None
    Vc, Fc = spherical_cap(50.0, 60.0, 2)
    t = MeshTopology(Vc, Fc)
    assert open_surface_note(t).startswith(f"open surface ({int(t.boundary_edges.sum())} boundary edges)")
    # the cheap cap evaluation is exact: the same figures as the plain one
    terms = PrintTerms.exact(t)
    b = np.array([0.3, -0.2, -0.93])
    b /= np.linalg.norm(b)
    T = b + 0.05 * np.random.default_rng(0).standard_normal((40, 3))
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    radius = float(np.arccos(np.clip(T @ b, -1, 1)).max())
    for near, plain in zip(terms.evaluate_near(b, T, radius, 0.2, np.cos(np.radians(45))),
                           terms.evaluate(T, 0.2, np.cos(np.radians(45)))):
        np.testing.assert_allclose(near, plain, rtol=1e-9, atol=1e-6)


def test_search_finds_the_narrow_slivers_of_scanned_face_parts():
    """Regression (honest print bench): on two ABcut parts of the ICT face the best
    directions lie in slivers about 0.3 deg wide; a 160-point first cap shrinking 4x missed them
    by 1.8 % and 4.7 % against the bench's independent reference (whose values are pinned here)."""
    from bolus_addon.core.printing.segmentation import print_segment
    from bolus_addon.core.mesh.topology import submesh

    V, F, _ = load_obj(ASSETS / "ict_face_narrow.obj", scale=10.0)  # cm -> mm
    lab = print_segment(V, F, 3, method="abcut", rng=0)
    for part, faces, reference in ((0, 6104, 3609.275), (1, 4776, 3082.320)):
        Fl, ids = submesh(F, lab == part)
        assert len(Fl) == faces, "test setup: the segmentation changed; measure the reference again"
        r = orient(V[ids], Fl, rng=0)
        assert r.objective <= 1.01 * reference, (part, r.objective / reference)


def test_print_plan_table_and_support_text():
    V, F, _ = sheet_with_dome(n_sheet=6, n_dome=6, na=24)
    C = V[F].mean(axis=1)
    plan = orient_print_parts(V, F, (C[:, 0] > 0).astype(int))
    t = plan.table(layer_mm=0.2, skin_side_up=False)
    assert t["layer_mm"] == 0.2 and t["skin_side_up"] is False and t["rows"] == plan.rows()
    assert t["parts_support_mm3"] == plan.parts_support_mm3 and t["support_ratio"] == plan.support_ratio
    text = plan.support_text()
    assert text.startswith(f"Support of the parts together: {plan.parts_support_mm3:.1f} mm³")
    if plan.support_ratio is not None:
        assert f"= {plan.support_ratio * 100:.0f} % of the whole model's" in text
    alone = orient_print_parts(V, F, np.zeros(len(F), int), whole=False)
    assert alone.support_ratio is None and alone.support_text().endswith("mm³")


def test_row_text():
    from bolus_addon.core.printing.parts import row_text

    r = {"part": "part 2", "faces": 12, "area_mm2": 1234.0, "direction": [0.0, -0.6, 0.8], "WQ": 1.25,
         "WU": 30.0, "support_volume_mm3": 7.04}
    assert row_text(r) == ("part 2: 12 triangles, 12.3 cm², build direction (+0.000, -0.600, +0.800), "
                           "WQ 1.2 mm³, WU 30.0 mm³, support 7.0 mm³")
