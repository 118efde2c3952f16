"""The one way the core turns an ``rng`` argument into a random generator."""

import numpy as np


def as_rng(rng) -> np.random.Generator:
    """``rng`` as a Generator (accepts None, an int seed or a Generator)."""
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
