"""COVER's geometric score as a counted oracle: how much of the model's geometry a view sees from a direction that
the views taken so far did not.

COVER (Chen, Dai et al., "Coverage Optimization for Camera View Selection", CVPR 2026, arXiv 2604.05259) derives,
from the Fisher information gain, that an informative view covers geometry the past cameras observed poorly, and
scores it without transmittance. This module is our reading of that principle over the model's Gaussians (written
from the paper's stated idea, not its code):

    gain(v | S) = sum_{i in F(v)} w_i * min(1, min_{c in S, i in F(c)} (1 - d_v,i . d_c,i) / 2)

* F(c): the Gaussians whose centre lies in camera c's frustum (positive depth, projected inside the image);
  no occlusion test, so the score needs no rendering;
* d_c,i: the unit direction from c's centre to Gaussian i; (1 - cos) / 2 = sin^2(theta / 2) is 0 for a ray
  already taken and 1 for the opposite one;
* a Gaussian no view of S sees counts fully (1);
* w_i: the Gaussian's opacity, so that near-transparent Gaussians (floaters) weigh little.

A gain can only shrink as S grows (the inner min runs over more cameras), so cached gains are upper bounds and the
lazy selectors stay exact. `evaluated` counts the gains computed, like every oracle. `views_computed` and
`fisher_seconds` are reported as 0 (no Fisher pass is made).
"""
from __future__ import annotations

import torch

from scene.cameras import Camera
from scene.gaussian_model import GaussianModel


def pixel_coordinates(means: torch.Tensor, camera: Camera) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Pinhole projection of points, without occlusion: pixel coordinates and whether each lands in the image.

    Args:
        means: points (Gaussian centres), float64. [N, 3]
    Returns:
        u [N], v [N] float64 (filled behind the camera too), inside [N] bool (positive depth, inside the image)
    """
    viewmat = camera.viewmat.double().cpu()
    cam = means @ viewmat[:3, :3].T + viewmat[:3, 3]  # [N, 3] camera coordinates (OpenCV: z forward)
    z = cam[:, 2]
    safe_z = z.clamp_min(1e-9)
    u = camera.fx * cam[:, 0] / safe_z + camera.cx
    v = camera.fy * cam[:, 1] / safe_z + camera.cy
    return u, v, (z > 1e-6) & (u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)


def frustum_directions(means: torch.Tensor, camera: Camera) -> tuple[torch.Tensor, torch.Tensor]:
    """Which Gaussians lie in `camera`'s frustum, and the unit direction from its centre to each.

    Args:
        means: Gaussian centres, float64. [N, 3]
    Returns:
        inside [N] bool, directions [N, 3] float64 (rows outside the frustum are still filled)
    """
    inside = pixel_coordinates(means, camera)[2]
    offsets = means - camera.camera_center.double().cpu()
    return inside, offsets / offsets.norm(dim=-1, keepdim=True).clamp_min(1e-12)


class CoverageOracle:
    """The counted COVER gain oracle of one acquisition step (the `GainOracle` protocol: gain, commit, evaluated).

    The committed views (the training views first) are kept as their frustum masks and directions; a gain compares
    the candidate's directions with each committed view's: O(|S| N) per gain.
    """

    views_computed = 0  # no Fisher pass: what acquisition reports for the Fisher oracles
    fisher_seconds = 0.0

    def __init__(self, means: torch.Tensor, weights: torch.Tensor, cameras: list[Camera], train_views: list[int]):
        """Args:
            means: Gaussian centres. [N, 3]
            weights: per-Gaussian weights w_i >= 0 (opacities). [N]
            cameras: every camera of the pool (view id = index).
            train_views: the views taken so far (the prior's).
        """
        self.means = means.detach().double().cpu()
        self.weights = weights.detach().double().cpu()
        self.cameras = cameras
        self.evaluated = 0
        self._committed: list[tuple[torch.Tensor, torch.Tensor]] = []  # (inside [N], directions [N, 3])
        for view in train_views:
            self._committed.append(frustum_directions(self.means, cameras[view]))

    @classmethod
    def for_model(cls, gaussians: GaussianModel, cameras: list[Camera], train_views: list[int]) -> CoverageOracle:
        """COVER's oracle over a model's Gaussians: their centres, weighted by their opacities."""
        return cls(gaussians.means, gaussians.opacities, cameras, train_views)

    def novelty(self, view_id: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Per Gaussian: in the view's frustum, and how new its direction is, min over S of (1 - cos) / 2 (1 where
        no committed view sees it). ([N] bool, [N] float64 in [0, 1])"""
        inside, directions = frustum_directions(self.means, self.cameras[view_id])
        novelty = torch.ones(self.means.shape[0], dtype=torch.float64)
        for seen, other in self._committed:
            taken = 0.5 * (1.0 - (directions * other).sum(-1))  # [N]
            novelty = torch.where(seen, torch.minimum(novelty, taken), novelty)
        return inside, novelty.clamp_(0.0, 1.0)

    def gain(self, view_id: int) -> float:
        """gain(v | S): one oracle evaluation."""
        self.evaluated += 1
        inside, novelty = self.novelty(view_id)
        return float((self.weights * novelty)[inside].sum())

    def commit(self, view_id: int) -> None:
        """S <- S + {v} (not an oracle evaluation)."""
        self._committed.append(frustum_directions(self.means, self.cameras[view_id]))

    def reset_counts(self) -> None:
        self.evaluated = 0
