"""Adaptive density control of 3DGS: clone small / split large Gaussians with large screen-space gradients,
prune transparent or oversized ones, and reset opacities periodically."""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import torch

from gaussian_renderer.projection import quat_to_rotmat
from scene.gaussian_model import GaussianModel
from training.param_ops import append_params, prune_params, replace_param
from utils.errors import UserError

logger = logging.getLogger(__name__)

STATE_FORMAT_VERSION = 1
SPLIT_SAMPLES = 2  # 3DGS draws N = 2 children per split Gaussian
SPLIT_SHRINK = 0.8  # children get scale / (0.8 N)
RESET_OPACITY = 0.01  # opacity reset caps every opacity at this value
MAX_WORLD_SIZE = 0.1  # after the first reset, prune Gaussians larger than this fraction of the scene extent


@dataclass(frozen=True)
class DensifyConfig:
    """Densification schedule and thresholds (3DGS values, except the end point and the cap, sized for CPU runs)."""

    densify_from_iter: int = field(default=500, metadata={"help": "first densification iteration"})
    densify_until_iter: int = field(default=-1, metadata={
        "help": "last densification iteration (-1: half of --iterations, as 3DGS's 15000 of 30000)"})
    densification_interval: int = field(default=100, metadata={"help": "iterations between densifications"})
    opacity_reset_interval: int = field(default=3000, metadata={"help": "iterations between opacity resets"})
    densify_grad_threshold: float = field(default=2e-4, metadata={"help": "mean NDC gradient above which to densify"})
    percent_dense: float = field(default=0.01, metadata={"help": "clone/split boundary, fraction of scene extent"})
    min_opacity: float = field(default=0.005, metadata={"help": "prune Gaussians below this opacity"})
    max_screen_size: int = field(default=20, metadata={"help": "prune Gaussians wider than this (px) after a reset"})
    max_gaussians: int = field(default=50_000, metadata={
        "help": "no growth beyond this count (bounds CPU time per iteration and Fisher memory)"})


class DensifyStrategy:
    """Accumulates screen-space gradient statistics and edits the model at the configured intervals.

    Follows graphdeco 3DGS: while `iteration < until`, every call adds the NDC-space norm of each visible Gaussian's
    2D mean gradient and tracks its largest screen radius; every `densification_interval` iterations after
    `densify_from_iter` Gaussians whose average gradient reaches the threshold are cloned (max scale <=
    percent_dense * extent) or split in two, then low-opacity ones (and, after the first opacity reset, ones
    over `max_screen_size` px or 0.1 * extent wide) are pruned; every `opacity_reset_interval` iterations
    opacities are capped at 0.01. Growth stops at `max_gaussians`: when the candidates exceed the room left,
    those with the largest average gradient go first. The accumulators always have one row per Gaussian and are
    zeroed after each densification.
    """

    def __init__(self, cfg: DensifyConfig, total_iterations: int):
        self.cfg = cfg
        self.until = cfg.densify_until_iter if cfg.densify_until_iter >= 0 else total_iterations // 2
        self.grad_accum = torch.zeros(0)  # [N] summed NDC gradient norms
        self.denom = torch.zeros(0)  # [N] iterations in which each Gaussian was visible
        self.max_radii = torch.zeros(0)  # [N] largest screen radius (px) seen

    def _ensure_size(self, n: int, device: torch.device) -> None:
        """Zero accumulators of length `n` unless they already have it (surgery elsewhere resets them)."""
        if self.grad_accum.shape[0] == n and self.grad_accum.device != device:  # e.g. restored from a CPU checkpoint
            self.grad_accum, self.denom, self.max_radii = (t.to(device) for t in
                                                           (self.grad_accum, self.denom, self.max_radii))
        if self.grad_accum.shape[0] != n:
            self.grad_accum = torch.zeros(n, device=device)
            self.denom = torch.zeros(n, device=device)
            self.max_radii = torch.zeros(n, device=device)

    @torch.no_grad()
    def step_post_backward(self, gaussians: GaussianModel, optimizer: torch.optim.Optimizer, means2d: torch.Tensor,
                           radii: torch.Tensor, visible: torch.Tensor, width: int, height: int, iteration: int,
                           scene_extent: float) -> None:
        """Accumulate statistics and densify/prune/reset when due; call after `backward()`, before `step()`.

        Args:
            means2d: projected centres whose `.grad` is d loss / d pixel position. [N, 2]
            radii: screen radii in pixels (0 = culled). [N]
            visible: Gaussians rendered in this view. [N] bool
            width, height: image size in pixels.
            iteration: 1-based training iteration.
            scene_extent: scene radius in world units.
        """
        cfg = self.cfg
        if iteration >= self.until:
            return
        n = gaussians.num_gaussians
        assert means2d.shape == (n, 2) and radii.shape == (n,) and visible.shape == (n,), \
            f"means2d {tuple(means2d.shape)}, radii {tuple(radii.shape)}, visible {tuple(visible.shape)} vs N={n}"
        self._ensure_size(n, gaussians.device)
        if means2d.grad is not None:
            # ndc = 2 px / W - 1 (per axis), so d loss / d ndc = d loss / d px * (W / 2, H / 2): the 3DGS threshold
            # is in NDC units.
            scale = torch.tensor([width / 2.0, height / 2.0], device=means2d.device, dtype=means2d.dtype)
            grad_norm = (means2d.grad * scale).norm(dim=-1).to(self.grad_accum.dtype)  # [N]
            # torch.where instead of boolean indexing: the same values without a host sync per iteration on a GPU
            self.grad_accum += torch.where(visible, grad_norm, torch.zeros_like(grad_norm))
            self.denom += visible.to(self.denom.dtype)
        self.max_radii = torch.where(visible, torch.maximum(self.max_radii, radii.to(self.max_radii.dtype)),
                                     self.max_radii)
        if iteration > cfg.densify_from_iter and iteration % cfg.densification_interval == 0:
            size_threshold = cfg.max_screen_size if iteration > cfg.opacity_reset_interval else None
            self.densify_and_prune(gaussians, optimizer, scene_extent, size_threshold)
        if iteration % cfg.opacity_reset_interval == 0:
            self.reset_opacities(gaussians, optimizer)

    @torch.no_grad()
    def reset_opacities(self, gaussians: GaussianModel, optimizer: torch.optim.Optimizer) -> None:
        """Cap every opacity at 0.01 (done on logits, so no round trip through sigmoid) and zero its Adam state."""
        cap = math.log(RESET_OPACITY / (1 - RESET_OPACITY))  # logit(0.01)
        logits = gaussians.params["logit_opacities"].detach()  # [N]
        replace_param(gaussians, optimizer, "logit_opacities", logits.clamp_max(cap))

    @torch.no_grad()
    def densify_and_prune(self, gaussians: GaussianModel, optimizer: torch.optim.Optimizer, scene_extent: float,
                          size_threshold: int | None) -> None:
        """Clone/split by the average NDC gradient, then prune; `size_threshold` (px) None skips screen-size pruning."""
        cfg = self.cfg
        n = gaussians.num_gaussians
        grads = self.grad_accum / self.denom.clamp_min(1)  # [N] average NDC gradient norm
        candidates = grads >= cfg.densify_grad_threshold  # [N]
        room = max(cfg.max_gaussians - n, 0)  # clone and split each add one net Gaussian
        if int(candidates.sum()) > room:
            logger.info("densify: %d candidates, room for %d under max_gaussians=%d", int(candidates.sum()), room,
                        cfg.max_gaussians)
            top = torch.where(candidates, grads, torch.full_like(grads, -math.inf)).topk(room).indices
            candidates = torch.zeros_like(candidates)
            candidates[top] = True
        max_scale = gaussians.scales.max(dim=1).values  # [N]
        clone = candidates & (max_scale <= cfg.percent_dense * scene_extent)
        split = candidates & (max_scale > cfg.percent_dense * scene_extent)
        if bool(candidates.any()):
            params = {k: v.detach() for k, v in gaussians.params.items()}
            cloned = {k: v[clone] for k, v in params.items()}
            stds = gaussians.scales.detach()[split].repeat(SPLIT_SAMPLES, 1)  # [S*2, 3]
            samples = torch.normal(torch.zeros_like(stds), stds)  # local frame offsets
            rots = quat_to_rotmat(params["quats"][split]).repeat(SPLIT_SAMPLES, 1, 1)  # [S*2, 3, 3]
            children = {k: v[split].repeat(SPLIT_SAMPLES, *([1] * (v.dim() - 1))) for k, v in params.items()}
            children["means"] = (rots @ samples[..., None])[..., 0] + children["means"]
            children["log_scales"] = torch.log(stds / (SPLIT_SHRINK * SPLIT_SAMPLES))
            append_params(gaussians, optimizer, {k: torch.cat([cloned[k], children[k]]) for k in params})
        n_now = gaussians.num_gaussians
        added = torch.zeros(n_now - n, dtype=torch.bool, device=split.device)
        prune = torch.cat([split, added]) | (gaussians.opacities < cfg.min_opacity)  # split parents go
        if size_threshold is not None:
            radii = torch.cat([self.max_radii, torch.zeros(n_now - n, device=self.max_radii.device)])
            prune |= (radii > size_threshold) | (gaussians.scales.max(dim=1).values > MAX_WORLD_SIZE * scene_extent)
        if bool(prune.all()):
            prune[torch.argmax(gaussians.opacities)] = False  # never prune the model away entirely
        prune_params(gaussians, optimizer, ~prune)
        logger.debug("densify: cloned %d, split %d, pruned %d -> %d Gaussians", int(clone.sum()), int(split.sum()),
                     int(prune.sum()) - int(split.sum()), gaussians.num_gaussians)
        self._ensure_size(0, gaussians.device)
        self._ensure_size(gaussians.num_gaussians, gaussians.device)

    def state_dict(self) -> dict:
        """Named, versioned accumulators for checkpoints."""
        return {"format_version": STATE_FORMAT_VERSION, "grad_accum": self.grad_accum, "denom": self.denom,
                "max_radii": self.max_radii, "until": self.until}

    def load_state_dict(self, state: dict) -> None:
        """Restore `state_dict()` output."""
        if state.get("format_version") != STATE_FORMAT_VERSION:
            raise UserError(f"checkpoint holds densification state version {state.get('format_version')}, this code "
                            f"reads version {STATE_FORMAT_VERSION}; resume with the code that wrote it or retrain")
        self.grad_accum, self.denom, self.max_radii = state["grad_accum"], state["denom"], state["max_radii"]
        self.until = state["until"]
