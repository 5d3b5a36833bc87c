"""`lazy_pop`: pop_gs's exhaustive greedy computed lazily (Minoux's accelerated greedy) over the whole pool.

The log-det gain is monotone submodular, so a gain cached at an earlier pick is an upper bound on the gain now.
Every pick is `lazy_greedy_pick` over all the candidates left (bounds start at +inf and persist across the stage's
picks): only the candidates whose bound could still win are re-evaluated, in order (bound descending, view id
ascending), so a stale bound equal to the best fresh gain is refreshed when its id is lower. The picks are pop_gs's,
exact ties included (to the lowest view id); only the evaluated count differs.

Counts: conservative = pop_gs's worst case, sum_{j < min(K, M)} (M - j) (`exhaustive_count`); evaluated (counted
by the oracle) = the gains actually computed: M at the first pick, usually far fewer at the next ones.
"""
from __future__ import annotations

from active.base import Selection, SelectionContext, Selector, check_k
from active.oracle_counts import exhaustive_count
from active.registry import register_selector
from active.selectors.lazy_greedy import lazy_greedy_select


@register_selector("lazy_pop")
class LazyPopSelector(Selector):
    """Lazy greedy over every remaining candidate at every pick: pop_gs's selection with fewer evaluated oracles."""

    def conservative_count(self, m: int, k: int) -> int:
        return exhaustive_count(m, k)  # the worst case: every bound re-evaluated at every pick, as pop_gs

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        candidates = sorted(ctx.candidate_ids)
        k = min(k, len(candidates))
        return lazy_greedy_select(candidates, k, ctx.oracle, lambda j, pool: pool)  # M - j members at pick j
