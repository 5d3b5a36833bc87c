"""Greedy facility location over a pool of views: the `coverage` selector's `--coverage_objective pool`.

Farthest-point sampling (`active.farthest_point`) minimises the *largest* distance from a pool view to the set
chosen (k-centre), so it reaches first for the pool's extremes. Facility location minimises the *sum* over the pool
of each view's distance to its nearest chosen view, so its picks stand for many pool views at once (k-medoid-like):

    F(S) = sum_{c in pool} min(cap, min_{s in S} cost(c, s)),    pick = argmax_v F(S) - F(S + {v}).

`cover_pool` computes the same objective per (pose, Gaussian) direction; with every Gaussian at the point the cameras
look at it reduces to this one over viewing directions (cost (1 - cos)/2, cap 1), tested to make the same picks.
"""
from __future__ import annotations

import torch

COSTS = ("centers", "directions")


def pair_costs(points: torch.Tensor, space: str) -> tuple[torch.Tensor, float]:
    """(cost of every pair of rows, cap for a pool view no chosen view covers). [P, P]

    centers: Euclidean distance, capped at the pool's diameter; directions (unit rows): (1 - cos) / 2, capped at 1."""
    if space == "centers":
        cost = torch.cdist(points, points)
        return cost, float(cost.max())
    if space == "directions":
        return (1.0 - points @ points.T).mul_(0.5).clamp_(min=0.0), 1.0
    raise ValueError(f"space must be one of {', '.join(COSTS)}, got {space!r}")


def facility_location_picks(points: torch.Tensor, chosen: list[int], candidates: list[int], k: int,
                            space: str) -> list[int]:
    """`k` candidates by greedy facility location over the pool = `chosen` + `candidates`; exact ties go to the
    lowest view id. At most len(candidates) picks.

    Args:
        points: one point per view id (unit rows for "directions"). [V, D]
        chosen: view ids already taken (they cover the pool from the start).
        candidates: the view ids to pick from.
    """
    remaining = sorted(candidates)
    pool = sorted(set(chosen) | set(remaining))
    row = {view: i for i, view in enumerate(pool)}
    cost, cap = pair_costs(points[pool], space)  # [P, P]
    error = torch.full((len(pool),), cap, dtype=points.dtype, device=points.device)  # [P]
    for view in chosen:
        error = torch.minimum(error, cost[:, row[view]])
    picks = []
    for _ in range(min(k, len(remaining))):
        cols = cost[:, [row[v] for v in remaining]]  # [P, M]
        gains = (error[:, None] - torch.minimum(error[:, None], cols)).sum(0)  # [M]
        best = remaining.pop(int(torch.argmax(gains)))  # the first maximum: the lowest id
        picks.append(best)
        error = torch.minimum(error, cost[:, row[best]])
    return picks
