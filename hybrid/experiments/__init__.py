"""Experiments: the seed paper's Table I, side-by-side comparisons, ablations and their figures."""
