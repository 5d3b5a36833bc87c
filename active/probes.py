"""Probe Gaussians: faint Gaussians in the space that no captured view has observed, added to the model for the
Fisher pass only, so that a parameter Fisher can value views of space where the model has no Gaussians yet.

A parameter Fisher carries no information about space that no Gaussian occupies: from a model trained on a few
views, pop_gs values only views of the geometry that exists and picks beside the captured views
(docs/diagnosis.md). With every SfM point in the seed model, the same Fisher beat coverage on bonsai
(docs/recommend.md, `--seed_points all`). Probes stand in for that missing geometry without using any image the user
has not captured:

* the volume: the box of the model's Gaussian centres between their `BOX_QUANTILE` and 1 - `BOX_QUANTILE`
  quantiles per axis, widened on each side by `BOX_MARGIN` of its largest side;
* a regular grid of about `PROBE_COUNT` cells over it (cubic cells of side s), one probe at each cell centre;
* a probe is *observed* when some captured view sees through it: it projects inside the image in front of the
  camera, and the model rendered from that view is transparent there (alpha < `SEE_THROUGH_ALPHA`: the background
  shows) or its expected depth lies beyond the probe's by more than s. Observed probes are dropped: that space is
  known to be empty;
* each kept probe is an isotropic Gaussian of standard deviation s / 2, opacity `PROBE_OPACITY` and grey colour.

The probes behind the captured surfaces or outside every captured frustum remain. A candidate that sees them gains
their information (large: their prior is only the ridge), weighted by the transmittance the model leaves them,
so occluded probes inside an object count for little from any side.
"""
from __future__ import annotations

import math

import torch

from active.cover_oracle import pixel_coordinates
from gaussian_renderer import RasterSettings, rasterization
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel

PROBE_COUNT = 4096  # grid cells over the box (before the observed ones are dropped)
PROBE_OPACITY = 0.1  # faint: a probe barely hides the model behind it
BOX_QUANTILE = 0.02  # the box spans these quantiles of the Gaussian centres (outliers and far floaters excluded)
BOX_MARGIN = 0.1  # ... widened by this share of its size on each side
SEE_THROUGH_ALPHA = 0.5  # a pixel with less accumulated alpha shows the background: its ray is free space


def probe_box(means: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The box probes fill: quantiles of the centres, widened (module docstring). ([3] low, [3] high, float64)"""
    points = means.detach().double().cpu()
    low = torch.quantile(points, BOX_QUANTILE, dim=0)
    high = torch.quantile(points, 1.0 - BOX_QUANTILE, dim=0)
    margin = BOX_MARGIN * float((high - low).max())  # the largest side's share on every axis: a flat model's box
    return low - margin, high + margin  # keeps a thickness


def grid_centres(low: torch.Tensor, high: torch.Tensor, count: int) -> tuple[torch.Tensor, float]:
    """Centres of a regular grid of about `count` cubic cells over the box [low, high], and the cell side.

    Returns:
        centres [M, 3] float64, side s
    """
    extent = (high - low).clamp_min(1e-9)
    side = float((extent.prod() / count) ** (1.0 / 3.0))
    cells = [max(1, round(float(e) / side)) for e in extent]
    axes = [low[a] + (torch.arange(n, dtype=torch.float64) + 0.5) * (extent[a] / n) for a, n in enumerate(cells)]
    grid = torch.stack(torch.meshgrid(*axes, indexing="ij"), dim=-1).reshape(-1, 3)
    return grid, side


def depth_and_alpha(gaussians: GaussianModel, camera: Camera, settings: RasterSettings
                    ) -> tuple[torch.Tensor, torch.Tensor]:
    """The model's expected depth (sum of w z over sum of w) and accumulated alpha per pixel. ([H, W] each)"""
    with torch.no_grad():
        viewmat = camera.viewmat
        z = gaussians.means @ viewmat[2, :3] + viewmat[2, 3]  # [N] camera-space depth of each centre
        out = rasterization(gaussians.means, gaussians.quats, gaussians.scales, gaussians.opacities, z[:, None],
                            viewmat, camera.intrinsics, camera.width, camera.height,
                            background=torch.zeros(1, dtype=z.dtype, device=z.device), settings=settings)
    alpha = out.alpha.detach().double().cpu()
    return out.image[0].detach().double().cpu() / alpha.clamp_min(1e-9), alpha


def observed_probes(points: torch.Tensor, side: float, gaussians: GaussianModel, cameras: list[Camera],
                    train_views: list[int], settings: RasterSettings) -> torch.Tensor:
    """Which points some captured view sees through (module docstring: observed). [M] bool

    Args:
        points: probe centres, float64. [M, 3]
    """
    seen = torch.zeros(points.shape[0], dtype=torch.bool)
    for view in train_views:
        camera = cameras[view]
        u, v, inside = pixel_coordinates(points, camera)
        depth, alpha = depth_and_alpha(gaussians, camera, settings)
        viewmat = camera.viewmat.double().cpu()
        z = points @ viewmat[2, :3] + viewmat[2, 3]  # [M]
        cols = u.clamp(0, camera.width - 1).long()
        rows = v.clamp(0, camera.height - 1).long()
        free = (alpha[rows, cols] < SEE_THROUGH_ALPHA) | (z < depth[rows, cols] - side)
        seen |= inside & free
    return seen


def with_probes(gaussians: GaussianModel, cameras: list[Camera], train_views: list[int],
                settings: RasterSettings, count: int = PROBE_COUNT) -> tuple[GaussianModel, int]:
    """The model with a probe Gaussian in every unobserved grid cell appended after its own Gaussians (module
    docstring), detached, and the number of probes.

    Returns:
        (model of N + probes Gaussians, probes)
    """
    params = {name: value.detach() for name, value in gaussians.params.items()}
    low, high = probe_box(params["means"])
    centres, side = grid_centres(low, high, count)
    keep = ~observed_probes(centres, side, gaussians, cameras, train_views, settings)
    centres = centres[keep].to(params["means"])
    m = centres.shape[0]
    like = params["means"]
    probe_params = {
        "means": centres,
        "quats": torch.tensor([1.0, 0.0, 0.0, 0.0]).to(like).expand(m, 4),
        "log_scales": torch.full((m, 3), math.log(0.5 * side)).to(like),
        "logit_opacities": torch.full((m,), math.log(PROBE_OPACITY / (1.0 - PROBE_OPACITY))).to(like),
        "sh_dc": torch.zeros(m, *params["sh_dc"].shape[1:]).to(like),  # grey: SH 0 is colour 0.5
        "sh_rest": torch.zeros(m, *params["sh_rest"].shape[1:]).to(like),
    }
    merged = GaussianModel(gaussians.max_sh_degree, {name: torch.cat([params[name], probe_params[name]])
                                                     for name in params})
    merged.active_sh_degree = gaussians.active_sh_degree
    return merged, m
