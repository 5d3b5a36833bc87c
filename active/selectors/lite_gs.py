"""`lite_gs`: LiTe-GS (Algorithm 1), stochastic greedy with a lazy priority queue.

At pick j a fresh random subset R of size p_j = max(1, floor((M - j) ln(1/eps) / K)) of the not-yet-chosen
candidates is drawn; the best member of R by true marginal gain is found by lazy evaluation over gains cached
since the start of the stage. Conservative count: sum_j p_j (about M ln(1/eps) per step, independent of K).
"""
from __future__ import annotations

import math

import torch

from active.base import OracleCalls, Selection, SelectionContext, Selector, check_k
from active.oracle_counts import subset_size
from active.registry import register_selector
from active.selectors.lazy_greedy import lazy_greedy_pick
from utils.errors import UserError


def check_eps(eps: float) -> float:
    if not 0.0 < eps < 1.0:
        raise UserError(f"--eps must lie in (0, 1), got {eps}")
    return float(eps)


@register_selector("lite_gs")
class LiteGSSelector(Selector):
    """Stochastic lazy greedy; `eps` in (0, 1) trades oracle evaluations against the (1 - 1/e - eps) guarantee."""

    def __init__(self, eps: float = 0.1):
        self.eps = check_eps(eps)

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        remaining = sorted(ctx.candidate_ids)
        m = len(remaining)
        cached = {v: math.inf for v in remaining}
        ids, gains, conservative, evaluated = [], [], 0, 0
        for j in range(min(k, m)):
            p = subset_size(m - j, k, self.eps)
            subset = [remaining[i] for i in torch.randperm(len(remaining), generator=ctx.generator)[:p].tolist()]
            conservative += p
            view, gain, calls = lazy_greedy_pick(subset, cached, ctx.oracle)
            evaluated += calls
            ctx.oracle.commit(view)
            remaining.remove(view)
            ids.append(view)
            gains.append(gain)
        return Selection(ids, gains, OracleCalls(conservative, evaluated))
