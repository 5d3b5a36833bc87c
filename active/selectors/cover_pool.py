"""`cover_pool`: greedy on COVER's direction coverage measured over the pool's poses (`active.pool_cover_oracle`):
each pick is the candidate after which every pool pose's view of the model's Gaussians lies closest in direction to
a captured view (opacity-weighted). Where `cover` rewards the newest directions (the far side first), this rewards
the directions that stand for many poses of the pool. Geometric: no Fisher pass, no rendering.

`--pool_weight pixels` weighs each (pose, Gaussian) pair by the pixels the Gaussian paints in that pose (occlusion
included, one render per pose) instead of its opacity, and a view covers only the Gaussians it actually paints.

The gain is monotone submodular, so the greedy picks are computed lazily over the whole pool, as `lazy_pop` does
(exhaustive greedy's picks, ties included). Counts: conservative = the exhaustive worst case,
sum_{j < min(K, M)} (M - j); evaluated = the gains computed (a gain costs O(|pool| n_v), n_v the Gaussians it sees).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from active.pool_cover_oracle import POOL_WEIGHTS
from active.registry import register_selector
from active.selectors.lazy_pop import LazyPopSelector
from utils.errors import UserError


@dataclass(frozen=True)
class CoverPoolConfig:
    pool_weight: str = field(default="opacity", metadata={
        "help": "cover_pool: what a (pose, Gaussian) pair weighs: opacity (the Gaussian's, pose-independent, frustum "
                "test) or pixels (the pixels it paints in that pose, occlusion included; one render per pose)"})

    def __post_init__(self) -> None:
        if self.pool_weight not in POOL_WEIGHTS:
            raise UserError(f"--pool_weight must be one of {', '.join(POOL_WEIGHTS)}, got {self.pool_weight!r}")


@register_selector("cover_pool", config=CoverPoolConfig)
class CoverPoolSelector(LazyPopSelector):
    """Lazy greedy on the pool-coverage gain over every remaining candidate; ties to the lowest id."""

    def __init__(self, config: CoverPoolConfig | None = None):
        self.config = config if config is not None else CoverPoolConfig()
        self.oracle_kind = "pool_coverage" if self.config.pool_weight == "opacity" else "pool_coverage_pixels"
