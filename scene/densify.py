"""Adaptive density control of 3DGS: clone small / split large Gaussians with large screen-space gradients,
prune transparent or oversized ones, and reset opacities periodically."""
from __future__ import annotations

from dataclasses import dataclass, field

import torch

from gaussian_renderer.projection import quat_to_rotmat
from scene.gaussian_model import GaussianModel
from scene.param_ops import append_params, prune_params, replace_param


@dataclass(frozen=True)
class DensifyConfig:
    """Densification schedule and thresholds (3DGS values, except the end point and the cap, sized for CPU runs)."""

    densify_from_iter: int = field(default=500, metadata={"help": "first densification iteration"})
    densify_until_iter: int = field(default=-1, metadata={"help": "last densification iteration (-1: half of --iterations)"})
    densification_interval: int = field(default=100, metadata={"help": "iterations between densifications"})
    opacity_reset_interval: int = field(default=3000, metadata={"help": "iterations between opacity resets"})
    densify_grad_threshold: float = field(default=2e-4, metadata={"help": "mean NDC gradient above which to densify"})
    percent_dense: float = field(default=0.01, metadata={"help": "clone/split boundary, fraction of scene extent"})
    min_opacity: float = field(default=0.005, metadata={"help": "prune Gaussians below this opacity"})
    max_screen_size: int = field(default=20, metadata={"help": "prune Gaussians wider than this (px) after a reset"})
    max_gaussians: int = field(default=50_000, metadata={"help": "no growth beyond this count (bounds CPU time per iteration)"})


class DensifyStrategy:
    """Accumulates screen-space gradient statistics and edits the model at the configured intervals."""

    def __init__(self, cfg: DensifyConfig, total_iterations: int):
        self.cfg = cfg
        self.until = cfg.densify_until_iter if cfg.densify_until_iter >= 0 else total_iterations // 2
        self.grad_accum = torch.zeros(0)
        self.denom = torch.zeros(0)
        self.max_radii = torch.zeros(0)

    def _ensure_size(self, n: int, device: torch.device) -> None:
        if self.grad_accum.shape[0] != n:
            self.grad_accum = torch.zeros(n, device=device)
            self.denom = torch.zeros(n, device=device)
            self.max_radii = torch.zeros(n, device=device)

    @torch.no_grad()
    def step_post_backward(self, gaussians: GaussianModel, optimizer: torch.optim.Optimizer, means2d: torch.Tensor,
                           radii: torch.Tensor, visible: torch.Tensor, width: int, height: int, iteration: int,
                           scene_extent: float) -> None:
        """Call after `loss.backward()` and before `optimizer.step()`; `means2d.grad` is in pixels [N, 2]."""
        cfg = self.cfg
        if iteration >= self.until:
            return
        n = gaussians.num_gaussians
        self._ensure_size(n, gaussians.device)
        if means2d.grad is not None:
            # d loss / d ndc = d loss / d pixel * (W / 2, H / 2): the 3DGS threshold is in NDC units.
            scale = torch.tensor([width / 2.0, height / 2.0], device=means2d.device, dtype=means2d.dtype)
            grad_norm = (means2d.grad * scale).norm(dim=-1).to(self.grad_accum.dtype)
            self.grad_accum[visible] += grad_norm[visible]
            self.denom[visible] += 1
        self.max_radii[visible] = torch.maximum(self.max_radii[visible], radii[visible].to(self.max_radii.dtype))
        if iteration > cfg.densify_from_iter and iteration % cfg.densification_interval == 0:
            size_threshold = cfg.max_screen_size if iteration > cfg.opacity_reset_interval else None
            self.densify_and_prune(gaussians, optimizer, scene_extent, size_threshold)
        if iteration % cfg.opacity_reset_interval == 0:
            reset = torch.minimum(gaussians.opacities, torch.full_like(gaussians.opacities, 0.01))
            replace_param(gaussians, optimizer, "logit_opacities", torch.logit(reset))

    @torch.no_grad()
    def densify_and_prune(self, gaussians: GaussianModel, optimizer: torch.optim.Optimizer, scene_extent: float,
                          size_threshold: int | None) -> None:
        cfg = self.cfg
        grads = self.grad_accum / self.denom.clamp_min(1)
        big_grad = grads >= cfg.densify_grad_threshold
        max_scale = gaussians.scales.max(dim=1).values
        clone = big_grad & (max_scale <= cfg.percent_dense * scene_extent)
        split = big_grad & (max_scale > cfg.percent_dense * scene_extent)
        n = gaussians.num_gaussians
        grow = int(clone.sum()) + int(split.sum())  # each split adds one net Gaussian (2 new, 1 removed)
        if n + grow <= cfg.max_gaussians and grow > 0:
            params = {k: v.detach() for k, v in gaussians.params.items()}
            cloned = {k: v[clone] for k, v in params.items()}
            stds = gaussians.scales[split].repeat(2, 1)
            samples = torch.normal(torch.zeros_like(stds), stds)
            rots = quat_to_rotmat(params["quats"][split]).repeat(2, 1, 1)
            split_new = {k: v[split].repeat(2, *([1] * (v.dim() - 1))) for k, v in params.items()}
            split_new["means"] = (rots @ samples[..., None])[..., 0] + split_new["means"]
            split_new["log_scales"] = torch.log(stds / (0.8 * 2))
            append_params(gaussians, optimizer, {k: torch.cat([cloned[k], split_new[k]]) for k in params})
            removed = torch.cat([split, torch.zeros(gaussians.num_gaussians - n, dtype=torch.bool,
                                                    device=split.device)])
        else:
            removed = torch.zeros(n, dtype=torch.bool, device=gaussians.device)
        n_now = gaussians.num_gaussians
        prune = removed | (gaussians.opacities < cfg.min_opacity)
        if size_threshold is not None:
            radii = torch.cat([self.max_radii, torch.zeros(n_now - n, device=self.max_radii.device)])
            prune |= (radii > size_threshold) | (gaussians.scales.max(dim=1).values > 0.1 * scene_extent)
        if bool(prune.all()):
            prune[torch.argmax(gaussians.opacities)] = False  # never prune the model away entirely
        prune_params(gaussians, optimizer, ~prune)
        self._ensure_size(0, gaussians.device)
        self._ensure_size(gaussians.num_gaussians, gaussians.device)

    def state_dict(self) -> dict:
        return {"grad_accum": self.grad_accum, "denom": self.denom, "max_radii": self.max_radii, "until": self.until}

    def load_state_dict(self, state: dict) -> None:
        self.grad_accum, self.denom, self.max_radii = state["grad_accum"], state["denom"], state["max_radii"]
        self.until = state["until"]
