"""`cover`: COVER (Chen, Dai et al., CVPR 2026) as we read it: greedy on a geometric coverage score of the model's
Gaussians (`active.cover_oracle`): each pick is the candidate that sees the most opacity-weighted geometry from
directions the views taken so far did not. No Fisher pass and no rendering; the paper reports beating FisherRF and
random on 15 real scenes.

Counts: exhaustive greedy, conservative = evaluated = sum_{j < min(K, M)} (M - j) (a gain costs O(|S| N)).
"""
from __future__ import annotations

from active.registry import register_selector
from active.selectors.pop_gs import ExhaustiveGreedySelector


@register_selector("cover")
class CoverSelector(ExhaustiveGreedySelector):
    """Greedy on COVER's score; ties to the lowest id."""

    oracle_kind = "coverage"
