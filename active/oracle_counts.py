"""Closed-form oracle counts per acquisition step (the conservative accounting of the LiTe-GS paper)."""
from __future__ import annotations

import math


def subset_size(remaining: int, k: int, eps: float) -> int:
    """p = max(1, floor(remaining * ln(1/eps) / K)), capped at `remaining`: the rule whose counts match the
    published tables (the paper writes p = (M/K) log(1/eps))."""
    return min(remaining, max(1, math.floor(remaining * math.log(1.0 / eps) / k)))


def step_count(method: str, m: int, k: int, eps: float = 0.1) -> int:
    """Conservative oracle count of one step choosing `k` of `m` candidates."""
    k = min(k, m)
    if method == "pop_gs":
        return sum(m - j for j in range(k))
    if method == "lite_gs":
        return sum(subset_size(m - j, k, eps) for j in range(k))
    if method == "ssg":
        p = max(subset_size(m, k, eps), k)
        return sum(p - j for j in range(k))
    if method == "random":
        return 0
    raise ValueError(f"no closed form for {method!r}")


def schedule_counts(method: str, pool: int, num_init: int, k: int, max_views: int, eps: float = 0.1) -> list[int]:
    """Per-step counts over a whole schedule (the last step adds the remainder when K does not divide)."""
    counts, views = [], num_init
    while views < max_views:
        step = min(k, max_views - views)
        counts.append(step_count(method, pool - views, step, eps))
        views += step
    return counts


def mean_rounded_up(counts: list[int]) -> int:
    """Average over steps, rounded up, as the paper reports."""
    return math.ceil(sum(counts) / len(counts)) if counts else 0
