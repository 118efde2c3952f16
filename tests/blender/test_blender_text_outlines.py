"""Text outlines from Blender's built-in font (bolus_addon/blender/text_outlines.py)."""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.blender


def _counts(bpy):
    return {k: len(getattr(bpy.data, k)) for k in ("curves", "objects", "meshes", "fonts", "materials")}


def _signed_area(P):
    x, y = P[:, 0], P[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _inside(q, P):
    """Point q (2,) inside the closed polygon P (k,2) (even-odd ray crossing)."""
    A, B = P, np.roll(P, -1, axis=0)
    cross = (A[:, 1] > q[1]) != (B[:, 1] > q[1])
    x = A[:, 0] + (q[1] - A[:, 1]) * (B[:, 0] - A[:, 0]) / np.where(B[:, 1] != A[:, 1], B[:, 1] - A[:, 1], 1.0)
    return bool(np.sum(cross & (x > q[0])) % 2)


def test_outlines_of_AB_12_are_closed_with_holes(scene):
    from bolus.bolus_addon.blender.text_outlines import text_outline  # noqa: PLC0415 (the registered extension)

    import bpy  # noqa: PLC0415

    before = _counts(bpy)
    out = text_outline("AB 12")
    assert _counts(bpy) == before  # nothing left in bpy.data (not even the font)
    polys = out.polygons
    assert all(p.ndim == 2 and p.shape[1] == 2 and len(p) >= 3 and np.isfinite(p).all() for p in polys)
    # closed loops: no repeated closing point, no zero-length edge
    for p in polys:
        assert np.linalg.norm(p - np.roll(p, -1, axis=0), axis=1).min() > 0
    areas = np.array([_signed_area(p) for p in polys])
    outer, holes = [p for p, a in zip(polys, areas) if a > 0], [p for p, a in zip(polys, areas) if a < 0]
    assert len(outer) == 4  # A, B, 1, 2
    assert len(holes) == 3  # one in A, two in B
    for h in holes:  # every hole lies inside an outer outline, in the left half (A and B)
        assert any(_inside(h[0], p) for p in outer)
        assert h[:, 0].max() < out.width / 2
    # cap height 1, baseline 0, left to right
    allp = np.concatenate(polys)
    assert allp[:, 1].min() == pytest.approx(0.0, abs=1e-6)
    assert allp[:, 1].max() == pytest.approx(1.0, abs=0.05)
    assert out.width == pytest.approx(allp[:, 0].max()) and out.width > 3.0


def test_cap_height_and_cache(scene):
    from bolus.bolus_addon.blender.text_outlines import text_outline  # noqa: PLC0415

    H = text_outline("H")
    assert len(H.polygons) == 1
    assert H.polygons[0][:, 1].max() == pytest.approx(1.0) and H.polygons[0][:, 1].min() == pytest.approx(0.0)
    again = text_outline("H")
    again.polygons[0][:] = 0.0  # the caller's copy: the cache is not changed
    assert text_outline("H").polygons[0][:, 1].max() == pytest.approx(1.0)
    g = text_outline("g")
    assert np.concatenate(g.polygons)[:, 1].min() < -0.2  # descender below the baseline


def test_refuses_empty_text(scene):
    from bolus.bolus_addon.core.errors import BolusError  # noqa: PLC0415
    from bolus.bolus_addon.blender.text_outlines import text_outline  # noqa: PLC0415

    for bad in ("", "   ", "two\nlines"):
        with pytest.raises(BolusError, match="one line of text"):
            text_outline(bad)


def test_font_outlines_engrave_a_closed_solid(scene):
    """The font's outlines go through core.engrave: closed result, volume down by letter area x depth."""
    from bolus.bolus_addon.core.solid.engrave import engrave_text  # noqa: PLC0415
    from bolus.bolus_addon.core.solid.manifold import SIDE_INNER, SIDE_OUTER, SIDE_RIM, closed_report  # noqa: PLC0415
    from bolus.bolus_addon.blender.text_outlines import text_outline  # noqa: PLC0415
    from meshgen import box  # noqa: PLC0415

    V, F = box((60.0, 30.0, 8.0), n=12)
    C = V[F].mean(axis=1)
    side = np.where(C[:, 2] > 8 - 1e-6, SIDE_OUTER, np.where(C[:, 2] < 1e-6, SIDE_INNER, SIDE_RIM)).astype(np.int8)
    out = text_outline("AB 12")
    V2, F2, s2, note = engrave_text(V, F, side, out, height_mm=6.0, depth_mm=0.6, up=(0, 1, 0))
    assert note is None
    assert closed_report(V2, F2)["closed"]
    area = sum(_signed_area(p) for p in out.polygons) * 36.0  # holes count negative
    removed = closed_report(V, F)["volume_mm3"] - closed_report(V2, F2)["volume_mm3"]
    assert removed == pytest.approx(area * 0.6, rel=0.10)


def test_from_edit_mode_of_another_object(scene):
    """make_shell engraves while the source may be in Edit Mode: the outline is the same and the
    user's object stays in Edit Mode with its selection."""
    from bolus.bolus_addon.blender.text_outlines import text_outline  # noqa: PLC0415
    from bpy_helpers import enter_edit_mode_with_faces, make_object  # noqa: PLC0415
    from meshgen import grid  # noqa: PLC0415

    import bpy  # noqa: PLC0415

    V, F = grid(4, 4, 10.0)
    ob = make_object(bpy, V, F, name="skin")
    mask = np.zeros(len(F), dtype=bool)
    mask[:5] = True
    enter_edit_mode_with_faces(bpy, ob, mask)
    before = _counts(bpy)
    out = text_outline("Q7 edit")  # a string not cached by the other tests
    assert _counts(bpy) == before
    assert ob.mode == "EDIT" and bpy.context.view_layer.objects.active == ob
    ob.update_from_editmode()
    sel = np.zeros(len(ob.data.polygons), dtype=bool)
    ob.data.polygons.foreach_get("select", sel)
    assert np.array_equal(sel, mask)
    bpy.ops.object.mode_set(mode="OBJECT")
    assert len(out.polygons) >= 4 and out.width > 3.0
