"""Print segmentation and print directions (seed ch. 6): measures, orientation, ABcut, the learned split."""
