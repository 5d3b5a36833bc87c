"""The views a run starts from, one acquisition step's selection (the stage record of selection.json) and the memory
check of its Fisher pass."""
from __future__ import annotations

from dataclasses import replace
from typing import Any

import torch

from active import Selector, acquisition
from active.memory_budget import (NO_FISHER_PASS, FisherWork, block_size, device_available_bytes, fit_fisher_memory,
                                  largest_count, largest_pixels, pass_label, selection_work, smaller_passes,
                                  usable_bytes)
from active.schedule import farthest_point_views, first_seed_index
from arguments import FisherSettings
from gaussian_renderer import RasterSettings
from gaussian_renderer.fisher_partials import RAW_PARAMETER_GROUPS
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from scene.scene import Scene
from training.config import TrainConfig
from training.state import TrainState
from training.step import mean_psnr
from utils.errors import UserError


def check_view_ids(ids: tuple[int, ...], pool: int, flag: str) -> None:
    """One error line unless `ids` (the values of train.py's `flag`) are distinct view ids in [0, pool)."""
    if any(not 0 <= v < pool for v in ids) or len(set(ids)) != len(ids):
        raise UserError(f"{flag} must be distinct view ids in [0, {pool}); got {list(ids)}")


def allowed_views(cfg: TrainConfig, pool: int) -> list[int]:
    """The training view ids a run may seed or pick: all but --exclude_views (checked: distinct ids in the pool)."""
    check_view_ids(cfg.active.exclude_views, pool, "--exclude_views")
    excluded = set(cfg.active.exclude_views)
    return [v for v in range(pool) if v not in excluded]


def seed_views(scene: Scene, cfg: TrainConfig) -> list[int]:
    """Seed views: --init_views, or farthest-point sampling of the allowed views' camera centres from the first
    (--seed_start first) or from one drawn with --seed (--seed_start random; its own generator, so the run's other
    random streams are untouched)."""
    pool = len(scene.train_cameras)
    a = cfg.active
    allowed = allowed_views(cfg, pool)
    if a.init_views:
        check_view_ids(a.init_views, pool, "--init_views")
        if excluded := sorted(set(a.init_views) & set(a.exclude_views)):
            raise UserError(f"--init_views {excluded} are also in --exclude_views; "
                            "seed from views that can be captured")
        return list(a.init_views)
    centers = torch.stack([scene.train_cameras[v].camera_center.cpu() for v in allowed])
    start = first_seed_index(a.seed_start, cfg.run.seed, len(allowed))
    return [allowed[i] for i in farthest_point_views(centers, a.num_init_views, start)]


def candidate_views(state: TrainState, scene: Scene, cfg: TrainConfig) -> list[int]:
    """The views the next acquisition may pick: the allowed training views not trained on yet."""
    return [v for v in allowed_views(cfg, len(scene.train_cameras)) if v not in state.train_views]


def acquire_views(state: TrainState, scene: Scene, cfg: TrainConfig, selector: Selector, k: int,
                  background: torch.Tensor, settings: RasterSettings) -> dict[str, Any]:
    """The training run's acquisition step: `active.acquisition.run_selection` over the training cameras neither
    trained on yet nor excluded (seeded by --seed and the stage) by the selector `selector.for_step` chooses for this
    step (itself, but for `auto`), its Fisher pass checked against the available memory first
    (`fit_selection_memory`); returns the stage record for selection.json (with the rule line of a selector that has
    one)."""
    candidates = candidate_views(state, scene, cfg)
    choice = selector.for_step(len(state.train_views), model_iterations(state, cfg))
    used = choice.selector
    fisher = fit_selection_memory(cfg, used, state.gaussians, scene.train_cameras, len(candidates))
    step = acquisition.run_selection(used, state.gaussians, scene.train_cameras, state.train_views, candidates, k,
                                     background, settings, seed=cfg.run.seed, stage=state.stage, fisher=fisher)
    selection = step.selection
    return {
        "stage": state.stage,
        "iteration": state.iteration,
        **({"selector_used": used.name, "rule": choice.rule} if choice.rule is not None else {}),
        "train_views": list(state.train_views),
        "candidates": len(candidates),
        "selected": [int(v) for v in selection.ids],
        "gains": [float(g) for g in selection.gains],
        **({"note": selection.note} if selection.note is not None else {}),
        "oracle_calls": {"conservative": selection.conservative, "evaluated": step.evaluated},
        "fisher_views_computed": step.fisher_views_computed,
        "fisher_seconds": step.fisher_seconds,
        "select_seconds": step.seconds,
        "train_psnr": mean_psnr(state.gaussians, [scene.train_cameras[v] for v in state.train_views], background,
                                settings),  # how well the model fits its captured views when it chooses
        "test_psnr": mean_psnr(state.gaussians, scene.test_cameras, background, settings),
    }


def model_iterations(state: TrainState, cfg: TrainConfig) -> int:
    """How long the current model has trained: since the last acquisition with --stage_reset (which starts the model
    afresh there), else since the run started."""
    if cfg.active.stage_reset and state.stages:
        return state.iteration - state.stages[-1]["iteration"]
    return state.iteration


TRAINING_BYTES_PER_FLOAT = 16  # a float32 parameter, its gradient and Adam's two moments
DENSIFY_BYTES_PER_GAUSSIAN = 12  # the densification accumulators: gradient sum, visible count, largest radius


def fit_selection_memory(cfg: TrainConfig, selector: Selector, gaussians: GaussianModel, cameras: list[Camera],
                         num_candidates: int) -> FisherSettings:
    """The run's Fisher settings for an acquisition step over `num_candidates` of `cameras`, checked against the
    available memory (`active.memory_budget.fit_fisher_memory`: the cache lowered, or one `UserError` line naming
    the estimate and train.py's flags that help)."""
    return _fit_memory(cfg, selector, gaussians, cameras, num_candidates,
                       FisherSettings.from_active(cfg.active), gaussians.num_gaussians)


def check_memory_before_training(cfg: TrainConfig, selector: Selector, gaussians: GaussianModel,
                                 cameras: list[Camera], num_candidates: int) -> None:
    """`fit_selection_memory` at the largest model the run can grow to (its size or --max_gaussians), the growth
    in training counted, without the cache (each acquisition fits the cache to the memory it finds then)."""
    fisher = replace(FisherSettings.from_active(cfg.active), fisher_mode="streaming")
    _fit_memory(cfg, selector, gaussians, cameras, num_candidates, fisher,
                max(gaussians.num_gaussians, cfg.densify.max_gaussians))


def _fit_memory(cfg: TrainConfig, selector: Selector, gaussians: GaussianModel, cameras: list[Camera],
                num_candidates: int, fisher: FisherSettings, n_max: int) -> FisherSettings:
    """`fit_fisher_memory` of the selector's pass over `n_max` Gaussians (the growth from the model's size counted),
    with train.py's remedies: --fisher_params default, -r (half the width), --max_gaussians."""
    n_now = gaussians.num_gaussians
    per_gaussian = TRAINING_BYTES_PER_FLOAT * block_size(gaussians, RAW_PARAMETER_GROUPS) + DENSIFY_BYTES_PER_GAUSSIAN

    def work_at(n: int) -> FisherWork | None:
        return selection_work(selector.oracle_kind, gaussians, largest_pixels(cameras), num_candidates,
                              cfg.active.fisher_params, num_gaussians=n, model_bytes=max(n - n_now, 0) * per_gaussian)

    work = work_at(n_max) if selector.uses_oracle else None
    if work is None:
        return fisher
    available = device_available_bytes(gaussians.device)
    remedies = smaller_passes(work, gaussians, max(c.width for c in cameras), "-r")
    fitting = largest_count(work_at, n_max, usable_bytes(available))
    if n_now <= fitting < n_max:
        remedies[f"--max_gaussians {fitting}"] = work_at(fitting)
    what = pass_label(f"{selector.name} Fisher pass", work, cfg.active.fisher_params, up_to=n_max > n_now)
    return fit_fisher_memory(work, fisher, what, remedies, f"{NO_FISHER_PASS}, or fewer Gaussians", available)
