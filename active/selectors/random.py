"""`random`: K candidates drawn uniformly without replacement with the stage's generator (no oracle calls)."""
from __future__ import annotations

import torch

from active.base import Selection, SelectionContext, Selector, check_k, unscored_selection
from active.registry import register_selector


@register_selector("random")
class RandomSelector(Selector):
    """Uniformly random views; the baseline that uses no information oracle.

    Gains are reported as 0.0 and the count as 0. When the context carries an oracle the picks are still committed
    to it, so its information state matches the chosen set as for every other selector.
    """

    uses_oracle = False

    def conservative_count(self, m: int, k: int) -> int:
        return 0

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        order = torch.randperm(len(ctx.candidate_ids), generator=ctx.generator)[:k].tolist()
        ids = [ctx.candidate_ids[i] for i in order]
        return unscored_selection(ctx, ids)
