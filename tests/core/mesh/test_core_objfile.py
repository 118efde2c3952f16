"""The OBJ reader of tests, benchmarks and scripts (core/objfile.py): good files and bad ones."""
import numpy as np
import pytest

from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.objfile import load_obj


def write(tmp_path, text):
    p = tmp_path / "m.obj"
    p.write_text(text)
    return p


def test_quad_and_negative_indices(tmp_path):
    p = write(tmp_path, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1 4/1\nf -4 -2 -1\n")
    V, F, tri_face = load_obj(p, scale=10.0)
    assert V.shape == (4, 3) and V[2].tolist() == [10.0, 10.0, 0.0]
    assert F.tolist() == [[0, 1, 2], [0, 2, 3], [0, 2, 3]]
    assert tri_face.tolist() == [0, 0, 1]


@pytest.mark.parametrize("text, says", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "outside the vertex array"),
    ("v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n", "line 2"),
    ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", "line 2: .*three coordinates"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "line 4: .*three corners"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "start at 1"),
    ("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "vertex 1"),
    ("# nothing\n", "no vertices or faces"),
])
def test_bad_files_name_the_problem(tmp_path, text, says):
    with pytest.raises(BolusError, match=says):
        load_obj(write(tmp_path, text))
