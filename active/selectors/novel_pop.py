"""`novel_pop`: greedy D-optimal selection among the novel candidates only (the Fisher gated by coverage).

From a model trained on a few views, a parameter Fisher values only views of the geometry that already exists, so
pop_gs's picks land beside the captured views (docs/diagnosis.md, docs/recommend.md). This selector keeps the
Fisher's choice but offers it only candidates that coverage would also call new: at pick j a candidate is eligible
when its distance to the nearest of the training views and the picks so far is at least `novelty` times the
largest such distance among the remaining candidates (distances between coverage's points: camera centres, or
viewing directions with `--coverage_space directions`). Among the eligible, the largest log-det gain wins (lazy
greedy over persistent upper bounds, so exactly plain greedy over each eligible set; ties to the lowest id).
`--novelty 0` is pop_gs; `--novelty 1` is coverage's farthest point, its exact distance ties broken by the gain.

Counts: conservative = pop_gs's worst case, sum_{j < min(K, M)} (M - j) (every candidate eligible); evaluated
(counted by the oracle) = the gains actually computed, at most the eligible candidates summed over the picks.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import torch

from active.base import (GAIN_WEIGHT_HELP, LogDetSelector, Selection, SelectionContext, check_gain_weight,
                         check_k)
from active.oracle_counts import exhaustive_count
from active.registry import register_selector
from active.selectors.coverage import COVERAGE_SPACE_HELP, CoverageConfig, coverage_points
from active.selectors.lazy_greedy import lazy_greedy_select
from utils.errors import UserError


def novel_candidates(points: torch.Tensor, chosen: list[int], pool: list[int], novelty: float) -> list[int]:
    """The members of `pool` whose distance to the nearest `chosen` view is >= `novelty` x the largest such
    distance over `pool` (all of `pool` when nothing is chosen). Order kept.

    Args:
        points: one point per view id. [V, D]
    """
    if not chosen or not pool:
        return list(pool)
    nearest = torch.cdist(points[pool], points[chosen]).min(dim=1).values  # [|pool|]
    threshold = novelty * float(nearest.max())
    return [view for view, d in zip(pool, nearest.tolist()) if d >= threshold]


@dataclass(frozen=True)
class NovelPopConfig:
    novelty: float = field(default=0.5, metadata={"help": "novel_pop: a candidate is offered to the Fisher only if "
                                                          "its distance to the nearest training view or pick is at "
                                                          "least this fraction of the largest such distance, in "
                                                          "[0, 1] (0: pop_gs, 1: coverage)"})
    coverage_space: str = field(default="centers", metadata={"help": COVERAGE_SPACE_HELP})
    gain_weight: str = field(default="none", metadata={"help": GAIN_WEIGHT_HELP})

    def __post_init__(self) -> None:
        if not 0.0 <= self.novelty <= 1.0:
            raise UserError(f"--novelty must lie in [0, 1] (0: pop_gs, 1: coverage), got {self.novelty}")
        CoverageConfig(self.coverage_space)  # validates the space
        check_gain_weight(self.gain_weight)


@register_selector("novel_pop", config=NovelPopConfig)
class NovelPopSelector(LogDetSelector):
    """pop_gs restricted, at each pick, to the candidates far enough from the views taken so far."""

    config_class = NovelPopConfig

    def conservative_count(self, m: int, k: int) -> int:
        return exhaustive_count(m, k)  # the worst case: every candidate eligible at every pick, as pop_gs

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        candidates = sorted(ctx.candidate_ids)
        m = len(candidates)
        k = min(k, m)
        points = coverage_points(ctx, self.config.coverage_space)  # [V, 3]

        def eligible(j: int, pool: list[int]) -> list[int]:
            picked = [v for v in candidates if v not in pool]
            return novel_candidates(points, list(ctx.train_ids) + picked, pool, self.config.novelty)

        sel = lazy_greedy_select(candidates, k, ctx.oracle, eligible)
        return Selection(sel.ids, sel.gains, exhaustive_count(m, k))
