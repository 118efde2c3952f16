"""Unfolding patches into true-scale sheet pieces: crossed springs, relaxation, overlap correction, darts and splits."""
