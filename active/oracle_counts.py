"""Oracle counts of a whole acquisition schedule, from each selector's closed-form `conservative_count(m, k)`.

With a pool of 100 views these reproduce the paper's tables (tests/test_oracle_counts.py): a schedule step's count is
averaged over the steps and rounded up, as the paper reports.
"""
from __future__ import annotations

import math

from active.base import Selector


def schedule_counts(selector: Selector, pool: int = 100, num_init: int = 2, k: int = 3,
                    max_views: int = 11) -> list[int]:
    """Per-step conservative counts of a schedule: `num_init` seed views, then K per step up to `max_views` (a last
    step adds the remainder when K does not divide). Their published summary is `mean_rounded_up(...)`."""
    counts, views = [], num_init
    while views < max_views:
        step = min(k, max_views - views)
        counts.append(selector.conservative_count(pool - views, step))
        views += step
    return counts


def mean_rounded_up(counts: list[int]) -> int:
    """Average over steps, rounded up, as the paper reports (0 for no steps)."""
    return math.ceil(sum(counts) / len(counts)) if counts else 0


def exhaustive_count(m: int, k: int) -> int:
    """Oracle evaluations of exhaustive greedy (every remaining candidate at every pick) choosing K of M candidates:
    sum_{j < min(K, M)} (M - j)."""
    return sum(m - j for j in range(min(k, m)))
