"""Lazy greedy step shared by lite_gs and ssg: a max-priority queue over cached (upper-bound) gains."""
from __future__ import annotations

import heapq

from active.base import GainOracle


def lazy_greedy_pick(members: list[int], cached: dict[int, float], oracle: GainOracle) -> tuple[int, float, int]:
    """Pick the member with the largest true marginal gain, re-evaluating only while a cached key could win.

    Cached gains are upper bounds (submodularity: gains only shrink as S grows; +inf = never evaluated).
    Pop the top, re-evaluate it (one oracle), accept it if its fresh gain is >= the next cached key, else push it
    back with the fresh key; a member that returns to the top with a fresh key wins without another oracle (so a
    pick costs at most len(members) evaluations). Ties go to the lowest view id.
    Returns (view, gain, oracle evaluations).
    """
    heap = [(-cached[v], v) for v in members]
    heapq.heapify(heap)
    evaluations = 0
    fresh: set[int] = set()
    while True:
        key, view = heapq.heappop(heap)
        if view in fresh:
            return view, -key, evaluations
        gain = oracle.gain(view)
        fresh.add(view)
        evaluations += 1
        cached[view] = gain
        if not heap or gain >= -heap[0][0]:
            return view, gain, evaluations
        heapq.heappush(heap, (-gain, view))
