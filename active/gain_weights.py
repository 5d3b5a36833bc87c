"""Per-Gaussian weights of the log-det gain's terms (`--gain_weight` of the log-det selectors).

A log-det gain is sum_i w_i (logdet(A_i + H_v,i) - logdet(A_i)) over the Gaussians i (`active.logdet`). Unweighted
(w = 1) it is a sum over Gaussians, so a region split into many small Gaussians by densification weighs as many
times more as it has Gaussians. `area` weighs each term by the surface area its Gaussian stands for, so the sum
approximates an integral of information over the scene's surfaces; isolated Gaussians (floaters, far background)
then weigh the most (on the recommend-then-train models the sparsest quarter holds 78-91 % of the weight,
docs/diagnosis.md).
"""
from __future__ import annotations

import torch

from scene.gaussian_model import GaussianModel
from utils.knn import knn_sq_distances

AREA_NEIGHBOURS = 8  # k of the k-th nearest centre whose distance sets a Gaussian's area share


def area_weights(xyz: torch.Tensor, k: int = AREA_NEIGHBOURS) -> torch.Tensor:
    """w_i proportional to r_k(i)^2, the squared distance from centre i to its k-th nearest other centre (fewer
    neighbours in clouds of at most k points): the area each Gaussian covers when Gaussians tile surfaces (their
    density per unit area is ~k / (pi r_k^2)). Mean 1, so a gain stays on the unweighted scale; all ones when every
    centre coincides or there is one. xyz [N, 3] -> [N] float64"""
    n = xyz.shape[0]
    if n < 2:
        return torch.ones(n, dtype=torch.float64)
    squared = knn_sq_distances(xyz.detach().cpu().double(), min(k, n - 1))[:, -1]  # [N]
    mean = squared.mean()
    return squared / mean if mean > 0 else torch.ones_like(squared)


def gain_weights(gaussians: GaussianModel, gain_weight: str) -> torch.Tensor | None:
    """The weights w [N] that `gain_weight` names (`active.base.GAIN_WEIGHTS`); None for "none" (every term 1)."""
    if gain_weight == "none":
        return None
    if gain_weight == "opacity":
        return gaussians.opacities.detach()
    if gain_weight == "area":
        return area_weights(gaussians.means)
    raise ValueError(f"unknown gain weight {gain_weight!r}")
