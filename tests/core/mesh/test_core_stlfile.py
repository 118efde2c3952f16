"""The core STL reader: binary and ASCII, merged corners, refusals."""
import numpy as np
import pytest
from meshfiles import write_ascii, write_binary
from meshgen import icosphere

from bolus_addon.core.errors import BolusError
from bolus_addon.core.mesh.stlfile import load_stl


def _same_mesh(V0, F0, V, F):
    assert len(V) == len(V0) and len(F) == len(F0)
    # same triangles as coordinate triples (order of vertices may differ)
    a = np.sort(np.round(V0[F0], 5).reshape(len(F0), -1), axis=0)
    b = np.sort(np.round(V[F], 5).reshape(len(F), -1), axis=0)
    assert np.allclose(a, b)


def test_binary_and_ascii_round_trip(tmp_path):
    V0, F0 = icosphere(2, 30.0)
    write_binary(tmp_path / "a.stl", V0, F0, header=b"solid but binary")  # a binary header starting "solid"
    write_ascii(tmp_path / "b.stl", V0, F0)
    for name in ("a.stl", "b.stl"):
        V, F = load_stl(tmp_path / name)
        _same_mesh(V0, F0, V, F)
    V, _ = load_stl(tmp_path / "a.stl", scale=10.0)
    assert np.abs(np.linalg.norm(V, axis=1) - 300.0).max() < 1e-3


def test_refusals(tmp_path):
    with pytest.raises(BolusError, match="cannot read"):
        load_stl(tmp_path / "none.stl")
    (tmp_path / "junk.stl").write_bytes(b"\x00\xff" * 100)
    with pytest.raises(BolusError, match="neither a binary STL"):
        load_stl(tmp_path / "junk.stl")
    (tmp_path / "text.stl").write_text("hello world\n")
    with pytest.raises(BolusError, match="not an STL file"):
        load_stl(tmp_path / "text.stl")
    write_binary(tmp_path / "empty.stl", np.zeros((0, 3)), np.zeros((0, 3), dtype=int))
    with pytest.raises(BolusError, match="no triangles"):
        load_stl(tmp_path / "empty.stl")
    V = np.array([[0.0, 0, 0], [1, 0, 0], [np.nan, 0, 0]])
    write_binary(tmp_path / "nan.stl", V, np.array([[0, 1, 2]]))
    with pytest.raises(BolusError, match="NaN"):
        load_stl(tmp_path / "nan.stl")
