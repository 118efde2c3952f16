"""EL, EA (seed eqs. 3-30, 3-31) as SPEC measures them: measures.py."""
import numpy as np
import pytest
from meshgen import grid

from bolus_addon.core.unfold.measures import length_area_errors, polygon_errors


def test_errors_are_relative_to_the_skin_not_the_pattern():
    """EL and EA divide by the 3D sums (eqs. 3-30, 3-31; SPEC): a pattern at twice the size
    has every edge 100 % too long and every area 300 % too large (dividing by the pattern's
    own sums would give 50 % and 75 %)."""
    V, F = grid(6, 6, size=60.0)
    UV = 2.0 * V[:, :2]
    EL, EA = length_area_errors(V, F, UV)
    assert EL == pytest.approx(1.0, rel=1e-12)
    assert EA == pytest.approx(3.0, rel=1e-12)
    el, ea, flipped = polygon_errors(V, F.ravel(), UV, F.ravel(), np.full(len(F), 3))[None]
    assert (el, ea, flipped) == (pytest.approx(1.0, rel=1e-12), pytest.approx(3.0, rel=1e-12), 0)
