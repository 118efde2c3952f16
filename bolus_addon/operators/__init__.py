"""The operators, one module per stage; each imports blender/ and core/ only."""
