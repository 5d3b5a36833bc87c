"""`cover_pool`: greedy on COVER's direction coverage measured over the pool's poses (`active.pool_cover_oracle`):
each pick is the candidate after which every pool pose's view of the model's Gaussians lies closest in direction to
a captured view (opacity-weighted). Where `cover` rewards the newest directions (the far side first), this rewards
the directions that stand for many poses of the pool. Geometric: no Fisher pass, no rendering.

The gain is monotone submodular, so the greedy picks are computed lazily over the whole pool, as `lazy_pop` does
(exhaustive greedy's picks, ties included). Counts: conservative = the exhaustive worst case,
sum_{j < min(K, M)} (M - j); evaluated = the gains computed (a gain costs O(|pool| n_v), n_v the Gaussians it sees).
"""
from __future__ import annotations

from active.registry import register_selector
from active.selectors.lazy_pop import LazyPopSelector


@register_selector("cover_pool")
class CoverPoolSelector(LazyPopSelector):
    """Lazy greedy on the pool-coverage gain over every remaining candidate; ties to the lowest id."""

    oracle_kind = "pool_coverage"
