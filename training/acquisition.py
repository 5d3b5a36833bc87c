"""The views a run starts from and one acquisition step's selection (the stage record of selection.json)."""
from __future__ import annotations

from typing import Any

import torch

from active import Selector, acquisition
from active.schedule import farthest_point_views
from arguments import FisherSettings
from gaussian_renderer import RasterSettings
from scene.scene import Scene
from training.config import TrainConfig
from training.state import TrainState
from training.step import test_psnr
from utils.errors import UserError


def seed_views(scene: Scene, cfg: TrainConfig) -> list[int]:
    """Seed views: --init_views, or farthest-point sampling of camera centres from view 0."""
    pool = len(scene.train_cameras)
    a = cfg.active
    if a.init_views:
        bad = [v for v in a.init_views if not 0 <= v < pool]
        if bad or len(set(a.init_views)) != len(a.init_views):
            raise UserError(f"--init_views must be distinct view ids in [0, {pool}); got {list(a.init_views)}")
        return list(a.init_views)
    centers = torch.stack([c.camera_center.cpu() for c in scene.train_cameras])
    return farthest_point_views(centers, a.num_init_views)


def acquire_views(state: TrainState, scene: Scene, cfg: TrainConfig, selector: Selector, k: int,
                  background: torch.Tensor, settings: RasterSettings) -> dict[str, Any]:
    """The training run's acquisition step: `active.acquisition.run_selection` over the training cameras not trained
    on yet (seeded by --seed and the stage); returns the stage record for selection.json."""
    candidates = [v for v in range(len(scene.train_cameras)) if v not in state.train_views]
    step = acquisition.run_selection(selector, state.gaussians, scene.train_cameras, state.train_views, candidates, k,
                                     background, settings, seed=cfg.run.seed, stage=state.stage,
                                     fisher=FisherSettings.from_active(cfg.active))
    selection = step.selection
    return {
        "stage": state.stage,
        "iteration": state.iteration,
        "train_views": list(state.train_views),
        "candidates": len(candidates),
        "selected": [int(v) for v in selection.ids],
        "gains": [float(g) for g in selection.gains],
        "oracle_calls": {"conservative": selection.conservative, "evaluated": step.evaluated},
        "fisher_views_computed": step.fisher_views_computed,
        "fisher_seconds": step.fisher_seconds,
        "select_seconds": step.seconds,
        "test_psnr": test_psnr(state.gaussians, scene.test_cameras, background, settings),
    }
