"""Lazy greedy shared by lite_gs and ssg: a max-priority queue over cached (upper-bound) gains, and the pick loop."""
from __future__ import annotations

import heapq
import math
from typing import Callable

from active.base import GainOracle, Selection


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
    while True:
        key, view = heapq.heappop(heap)
        if view in fresh:
            return view, -key
        gain = oracle.gain(view)
        fresh.add(view)
        cached[view] = gain
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
    for j in range(k):
        members = members_for_pick(j, pool)
        conservative += len(members)
        view, gain = lazy_greedy_pick(members, cached, oracle)
        oracle.commit(view)
        pool.remove(view)
        ids.append(view)
        gains.append(gain)
    return Selection(ids, gains, conservative)
