"""One optimisation step, the order training views are visited in, and the test PSNR of a model."""
from __future__ import annotations

import random

import torch

from gaussian_renderer import RasterSettings, render
from scene.cameras import Camera
from scene.gaussian_model import SH_BAND_EVERY, GaussianModel
from training.config import TrainConfig
from training.optim import PositionLRSchedule
from training.state import TrainState
from utils.errors import UserError
from utils.losses import photometric_loss, psnr


def training_step(state: TrainState, camera: Camera, cfg: TrainConfig, background: torch.Tensor,
                  settings: RasterSettings, lr_schedule: PositionLRSchedule,
                  extent: float) -> tuple[torch.Tensor, torch.Tensor]:
    """One optimisation step on one view; returns (loss, psnr) as detached scalar tensors: reading them is a host
    sync on a GPU, so the caller does it only when it logs. The finiteness guard is the step's one sync."""
    it = state.iteration + 1
    lr_schedule.apply(state.optimizer, it)
    if it % SH_BAND_EVERY == 0:
        state.gaussians.increase_sh_degree()
    out = render(camera, state.gaussians, background, settings)
    gt = camera.image
    loss = photometric_loss(out.image, gt, cfg.optim.lambda_dssim)
    if not torch.isfinite(loss):
        raise UserError(f"the loss became non-finite at iteration {it}; nothing was saved as final. "
                        "Lower the learning rates or check the input images")
    loss.backward()
    with torch.no_grad():
        state.strategy.step_post_backward(state.gaussians, state.optimizer, out.means2d, out.radii, out.visible,
                                          camera.width, camera.height, it, extent)
        state.optimizer.step()
        state.optimizer.zero_grad(set_to_none=True)
        train_psnr = psnr(out.image.detach(), gt)
    state.iteration = it
    return loss.detach(), train_psnr


def next_view(state: TrainState, rng: random.Random) -> int:
    """Views are visited in shuffled passes over the current training set, as in 3DGS."""
    if not state.view_stack:
        state.view_stack = list(state.train_views)
        rng.shuffle(state.view_stack)
    return state.view_stack.pop()


@torch.no_grad()
def mean_psnr(gaussians: GaussianModel, cameras: list[Camera], background: torch.Tensor,
              settings: RasterSettings) -> float | None:
    """Mean PSNR over `cameras` (None when there are none)."""
    if not cameras:
        return None
    values = [float(psnr(render(c, gaussians, background, settings).image.clamp(0, 1), c.image)) for c in cameras]
    return sum(values) / len(values)
