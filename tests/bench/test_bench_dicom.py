"""The DICOM benchmark's measures on a small CT (bench/dicom_bench.py); no timing is asserted.

The import rows rest on the torso's distance and the share of the surface off the skin; the
export's peer rests on the pixel mask of the solid and its Dice against the exact sections.
"""
from __future__ import annotations

import numpy as np
import pytest
from paths import import_bench

pytest.importorskip("pydicom")


@pytest.fixture(scope="module")
def db():
    return import_bench("dicom_bench")


def test_import_rows_tell_the_skin_from_the_couch_and_lungs(db, tmp_path):
    db.make_ct(str(tmp_path), 16, 128)
    ours, peer = db.worker("ours", str(tmp_path)), db.worker("peer", str(tmp_path))
    assert ours["far_pct"] < 1.0 < 20.0 < peer["far_pct"]  # the couch and the lungs' walls in the peer's
    assert ours["mean_mm"] < 1.5 and ours["triangles"] < peer["triangles"]


def test_pixel_mask_peer_is_near_but_not_exact(db):
    import dicomgen as g

    grid = g.Grid(rows=64, cols=64, spacing=(2.0, 2.0), positions=np.arange(12) * 2.5 - 13.75,
                  origin=np.array([-64.0, -64.0, 0.0]))
    V, F = g.manifold_arrays(__import__("manifold3d").Manifold.sphere(20.0, 64))
    masks, _ = db._peer_mask(grid, V, F)
    q = db._peer_quality(grid, masks, V, F, every=2, fine=0.5)
    assert 0.9 < q["dice"] < 1.0 and q["volume_err_pct"] < 10.0
