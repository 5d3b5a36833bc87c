"""The views a run starts from and one acquisition step's selection (the stage record of selection.json)."""
from __future__ import annotations

import time
from typing import Any

import torch

from active import Selector, SelectionContext
from active.fisher import build_oracle
from active.schedule import farthest_point_views
from gaussian_renderer import RasterSettings
from gaussian_renderer.projection import camera_centers, look_at_point
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


def select_views(state: TrainState, scene: Scene, cfg: TrainConfig, selector: Selector, k: int,
                 background: torch.Tensor, settings: RasterSettings) -> dict[str, Any]:
    """Run the selector for one acquisition step; returns the stage record for selection.json."""
    a = cfg.active
    candidates = [v for v in range(len(scene.train_cameras)) if v not in state.train_views]
    t0 = time.perf_counter()
    oracle = None
    if selector.uses_oracle:
        oracle = build_oracle(selector.oracle_kind, state.gaussians, scene.train_cameras, state.train_views,
                              background, settings, sigma=a.sigma, delta_rel=a.delta_rel, delta_abs=a.delta_abs,
                              param_groups=a.fisher_params, mode=a.fisher_mode, cache_mb=a.fisher_cache_mb)
    generator = torch.Generator().manual_seed(cfg.run.seed * 100_003 + state.stage)
    viewmats = torch.stack([c.viewmat.cpu() for c in scene.train_cameras])  # [V, 4, 4]
    selection = selector.select(SelectionContext(candidate_ids=candidates, oracle=oracle, generator=generator,
                                                 stage=state.stage, train_ids=tuple(state.train_views),
                                                 camera_centers=camera_centers(viewmats),
                                                 scene_center=look_at_point(viewmats)), k)
    select_seconds = time.perf_counter() - t0
    return {
        "stage": state.stage,
        "iteration": state.iteration,
        "train_views": list(state.train_views),
        "candidates": len(candidates),
        "selected": [int(v) for v in selection.ids],
        "gains": [float(g) for g in selection.gains],
        "oracle_calls": {"conservative": selection.conservative, "evaluated": oracle.evaluated if oracle else 0},
        "fisher_views_computed": oracle.views_computed if oracle else 0,
        "fisher_seconds": oracle.fisher_seconds if oracle else 0.0,
        "select_seconds": select_seconds,
        "test_psnr": test_psnr(state.gaussians, scene.test_cameras, background, settings),
    }
