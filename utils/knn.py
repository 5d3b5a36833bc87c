"""Exact k-nearest-neighbour distances in memory-bounded chunks."""
from __future__ import annotations

import torch


def mean_sq_dist_to_neighbours(points: torch.Tensor, k: int = 3, chunk: int = 2048) -> torch.Tensor:
    """Mean squared distance of each point to its `k` nearest other points. [P, 3] -> [P]"""
    n = points.shape[0]
    if n <= 1:
        return torch.ones(n, dtype=points.dtype, device=points.device)
    k = min(k, n - 1)
    out = torch.empty(n, dtype=points.dtype, device=points.device)
    for start in range(0, n, chunk):
        block = points[start:start + chunk]
        d2 = torch.cdist(block, points).square()  # [c, P]
        d2[torch.arange(block.shape[0]), torch.arange(start, start + block.shape[0])] = float("inf")
        out[start:start + chunk] = d2.topk(k, dim=1, largest=False).values.mean(dim=1)
    return out
