"""Starting positions (seed 4.5.1, eq. 4-24; LSCM): initial_unfolding.py."""
import numpy as np
from meshgen import cylinder_piece

from bolus_addon.core.unfold.initial_unfolding import initial_unfolding
from bolus_addon.core.unfold.measures import length_area_errors
from bolus_addon.core.mesh.topology import MeshTopology


def test_initial_unfolding_is_exact_on_developable_patch():
    V, F = cylinder_piece(30.0, np.pi, na=20, nl=12)
    topo = MeshTopology(V, F)
    UV = initial_unfolding(topo)  # 4.5.1 alone: central crossing + layers, no relaxation
    EL, EA = length_area_errors(V, F, UV)
    assert EL < 1e-9 and EA < 1e-9
