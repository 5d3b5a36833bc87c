"""Lazy greedy shared by lite_gs, ssg and lazy_pop: a max-priority queue over cached (upper-bound) gains, the pick
loop, and the optional priority hints to a Fisher cache."""
from __future__ import annotations

import heapq
import math
from typing import Callable

from active.base import GainOracle, Selection


def priority_hint(oracle: GainOracle) -> Callable[[int, float], None]:
    """The oracle's optional `set_priority(view, bound)` (a Fisher cache evicting the lowest bound first), or a
    no-op. Hints never change a selection, only which views' Fisher blocks stay cached."""
    return getattr(oracle, "set_priority", None) or (lambda view, bound: None)


def lazy_greedy_pick(members: list[int], cached: dict[int, float], oracle: GainOracle) -> tuple[int, float]:
    """Pick the member with the largest true marginal gain, re-evaluating only while a cached key could win.

    Cached gains are upper bounds (submodularity: gains only shrink as S grows; +inf = never evaluated).
    The heap is ordered by (key descending, view id ascending). Pop the top, re-evaluate it (one oracle) and accept
    it if it still beats the next entry: a larger gain, or an equal gain and a lower id. Otherwise push it back with
    the fresh key; a member that returns to the top with a fresh key wins without another oracle (so a pick costs at
    most len(members) evaluations). This is plain greedy's choice exactly, exact ties going to the lowest view id.
    Returns (view, gain).
    """
    heap = [(-cached[v], v) for v in members]
    heapq.heapify(heap)
    fresh: set[int] = set()
    hint = priority_hint(oracle)
    while True:
        key, view = heapq.heappop(heap)
        if view in fresh:
            return view, -key
        gain = oracle.gain(view)
        fresh.add(view)
        cached[view] = gain
        hint(view, gain)  # the new upper bound: a Fisher cache keeps the highest
        if not heap or (-gain, view) < heap[0]:  # strictly ahead of the next entry in heap order
            return view, gain
        heapq.heappush(heap, (-gain, view))


def lazy_greedy_select(pool: list[int], k: int, oracle: GainOracle,
                       members_for_pick: Callable[[int, list[int]], list[int]]) -> Selection:
    """K lazy greedy picks; pick j chooses among `members_for_pick(j, pool)` (a subset of what is left of `pool`).

    Cached gains start at +inf for the whole pool and persist across picks; each winner is committed to the oracle
    and removed from the pool. Conservative count: the members offered at every pick, summed.
    """
    pool = list(pool)
    cached = {v: math.inf for v in pool}
    ids, gains, conservative = [], [], 0
    hint = priority_hint(oracle)
    for j in range(k):
        members = members_for_pick(j, pool)
        conservative += len(members)
        view, gain = lazy_greedy_pick(members, cached, oracle)
        oracle.commit(view)
        hint(view, -math.inf)  # chosen: never asked for again this stage
        pool.remove(view)
        ids.append(view)
        gains.append(gain)
    return Selection(ids, gains, conservative)
