"""Synthetic scenes: the physically exact renderer that provides ground truth for benchmarks."""
