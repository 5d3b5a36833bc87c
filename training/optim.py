"""Adam with one parameter group per Gaussian attribute, and the 3DGS position learning-rate schedule."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from scene.gaussian_model import GaussianModel
from utils.losses import LAMBDA_DSSIM


@dataclass(frozen=True)
class OptimConfig:
    """Learning rates and loss weights (original 3DGS values)."""

    position_lr_init: float = field(default=1.6e-4, metadata={"help": "initial position LR (x scene extent)"})
    position_lr_final: float = field(default=1.6e-6, metadata={"help": "final position LR (x scene extent)"})
    position_lr_delay_mult: float = field(default=0.01, metadata={"help": "position LR warm-up multiplier"})
    position_lr_max_steps: int = field(default=30_000, metadata={"help": "iterations of the position LR decay"})
    feature_lr: float = field(default=2.5e-3, metadata={"help": "SH DC LR (the rest use feature_lr / 20)"})
    # 0.05 as in the 3DGS paper release; later graphdeco versions lowered it to 0.025 (pass --opacity_lr 0.025).
    opacity_lr: float = field(default=0.05, metadata={"help": "opacity LR"})
    scaling_lr: float = field(default=5e-3, metadata={"help": "log-scale LR"})
    rotation_lr: float = field(default=1e-3, metadata={"help": "quaternion LR"})
    lambda_dssim: float = field(default=LAMBDA_DSSIM, metadata={"help": "weight of (1 - SSIM) in the loss"})


PARAM_NAMES = ("means", "sh_dc", "sh_rest", "logit_opacities", "log_scales", "quats")


def create_optimizer(gaussians: GaussianModel, cfg: OptimConfig, spatial_lr_scale: float) -> torch.optim.Adam:
    """Adam (eps 1e-15) with one group per parameter, named by the `gaussians.params` key in `group["name"]`.

    Position LR is scaled by `spatial_lr_scale` (the scene extent) as in 3DGS; `PositionLRSchedule.apply` then
    overwrites it every iteration. sh_rest learns at feature_lr / 20.
    """
    lrs = {"means": cfg.position_lr_init * spatial_lr_scale, "sh_dc": cfg.feature_lr,
           "sh_rest": cfg.feature_lr / 20.0, "logit_opacities": cfg.opacity_lr, "log_scales": cfg.scaling_lr,
           "quats": cfg.rotation_lr}
    assert set(gaussians.params) == set(PARAM_NAMES), f"unexpected parameters {sorted(gaussians.params)}"
    groups = [{"params": [gaussians.params[name]], "lr": lr, "name": name} for name, lr in lrs.items()]
    return torch.optim.Adam(groups, lr=0.0, eps=1e-15)


@dataclass(frozen=True)
class PositionLRSchedule:
    """Log-linear decay from `lr_init` to `lr_final` over `max_steps`, with a sine warm-up (3DGS expon_lr_func).

    lr(step) = delay(step) * lr_init^(1 - t) * lr_final^t with t = clip(step / max_steps, 0, 1), and
    delay(step) = delay_mult + (1 - delay_mult) sin(pi/2 clip(step / delay_steps, 0, 1)) when delay_steps > 0, else 1
    (3DGS passes delay_mult but no delay_steps for positions, so by default there is no warm-up).
    """

    lr_init: float
    lr_final: float
    delay_mult: float
    max_steps: int
    delay_steps: int = 0

    @classmethod
    def from_config(cls, cfg: OptimConfig, spatial_lr_scale: float) -> "PositionLRSchedule":
        """The 3DGS position schedule, both ends scaled by the scene extent."""
        return cls(cfg.position_lr_init * spatial_lr_scale, cfg.position_lr_final * spatial_lr_scale,
                   cfg.position_lr_delay_mult, cfg.position_lr_max_steps)

    def __call__(self, step: int) -> float:
        """Learning rate at `step` (0 for negative steps or an all-zero schedule)."""
        if step < 0 or (self.lr_init == 0.0 and self.lr_final == 0.0):
            return 0.0
        if self.delay_steps > 0:
            delay = self.delay_mult + (1 - self.delay_mult) * math.sin(
                0.5 * math.pi * min(max(step / self.delay_steps, 0.0), 1.0))
        else:
            delay = 1.0
        t = min(max(step / self.max_steps, 0.0), 1.0)
        return delay * math.exp(math.log(self.lr_init) * (1 - t) + math.log(self.lr_final) * t)

    def apply(self, optimizer: torch.optim.Optimizer, step: int) -> float:
        """Set the `means` group's learning rate for `step`; returns it."""
        lr = self(step)
        for group in optimizer.param_groups:
            if group["name"] == "means":
                group["lr"] = lr
        return lr
