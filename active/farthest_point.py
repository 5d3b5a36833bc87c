"""Farthest-point sampling of views: the seed views of a run (`active.schedule.farthest_point_views`) and the
`coverage` selector's picks use this one loop."""
from __future__ import annotations

import torch


def farthest_point_picks(points: torch.Tensor, chosen: list[int], candidates: list[int], k: int) -> list[int]:
    """`k` candidates by farthest-point sampling from `chosen` (no chosen views: start from the lowest candidate id).

    Each pick is the candidate farthest (Euclidean) from its nearest neighbour among `chosen` and the picks so far;
    exact ties go to the lowest view id. At most len(candidates) picks.

    Args:
        points: one point per view id. [V, D]
        chosen: view ids already in the set (not picked again unless also candidates).
        candidates: the view ids to pick from.
    """
    pool = sorted(candidates)
    cand = points[pool]  # [M, D]
    dist = torch.full((len(pool),), float("inf"), dtype=points.dtype, device=points.device)  # [M]
    for view in chosen:
        dist = torch.minimum(dist, (cand - points[view]).norm(dim=-1))
    picks = []
    for _ in range(min(k, len(pool))):
        best = int(torch.argmax(dist))  # the first maximum: the lowest id
        picks.append(pool[best])
        dist = torch.minimum(dist, (cand - cand[best]).norm(dim=-1))
        dist[best] = -1.0  # never again
    return picks
