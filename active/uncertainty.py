"""Per-Gaussian and per-pixel uncertainty from the Fisher information of the training views.

Per Gaussian i, with A_i = H_train,i + delta_i I its prior block (the training views' Fisher blocks over the run's
`--fisher_params`, plus the oracle's ridge delta_i = delta_rel max diag + delta_abs, `active.logdet.BlockInformation`):

    u_i = trace([A_i^-1]_means),

the trace of the 3 x 3 positional block of the inverse: the marginal posterior variance of the mean under the
Laplace approximation, in world units^2 x sigma^2 (the other parameters are marginalised, not held fixed). A Gaussian
no training view sees has only the ridge: u_i = 3 / delta_abs.

Per pixel, u_i is alpha-composited like a colour (render with `override_color`, black background): the map is
sum_i w_i u_i with w_i the blending weights, 0 where nothing is drawn.

That is the kind "position_variance". Two more kinds follow FisherRF's `render_uncertainty.py` (docs/deviations.md):

* "fisherrf" (its `render_set`): per Gaussian the information of its colour parameters, the diagonal Fisher of sh_dc
  and sh_rest summed over the training views and over those parameters, times the Gaussian's depth in the rendered
  view (clamped at 0), composited; larger = more uncertain (FisherRF's convention, kept as is); pixels where nothing
  is drawn get the map's maximum (FisherRF's ause.py: log 0 = -inf replaced by the maximum).
* "fisherrf_view" (its `render_set_current`): the same from the rendered view's own Fisher diagonal over every
  parameter but rotation, as FisherRF's code computes it (`active.fisher.fisher_view_diagonals_reference`), times
  the unclamped depth.
"""
from __future__ import annotations

import torch

from active.fisher import (FISHER_PARAM_GROUPS, REFERENCE_DIAGONAL_GROUPS, fisher_view_blocks, fisher_view_diagonals,
                           fisher_view_diagonals_reference, parameter_columns, summed_views)
from active.logdet import BlockInformation
from arguments import FisherSettings
from gaussian_renderer import RasterSettings, render
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from utils.errors import parse_distinct_choices
from utils.model_dir import UNCERTAINTY_KINDS


def gaussian_uncertainty(gaussians: GaussianModel, cameras: list[Camera], train_views: list[int],
                         background: torch.Tensor, settings: RasterSettings, *,
                         fisher: FisherSettings = FisherSettings()) -> torch.Tensor:
    """u_i = trace of the means block of (H_train,i + delta_i I)^-1 for every Gaussian (sigma, the ridge and the
    parameter groups of `fisher`). [N] float64"""
    groups = FISHER_PARAM_GROUPS[fisher.fisher_params]
    prior = summed_views(lambda v: fisher_view_blocks(gaussians, cameras[v], background, settings, fisher.sigma,
                                                      groups), train_views)
    information = BlockInformation(prior, delta_rel=fisher.delta_rel, delta_abs=fisher.delta_abs)
    covariance = torch.cholesky_inverse(information.chol)  # A^-1 [N, P, P]
    means = parameter_columns(gaussians, groups)["means"]
    return torch.diagonal(covariance[:, means, means], dim1=-2, dim2=-1).sum(-1)


@torch.no_grad()
def uncertainty_map(camera: Camera, gaussians: GaussianModel, uncertainty: torch.Tensor,
                    settings: RasterSettings) -> torch.Tensor:
    """sum_i w_i u_i per pixel: `uncertainty` [N] rendered as a grey override colour on black. [H, W] float32"""
    colors = uncertainty.to(gaussians.means.dtype)[:, None].expand(-1, 3).contiguous()  # [N, 3]
    background = torch.zeros(3, dtype=gaussians.means.dtype, device=gaussians.means.device)
    return render(camera, gaussians, background, settings, override_color=colors).image[0].float()


COLOUR_GROUPS = ("sh_dc", "sh_rest")


def parse_uncertainty_kinds(text: str) -> tuple[str, ...]:
    """Comma-separated uncertainty kinds -> a tuple; an empty, repeated or unknown one is a one-line UserError that
    lists the valid kinds."""
    return parse_distinct_choices(text, UNCERTAINTY_KINDS, "--uncertainty_kind", "kinds")


def fisherrf_information(gaussians: GaussianModel, cameras: list[Camera], train_views: list[int],
                         background: torch.Tensor, settings: RasterSettings) -> torch.Tensor:
    """FisherRF's per-Gaussian information for its uncertainty map: the diagonal Fisher (sigma = 1) of the colour
    parameters (sh_dc, sh_rest), summed over `train_views` and over those parameters. [N] float64"""
    total = torch.zeros(gaussians.num_gaussians, dtype=torch.float64, device=gaussians.means.device)
    for v in train_views:
        total += fisher_view_diagonals(gaussians, cameras[v], background, settings, 1.0, COLOUR_GROUPS).sum(1)
    return total


def view_information(gaussians: GaussianModel, camera: Camera, background: torch.Tensor,
                     settings: RasterSettings) -> torch.Tensor:
    """FisherRF's per-view information: the view's own Fisher diagonal as FisherRF's code computes it, summed over
    every parameter but rotation. [N] float64"""
    return fisher_view_diagonals_reference(gaussians, camera, background, settings, 1.0,
                                           REFERENCE_DIAGONAL_GROUPS).sum(1)


def camera_depths(gaussians: GaussianModel, camera: Camera) -> torch.Tensor:
    """Each Gaussian's depth (camera-space z) in `camera`. [N]"""
    viewmat = camera.viewmat.to(gaussians.means)
    return gaussians.means.detach() @ viewmat[2, :3] + viewmat[2, 3]


@torch.no_grad()
def fisherrf_map(camera: Camera, gaussians: GaussianModel, information: torch.Tensor, settings: RasterSettings,
                 clamp_depth: bool = True) -> torch.Tensor:
    """FisherRF's map: information_i x depth_i (depth clamped at 0 with `clamp_depth`) composited on black, pixels
    where the composite is 0 (nothing drawn) set to the map's maximum. [H, W] float32"""
    depths = camera_depths(gaussians, camera).double()  # [N]
    values = information.double() * (depths.clamp_min(0) if clamp_depth else depths)
    image = uncertainty_map(camera, gaussians, values, settings)  # [H, W]
    empty = image == 0
    return torch.where(empty, image.max(), image) if not bool(empty.all()) else image

