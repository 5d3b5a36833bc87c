"""`probe_pop`: greedy D-optimal selection over the model plus probe Gaussians in the space no captured view observed.

A parameter Fisher values only views of Gaussians that exist; from a model trained on a few views that is the
geometry the captured views already show (docs/diagnosis.md). This selector builds the log-det oracle over the model
with probe Gaussians appended where no captured view has seen through (`active.probes`: a grid of faint Gaussians
over the model's box, those in observed free space dropped), so a candidate also gains the information about the
unobserved space it would see. Greedy over the whole pool at every pick, computed lazily (`lazy_greedy_select`):
exactly plain greedy on that oracle, ties to the lowest view id. With no unobserved cell it is pop_gs.

Counts: conservative = pop_gs's worst case, sum_{j < min(K, M)} (M - j); evaluated (counted by the oracle) = the
gains actually computed, over N + probes Gaussians each.
"""
from __future__ import annotations

from active.base import Selection, SelectionContext, Selector, check_k
from active.oracle_counts import exhaustive_count
from active.registry import register_selector
from active.selectors.lazy_greedy import lazy_greedy_select


@register_selector("probe_pop")
class ProbePopSelector(Selector):
    """Exact greedy on the log-det gain over the model and its probes of unobserved space."""

    oracle_kind = "logdet_probes"

    def conservative_count(self, m: int, k: int) -> int:
        return exhaustive_count(m, k)

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        candidates = sorted(ctx.candidate_ids)
        k = min(k, len(candidates))
        sel = lazy_greedy_select(candidates, k, ctx.oracle, lambda j, pool: pool)
        return Selection(sel.ids, sel.gains, exhaustive_count(len(candidates), k))
