"""Meshes as arrays: topology, boundary loops and cutting open, geodesics, 2-D geometry, island layout, remesh maps, OBJ and STL reading."""
