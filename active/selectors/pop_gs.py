"""`pop_gs`: exhaustive greedy D-optimal selection (POP-GS): every remaining candidate is scored at every pick."""
from __future__ import annotations

from dataclasses import dataclass, field

from active.base import (GAIN_WEIGHT_HELP, GainOracle, LogDetSelector, Selection, SelectionContext, Selector,
                         check_gain_weight, check_k)
from active.oracle_counts import exhaustive_count
from active.registry import register_selector


def exhaustive_greedy(candidate_ids: list[int], k: int, oracle: GainOracle) -> Selection:
    """Plain greedy: M - j oracles at pick j, ties to the lowest id; each pick committed to `oracle`."""
    remaining = sorted(candidate_ids)
    ids, gains, calls = [], [], 0
    for _ in range(min(k, len(remaining))):
        best, best_gain = remaining[0], float("-inf")
        for view in remaining:  # ascending ids and a strict '>': ties go to the lowest id
            gain = oracle.gain(view)
            calls += 1
            if gain > best_gain:
                best, best_gain = view, gain
        oracle.commit(best)
        remaining.remove(best)
        ids.append(best)
        gains.append(best_gain)
    return Selection(ids, gains, calls)


class ExhaustiveGreedySelector(Selector):
    """Plain greedy on the gains of the selector's `oracle_kind` (for selectors with no options: cover,
    render_variance); counts: conservative = evaluated = sum_{j < min(K, M)} (M - j)."""

    def conservative_count(self, m: int, k: int) -> int:
        return exhaustive_count(m, k)

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        return exhaustive_greedy(ctx.candidate_ids, k, ctx.oracle)


@dataclass(frozen=True)
class PopGSConfig:
    gain_weight: str = field(default="none", metadata={"help": GAIN_WEIGHT_HELP})

    def __post_init__(self) -> None:
        check_gain_weight(self.gain_weight)


@register_selector("pop_gs", config=PopGSConfig)
class PopGSSelector(LogDetSelector):
    """Greedy maximisation of the log-det information gain: M - j oracles at pick j, ties to the lowest id.

    Counts: conservative = evaluated = sum_{j < min(K, M)} (M - j).
    """

    config_class = PopGSConfig

    def conservative_count(self, m: int, k: int) -> int:
        return exhaustive_count(m, k)

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        return exhaustive_greedy(ctx.candidate_ids, k, ctx.oracle)
