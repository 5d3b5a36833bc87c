"""Closed-form oracle counts per acquisition step (the conservative accounting of the LiTe-GS paper).

With a pool of 100 views these reproduce the paper's tables (see tests/test_oracle_counts.py): the subset size is
p_j = max(1, floor((M - j) ln(1/eps) / K)), M - j being the candidates left at pick j (the paper writes
p = (M/K) log(1/eps)), and a schedule step's count is averaged over the steps and rounded up.
"""
from __future__ import annotations

import math

from active.base import check_eps


def subset_size(remaining: int, k: int, eps: float) -> int:
    """lite_gs subset size p = max(1, floor(remaining * ln(1/eps) / K)), capped at `remaining` (K >= 1)."""
    return min(remaining, max(1, math.floor(remaining * math.log(1.0 / eps) / k)))


def ssg_subset_size(m: int, k: int, eps: float) -> int:
    """ssg subset size: the lite_gs size for the whole pool, raised to K so that K views can be chosen (K >= 1)."""
    return min(m, max(k, subset_size(m, k, eps)))


def conservative_count(method: str, m: int, k: int, eps: float = 0.1) -> int:
    """Conservative oracle count of one step choosing `k` of `m` candidates (K >= M: all M are chosen)."""
    k = min(k, m)
    if method in ("lite_gs", "ssg"):
        check_eps(eps)
    if k <= 0 or method == "random":
        return 0
    if method == "pop_gs":
        return sum(m - j for j in range(k))
    if method == "lite_gs":
        return sum(subset_size(m - j, k, eps) for j in range(k))
    if method == "ssg":
        p = ssg_subset_size(m, k, eps)
        return sum(p - j for j in range(k))
    raise ValueError(f"no closed-form oracle count for selector {method!r}")


step_count = conservative_count  # the name the experiment scripts and their tests import


def schedule_counts(method: str, pool: int = 100, num_init: int = 2, k: int = 3, max_views: int = 11,
                    eps: float = 0.1) -> list[int]:
    """Per-step conservative counts of a schedule: `num_init` seed views, then K per step up to `max_views` (a last
    step adds the remainder when K does not divide). Their published summary is `mean_rounded_up(...)`."""
    counts, views = [], num_init
    while views < max_views:
        step = min(k, max_views - views)
        counts.append(conservative_count(method, pool - views, step, eps))
        views += step
    return counts


def mean_rounded_up(counts: list[int]) -> int:
    """Average over steps, rounded up, as the paper reports (0 for no steps)."""
    return math.ceil(sum(counts) / len(counts)) if counts else 0
