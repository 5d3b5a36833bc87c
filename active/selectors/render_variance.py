"""`render_variance`: greedy I-optimal (V-optimal) selection: each pick removes the most predicted rendering variance
over the candidate poses (`active.variance_oracle`), on the same per-Gaussian Fisher blocks and ridge as pop_gs.

Where pop_gs's log-det counts a parameter's information the same whatever it does to an image, this criterion weighs
each Gaussian by how much its parameters move the pixels of the candidate poses (the target T = the pool's summed
blocks), so near-transparent Gaussians, which carry half of a log-det gain from few views (docs/diagnosis.md), count
little. The test poses never enter.

Counts: plain greedy (the variance reduction is not submodular, so no lazy bounds): conservative = evaluated =
sum_{j < min(K, M)} (M - j). Fisher passes: every candidate once for the target, before the first gain.
"""
from __future__ import annotations

from active.registry import register_selector
from active.selectors.pop_gs import ExhaustiveGreedySelector


@register_selector("render_variance")
class RenderVarianceSelector(ExhaustiveGreedySelector):
    """Greedy on the predicted rendering variance each candidate removes; ties to the lowest id."""

    oracle_kind = "render_variance"
