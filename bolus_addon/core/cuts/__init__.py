"""Treatment areas and smooth cut lines on the surface (seed ch. 4.2): borders, level-set cuts, curve fitting."""
