"""Where the skin cannot lie flat and how it falls into patches: saliency (eqs. 4-1..4-3), curvature, spectral segmentation (eqs. 3-3..3-8), clustering."""
