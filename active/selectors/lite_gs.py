"""`lite_gs`: LiTe-GS (the paper's Algorithm 1), stochastic greedy with a lazy priority queue.

Cached gains gamma_v = +inf for every candidate at the start of the stage. At pick j (0-based) a fresh random subset
R of size p_j = max(1, floor((M - j) ln(1/eps) / K)) (capped at M - j) is drawn from the not-yet-chosen candidates
with the stage's generator; the best member of R is found by lazy evaluation over the cached gains
(`lazy_greedy_pick`); the winner is committed to the oracle. Conservative count: sum_j p_j, about M ln(1/eps) per
step whatever K; evaluated (counted by the oracle): the gains actually computed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from active.base import (GAIN_WEIGHT_HELP, LogDetSelector, Selection, SelectionContext, check_eps, check_gain_weight,
                         check_k)
from active.registry import register_selector
from active.selectors.lazy_greedy import lazy_greedy_select


def subset_size(remaining: int, k: int, eps: float) -> int:
    """lite_gs subset size p = max(1, floor(remaining * ln(1/eps) / K)), capped at `remaining` (K >= 1)."""
    return min(remaining, max(1, math.floor(remaining * math.log(1.0 / eps) / k)))


@dataclass(frozen=True)
class LiteGSConfig:
    eps: float = field(default=0.1, metadata={"help": "accuracy parameter in (0, 1): guarantee 1 - exp(-(1 - eps)), "
                                                      "about M ln(1/eps) oracles per step"})
    gain_weight: str = field(default="none", metadata={"help": GAIN_WEIGHT_HELP})

    def __post_init__(self) -> None:
        check_eps(self.eps)
        check_gain_weight(self.gain_weight)


@register_selector("lite_gs", config=LiteGSConfig)
class LiteGSSelector(LogDetSelector):
    """Stochastic lazy greedy with a fresh subset per pick."""

    config_class = LiteGSConfig

    def conservative_count(self, m: int, k: int) -> int:
        k = min(k, m)
        return sum(subset_size(m - j, k, self.config.eps) for j in range(k))

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        remaining = sorted(ctx.candidate_ids)
        m = len(remaining)
        k = min(k, m)

        def fresh_subset(j: int, pool: list[int]) -> list[int]:  # p_j members drawn from the not-yet-chosen
            draw = torch.randperm(len(pool), generator=ctx.generator)[:subset_size(m - j, k, self.config.eps)]
            return [pool[i] for i in draw.tolist()]

        return lazy_greedy_select(remaining, k, ctx.oracle, fresh_subset)
