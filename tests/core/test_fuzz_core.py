"""Regression cases the operator fuzzing (tests/test_fuzz_operators.py) found, pinned at the core
(bpy-free): each failed before its fix with an exception the operator reported as "Unexpected error"."""
from __future__ import annotations

import numpy as np

import fuzzgen
from bolus_addon.core.unfold.sheet_pieces import sheet_pieces
from bolus_addon.core.mesh.topology import MeshTopology

BOWTIE_SPEC = fuzzgen.FOUND["bowtie"]


def test_sheet_pieces_bowtie_vertex_piece():
    """A patch that is a disk but for one bow-tie vertex (a hole touching another boundary at a vertex):
    cut_to_disk splits the vertex without a cut path; _piece_mesh concatenated no paths (ValueError)."""
    V, F = fuzzgen.build_surface(BOWTIE_SPEC)
    topo = MeshTopology(V, F)
    assert (topo.vertex_fan_count > 1).sum() == 1 and topo.face_components()[0] == 1  # the case is still the case
    res = sheet_pieces(V, F, 8.27)
    assert len(res.unfoldings) >= 1 and len(res.piece) == len(F) and (res.piece >= 0).all()
    for u in res.unfoldings:
        assert np.isfinite(u.UV).all() and np.isfinite(u.EL) and u.EL >= 0 and u.flipped == 0
