"""`ssg`: static-subset greedy (the paper's ablation of LiTe-GS).

One subset of size p = max(K, floor(M ln(1/eps) / K)) is drawn at the start of the stage (the lite_gs size for
j = 0; at least K members so that K views can be chosen) and every pick is a lazy greedy step over what is left of
it, with gains cached across the picks. Conservative count: sum_{j < K} (p - j).
"""
from __future__ import annotations

import torch

from active.base import LogDetSelector, Selection, SelectionContext, check_k
from active.oracle_counts import exhaustive_count
from active.registry import register_selector
from active.selectors.lazy_greedy import lazy_greedy_select
from active.selectors.lite_gs import LiteGSConfig, subset_size


def ssg_subset_size(m: int, k: int, eps: float) -> int:
    """ssg subset size: the lite_gs size for the whole pool, raised to K so that K views can be chosen (K >= 1)."""
    return min(m, max(k, subset_size(m, k, eps)))


@register_selector("ssg", config=LiteGSConfig)  # the same options, eps and gain_weight
class SSGSelector(LogDetSelector):
    """Lazy greedy over one random subset drawn once per stage."""

    config_class = LiteGSConfig

    def conservative_count(self, m: int, k: int) -> int:
        k = min(k, m)
        return exhaustive_count(ssg_subset_size(m, k, self.config.eps), k) if k else 0  # exhaustive over the subset

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        candidates = sorted(ctx.candidate_ids)
        m = len(candidates)
        k = min(k, m)
        p = ssg_subset_size(m, k, self.config.eps) if k else 0  # no candidates: nothing to draw
        subset = [candidates[i] for i in torch.randperm(m, generator=ctx.generator)[:p].tolist()]
        return lazy_greedy_select(subset, k, ctx.oracle, lambda j, pool: pool)  # p - j members at pick j
