"""2-D cross product (core.geometry2d) and numpy 1.26 / 2.x hygiene of the code base.

numpy 2 (Blender 5.1+, Python 3.13) raises on ``np.cross`` of 2-vectors and dropped a
number of aliases; numpy 1.26 (Blender 4.2-5.0) still accepts them.  The static scan
below fails on either numpy when such a call comes back; `make test` runs the whole
suite on both.
"""
import re
from pathlib import Path

import numpy as np
import pytest

from bolus_addon.core.mesh.geometry2d import cross2d

ROOT = Path(__file__).resolve().parents[3]


def test_cross2d_is_the_z_of_the_3d_cross_product():
    g = np.random.default_rng(0)
    a, b = g.normal(size=(50, 2)), g.normal(size=(50, 2))
    z = np.zeros((50, 1))
    want = np.cross(np.hstack([a, z]), np.hstack([b, z]))[:, 2]
    assert np.allclose(cross2d(a, b), want, rtol=0, atol=1e-15)
    assert cross2d([1.0, 0.0], [0.0, 1.0]) == 1.0  # counter-clockwise: positive
    assert cross2d([0.0, 1.0], [1.0, 0.0]) == -1.0
    assert cross2d([2.0, 4.0], [1.0, 2.0]) == 0.0  # parallel


def test_cross2d_broadcasts_like_numpy():
    g = np.random.default_rng(1)
    a, b = g.normal(size=(4, 1, 2)), g.normal(size=(1, 7, 2))
    out = cross2d(a, b)
    assert out.shape == (4, 7)
    assert out[2, 5] == pytest.approx(a[2, 0, 0] * b[0, 5, 1] - a[2, 0, 1] * b[0, 5, 0], abs=1e-15)
    tri = g.normal(size=(9, 3, 2))  # twice the signed areas of 9 triangles
    area2 = cross2d(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.allclose(area2, -cross2d(tri[:, 2] - tri[:, 0], tri[:, 1] - tri[:, 0]))


def test_cross2d_refuses_non_planar_vectors():
    with pytest.raises(ValueError, match=r"\(\.\.\., 2\)"):
        cross2d(np.zeros((3, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError):
        cross2d(np.zeros(2), np.zeros(3))


# names gone in numpy 2 (AttributeError there) or deprecated in 1.25+/2.x
REMOVED = ("in1d", "trapz", "product", "cumproduct", "row_stack", "NaN", "Inf", "NINF", "PINF", "infty",
           "float_", "complex_", "alltrue", "sometrue", "asfarray", "find_common_type", "round_", "msort",
           "string_", "unicode_", "int0", "uint0", "bool8", "cast", "mat", "issubclass_", "deprecate",
           "set_string_function", "source", "lookfor", "who", "byte_bounds", "compare_chararrays")
PATTERN = re.compile(
    r"\bnp\.(" + "|".join(REMOVED) + r")\b"
    r"|\bnp\.core\b"  # private in numpy 2 (numpy._core)
    r"|(?<!\bnp)\.(ptp|itemset|newbyteorder)\("  # ndarray methods removed in numpy 2 (np.ptp stays)
    r"|\bnp\.(array|asarray)\([^)]*copy=False"  # means "never copy" in numpy 2
)


def python_sources():
    for folder in ("bolus_addon", "tests", "bench", "scripts"):
        yield from (p for p in (ROOT / folder).rglob("*.py") if "__pycache__" not in p.parts)


def test_no_numpy_calls_removed_in_numpy_2():
    hits = [f"{path.relative_to(ROOT)}:{no}: {line.strip()}" for path in python_sources()
            for no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
            if PATTERN.search(line.split("#", 1)[0]) and path.name != "test_core_geometry2d.py"]
    assert not hits, "numpy calls removed in numpy 2 (use the documented replacement):\n" + "\n".join(hits)
