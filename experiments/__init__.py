"""Experiment grids: the paper's protocols as data, one job per run, and a runner over submitit."""
