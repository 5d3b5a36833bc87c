"""`pop_gs`: exhaustive greedy D-optimal selection (POP-GS): every remaining candidate is scored at every pick."""
from __future__ import annotations

from active.base import Selection, SelectionContext, Selector, check_k
from active.oracle_counts import exhaustive_count
from active.registry import register_selector


@register_selector("pop_gs")
class PopGSSelector(Selector):
    """Greedy maximisation of the log-det information gain: M - j oracles at pick j, ties to the lowest id.

    Counts: conservative = evaluated = sum_{j < min(K, M)} (M - j).
    """

    def conservative_count(self, m: int, k: int) -> int:
        return exhaustive_count(m, k)

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        remaining = sorted(ctx.candidate_ids)
        ids, gains, calls = [], [], 0
        for _ in range(min(k, len(remaining))):
            best, best_gain = remaining[0], float("-inf")
            for view in remaining:  # ascending ids and a strict '>': ties go to the lowest id
                gain = ctx.oracle.gain(view)
                calls += 1
                if gain > best_gain:
                    best, best_gain = view, gain
            ctx.oracle.commit(best)
            remaining.remove(best)
            ids.append(best)
            gains.append(best_gain)
        return Selection(ids, gains, calls)
