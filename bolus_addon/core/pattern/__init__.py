"""The cut pattern: pieces with their marks, the drawing in paper millimetres, and its writers (export/)."""
