"""`ssg`: static-subset greedy (ablation). Same subset size as lite_gs, but the subset is sampled once per stage
and every pick is a lazy greedy step over what is left of it. Conservative count: sum_j (p - j)."""
from __future__ import annotations

import math

import torch

from active.base import OracleCalls, Selection, SelectionContext, Selector, check_k
from active.oracle_counts import subset_size
from active.registry import register_selector
from active.selectors.lazy_greedy import lazy_greedy_pick
from active.selectors.lite_gs import check_eps


@register_selector("ssg")
class SSGSelector(Selector):
    """Lazy greedy over one random subset of size max(p, K) drawn at the start of the stage."""

    def __init__(self, eps: float = 0.1):
        self.eps = check_eps(eps)

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        candidates = sorted(ctx.candidate_ids)
        m = len(candidates)
        k = min(k, m)
        p = max(subset_size(m, k, self.eps), k)  # at least K members, so K views can be chosen
        subset = [candidates[i] for i in torch.randperm(m, generator=ctx.generator)[:p].tolist()]
        cached = {v: math.inf for v in subset}
        ids, gains, conservative, evaluated = [], [], 0, 0
        for j in range(k):
            conservative += p - j
            view, gain, calls = lazy_greedy_pick(subset, cached, ctx.oracle)
            evaluated += calls
            ctx.oracle.commit(view)
            subset.remove(view)
            ids.append(view)
            gains.append(gain)
        return Selection(ids, gains, OracleCalls(conservative, evaluated))
