"""Finding a similar bolus from a photo (seed ch. 5): image edges, contours, spectral skeletons, the library."""
