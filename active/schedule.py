"""The acquisition schedule: seed views, how many views each step adds, and how long each stage trains."""
from __future__ import annotations

import random
from dataclasses import dataclass

import torch

from active.farthest_point import farthest_point_picks
from utils.errors import UserError


SEED_STARTS = ("first", "random")  # where farthest-point seeding starts: the first view, or one drawn with the seed


def first_seed_index(seed_start: str, seed: int, num_views: int) -> int:
    """The index among `num_views` views that farthest-point seeding starts from: 0 ("first"), or one drawn with
    `seed` ("random"; its own generator, so a run's other random streams are untouched). Different seeds can draw
    the same view: of 100 views, seeds 3 and 4 both draw view 30, and seeds 6 and 10 view 73."""
    return random.Random(seed).randrange(num_views) if seed_start == "random" else 0


def farthest_point_views(centers: torch.Tensor, n: int, start: int = 0) -> list[int]:
    """Pick `n` view indices by farthest-point sampling of camera centres, starting from `start`.

    Deterministic (ties go to the lowest index), as FisherRF chooses its seed views.

    Args:
        centers: camera centres of the pool. [V, 3]
        n: number of views to pick (1 <= n <= V).
    """
    num_views = centers.shape[0]
    assert centers.shape == (num_views, 3), f"centers must be [V,3], got {tuple(centers.shape)}"
    others = [v for v in range(num_views) if v != start]
    return [start] + farthest_point_picks(centers, [start], others, n - 1)


@dataclass(frozen=True)
class StagePlan:
    """Numbers of views added per acquisition step and the iteration at which each stage ends.

    Stage s (s = 0 .. len(adds)) trains `iters_per_view * views_in_stage[s]` iterations; after stage s < len(adds)
    the selector adds `adds[s]` views. After the last acquisition the model trains on to `total_iterations`.
    """

    adds: tuple[int, ...]  # views added at each acquisition step
    views_in_stage: tuple[int, ...]  # training-set size during each stage
    stage_end: tuple[int, ...]  # iteration at which each stage ends (the last one = the acquisition-free end)
    total_iterations: int


def plan_stages(num_init: int, k: int, max_views: int, pool: int, iters_per_view: int,
                total_iterations: int) -> StagePlan:
    """Validate the schedule flags and lay out the stages.

    When K does not divide the remaining budget, the last step adds the remainder (fewer than K views).
    """
    if k <= 0:
        raise UserError(f"--views_per_step must be positive, got {k}")
    if num_init <= 0:
        raise UserError(f"--num_init_views must be positive, got {num_init}")
    if num_init >= pool:
        raise UserError(f"--num_init_views ({num_init}) must be smaller than the candidate pool ({pool} training views)")
    if max_views > pool:
        raise UserError(f"--max_views ({max_views}) is larger than the pool of {pool} training views; lower it")
    if max_views < num_init:
        raise UserError(f"--max_views ({max_views}) is smaller than the seed set ({num_init} views); raise it")
    if iters_per_view <= 0:
        raise UserError(f"--iters_per_view must be positive, got {iters_per_view}")
    remaining = max_views - num_init
    adds = tuple([k] * (remaining // k) + ([remaining % k] if remaining % k else []))
    views = [num_init]
    for a in adds:
        views.append(views[-1] + a)
    ends, it = [], 0
    for v in views[:-1]:
        it += iters_per_view * v
        ends.append(it)
    ends.append(max(total_iterations, it))
    return StagePlan(adds, tuple(views), tuple(ends), max(total_iterations, it))

