"""`cover_pool`: greedy on COVER's direction coverage measured over the pool's poses (`active.pool_cover_oracle`):
each pick is the candidate after which every pool pose's view of the model's Gaussians lies closest in direction to
a captured view (opacity-weighted). Where `cover` rewards the newest directions (the far side first), this rewards
the directions that stand for many poses of the pool. Geometric: no Fisher pass, no rendering.

`--pool_weight pixels` weighs each (pose, Gaussian) pair by the pixels the Gaussian paints in that pose (occlusion
included, one render per pose) instead of its opacity, and a view covers only the Gaussians it actually paints.

`--pool_compare coverage` also scores coverage's picks (farthest-point sampling of the camera centres from the
captured views) under the same objective, F(S) - F(S + T) as the sum of T's K sequential gains, and keeps the set
that covers more (greedy's on a tie). Greedy guarantees only 1 - 1/e of the best set; where the first pick's large
gain leaves poor complements, the spread set can cover more ([diagnosis](../../docs/diagnosis.md)).

The gain is monotone submodular, so the greedy picks are computed lazily over the whole pool, as `lazy_pop` does
(exhaustive greedy's picks, ties included). Counts: conservative = the exhaustive worst case,
sum_{j < min(K, M)} (M - j), plus min(K, M) with `--pool_compare coverage`; evaluated = the gains computed (a gain
costs O(|pool| n_v), n_v the Gaussians it sees).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from active.base import Selection, SelectionContext
from active.farthest_point import farthest_point_picks
from active.oracle_counts import exhaustive_count
from active.pool_cover_oracle import POOL_WEIGHTS
from active.registry import register_selector
from active.selectors.coverage import coverage_points
from active.selectors.lazy_pop import LazyPopSelector
from utils.errors import UserError

POOL_COMPARE = ("none", "coverage")  # cover_pool's --pool_compare
POOL_COMPARE_HELP = ("cover_pool: none (greedy's picks) or coverage (also score coverage's farthest-camera picks "
                     "under the same objective and keep the set that covers more; K more oracle evaluations)")


@dataclass(frozen=True)
class CoverPoolConfig:
    pool_weight: str = field(default="opacity", metadata={
        "help": "cover_pool: what a (pose, Gaussian) pair weighs: opacity (the Gaussian's, pose-independent, frustum "
                "test) or pixels (the pixels it paints in that pose, occlusion included; one render per pose)"})

    pool_compare: str = field(default="none", metadata={"help": POOL_COMPARE_HELP})

    def __post_init__(self) -> None:
        if self.pool_weight not in POOL_WEIGHTS:
            raise UserError(f"--pool_weight must be one of {', '.join(POOL_WEIGHTS)}, got {self.pool_weight!r}")
        check_pool_compare(self.pool_compare)


def check_pool_compare(value: str) -> None:
    """`--pool_compare` must name a known comparison (one clear line otherwise)."""
    if value not in POOL_COMPARE:
        raise UserError(f"--pool_compare must be one of {', '.join(POOL_COMPARE)}, got {value!r}")


@register_selector("cover_pool", config=CoverPoolConfig)
class CoverPoolSelector(LazyPopSelector):
    """Lazy greedy on the pool-coverage gain over every remaining candidate; ties to the lowest id."""

    def __init__(self, config: CoverPoolConfig | None = None):
        self.config = config if config is not None else CoverPoolConfig()
        self.oracle_kind = "pool_coverage" if self.config.pool_weight == "opacity" else "pool_coverage_pixels"

    def conservative_count(self, m: int, k: int) -> int:
        compared = min(k, m) if self.config.pool_compare == "coverage" else 0
        return exhaustive_count(m, k) + compared

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        if self.config.pool_compare == "none":
            return super().select(ctx, k)
        oracle = ctx.oracle
        before = oracle.snapshot()
        greedy = super().select(ctx, k)  # commits greedy's picks
        after_greedy = oracle.snapshot()
        oracle.restore(before)
        spread = farthest_point_picks(coverage_points(ctx, "centers"), list(ctx.train_ids), ctx.candidate_ids,
                                      len(greedy.ids))
        spread_gains = []
        for view in spread:  # F(S) - F(S + T) as T's sequential gains: one oracle evaluation each
            spread_gains.append(oracle.gain(view))
            oracle.commit(view)
        conservative = greedy.conservative + len(spread)
        spread_covers, greedy_covers = sum(spread_gains), sum(greedy.gains)
        if spread_covers > greedy_covers:
            return Selection(spread, spread_gains, conservative,
                             f"cover_pool --pool_compare coverage: kept coverage's farthest-camera picks, which cover "
                             f"{spread_covers:.6g} of the objective against greedy's {greedy_covers:.6g}")
        oracle.restore(after_greedy)
        return Selection(greedy.ids, greedy.gains, conservative,
                         f"cover_pool --pool_compare coverage: kept greedy's picks, which cover {greedy_covers:.6g} "
                         f"of the objective against coverage's farthest-camera picks' {spread_covers:.6g}")
