"""`cover_pop`: greedy D-optimal selection among the candidates COVER rates well (the Fisher gated by COVER).

From a model trained on a few views the log-det gain is a sum of ~1-nat terms over the Gaussians a view sees, so it
favours views of the densest geometry, often beside the captured views (docs/diagnosis.md); COVER's score (the
opacity of the Gaussians a view sees from directions the views taken so far did not) does not. This selector lets
the Fisher choose only among the candidates COVER also values: at pick j a candidate is eligible when its COVER gain
given the views taken so far is at least `cover_gate` times the largest among the remaining candidates (all are
eligible when every COVER gain is 0). Among the eligible, the largest log-det gain wins (lazy greedy over persistent
upper bounds, so exactly plain greedy over each eligible set; ties to the lowest id). `--cover_gate 0` is pop_gs;
`--cover_gate 1` is cover's pick (its exact ties broken by the log-det gain).

Counts: conservative = pop_gs's worst case, sum_{j < min(K, M)} (M - j) (every candidate eligible); evaluated (counted
by the oracle) = the log-det gains actually computed, at most the eligible candidates summed over the picks. The gate
costs one COVER gain per remaining candidate per pick (no Fisher pass), counted apart
(`CoverGatedOracle.cover_evaluated`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from active.base import Selection, SelectionContext, Selector, check_k
from active.oracle_counts import exhaustive_count
from active.registry import register_selector
from active.selectors.lazy_greedy import lazy_greedy_select
from utils.errors import UserError

DEFAULT_COVER_GATE = 0.7  # set from the first picks on the lego and mic recommend-then-train models (docs/selectors.md)


def gated_candidates(cover_gains: dict[int, float], gate: float) -> list[int]:
    """The views whose COVER gain is >= `gate` x the largest (all of them when the largest is 0), in id order."""
    largest = max(cover_gains.values(), default=0.0)
    if largest <= 0.0:
        return sorted(cover_gains)
    return sorted(v for v, g in cover_gains.items() if g >= gate * largest)


@dataclass(frozen=True)
class CoverPopConfig:
    cover_gate: float = field(default=DEFAULT_COVER_GATE, metadata={
        "help": f"cover_pop: a candidate is offered to the Fisher only if its COVER gain is at least this fraction of "
                f"the largest among the remaining candidates, in [0, 1] (0: pop_gs, 1: cover; default "
                f"{DEFAULT_COVER_GATE})"})

    def __post_init__(self) -> None:
        if not 0.0 <= self.cover_gate <= 1.0:
            raise UserError(f"--cover_gate must lie in [0, 1] (0: pop_gs, 1: cover), got {self.cover_gate}")


@register_selector("cover_pop", config=CoverPopConfig)
class CoverPopSelector(Selector):
    """pop_gs restricted, at each pick, to the candidates whose COVER gain is near the best."""

    oracle_kind = "logdet_cover"

    def __init__(self, config: CoverPopConfig | None = None):
        self.config = config if config is not None else CoverPopConfig()

    def conservative_count(self, m: int, k: int) -> int:
        return exhaustive_count(m, k)  # the worst case: every candidate eligible at every pick, as pop_gs

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        candidates = sorted(ctx.candidate_ids)
        k = min(k, len(candidates))

        def eligible(j: int, pool: list[int]) -> list[int]:
            return gated_candidates({v: ctx.oracle.cover_gain(v) for v in pool}, self.config.cover_gate)

        sel = lazy_greedy_select(candidates, k, ctx.oracle, eligible)
        return Selection(sel.ids, sel.gains, exhaustive_count(len(candidates), k))
