"""A run's changing state (model, optimiser, densification, views, stages), its creation and its checkpoint form."""
from __future__ import annotations

import random
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from scene.gaussian_model import GaussianModel
from scene.scene import Scene
from training.config import TrainConfig
from training.densify import DensifyStrategy
from training.optim import create_optimizer
from utils.errors import UserError
from utils.seeding import rng_state


@dataclass
class TrainState:
    """Everything that changes during a run and is restored on resume."""

    gaussians: GaussianModel
    optimizer: torch.optim.Optimizer
    strategy: DensifyStrategy
    iteration: int = 0
    stage: int = 0
    train_views: list[int] = field(default_factory=list)
    stages: list[dict[str, Any]] = field(default_factory=list)
    view_stack: list[int] = field(default_factory=list)


def fresh_state(scene: Scene, cfg: TrainConfig, train_views: list[int], total_iterations: int) -> TrainState:
    """A new model from the scene's initial point cloud (seeded by --seed) or from --init_ply, its optimiser and
    densification."""
    if cfg.model.init_ply:
        gaussians = initial_gaussians_from_ply(cfg.model.init_ply, cfg.model.sh_degree, cfg.model.device)
    else:
        pcd = scene.initial_point_cloud(cfg.model.num_random_points, cfg.run.seed)
        gaussians = scene.new_gaussians(pcd, cfg.model.sh_degree, cfg.model.device)
    optimizer = create_optimizer(gaussians, cfg.optim, scene.extent)
    return TrainState(gaussians, optimizer, DensifyStrategy(cfg.densify, total_iterations), train_views=list(train_views))


def initial_gaussians_from_ply(path: str, sh_degree: int, device: str) -> GaussianModel:
    """The Gaussians of a 3DGS PLY as a run's starting model, every SH band it holds active (as 3DGS loads a PLY)."""
    if not Path(path).is_file():
        raise UserError(f"--init_ply {path} does not exist; pass a 3DGS point_cloud.ply (e.g. "
                        "MODEL/point_cloud/iteration_N/point_cloud.ply)")
    gaussians = GaussianModel.load_ply(path, device=device)
    if gaussians.max_sh_degree != sh_degree:
        raise UserError(f"--init_ply {path} holds SH degree {gaussians.max_sh_degree}, but --sh_degree is {sh_degree}; "
                        f"pass --sh_degree {gaussians.max_sh_degree}")
    return gaussians


def capture_state(state: TrainState, rng: random.Random, cfg: TrainConfig) -> dict[str, Any]:
    """The checkpoint: a named dict with a format version (see utils/checkpoint.py)."""
    return {
        "iteration": state.iteration, "stage": state.stage, "train_views": state.train_views,
        "stages": state.stages, "view_stack": state.view_stack,
        "model": state.gaussians.state_dict(), "optimizer": state.optimizer.state_dict(),
        "densify": state.strategy.state_dict(), "rng": rng_state(), "train_rng": rng.getstate(),
        "config": cfg.to_dict(),
    }


def restore_state(state: TrainState, ckpt: dict[str, Any], cfg: TrainConfig, scene: Scene) -> None:
    """Load a checkpoint made by `capture_state` into `state` (the caller restores the random generators)."""
    state.gaussians.load_state_dict(ckpt["model"])
    state.optimizer = create_optimizer(state.gaussians, cfg.optim, scene.extent)
    state.optimizer.load_state_dict(ckpt["optimizer"])
    state.strategy.load_state_dict(ckpt["densify"])
    state.iteration, state.stage = ckpt["iteration"], ckpt["stage"]
    state.train_views, state.stages, state.view_stack = ckpt["train_views"], ckpt["stages"], ckpt["view_stack"]
