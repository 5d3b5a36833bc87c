"""`random`: K candidates drawn uniformly without replacement (seeded; a fresh draw per stage)."""
from __future__ import annotations

import torch

from active.base import OracleCalls, Selection, SelectionContext, Selector, check_k
from active.registry import register_selector


@register_selector("random")
class RandomSelector(Selector):
    """Uniformly random views; the baseline that uses no information oracle."""

    uses_oracle = False

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        order = torch.randperm(len(ctx.candidate_ids), generator=ctx.generator)[:k].tolist()
        ids = [ctx.candidate_ids[i] for i in order]
        return Selection(ids, [0.0] * len(ids), OracleCalls(0, 0))
