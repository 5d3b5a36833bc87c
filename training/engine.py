"""The training engine behind train.py: open (or resume) a run, train each stage, acquire views after it, finish.

    run = open_run(cfg, model_path)     # the scene, the stage plan, the state (resumed from the newest checkpoint)
    train_stage(run, progress)           # train until the stage ends (test reports, PLY saves, checkpoints)
    acquire(run, progress)               # select the next views, write selection.json and the stage checkpoint
    finish(run)                          # final test PSNR, run_status.json "complete"

`training(cfg)` does all of it; benchmarks drive the steps themselves.
"""
from __future__ import annotations

import contextlib
import random
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import torch
from tqdm import tqdm

from active import Selector
from active.schedule import StagePlan, plan_stages
from arguments import config_to_dict
from gaussian_renderer import RasterSettings
from scene.resolution_policy import training_resolution
from scene.scene import Scene
from scene.trained import background_color, raster_settings
from training.acquisition import (acquire_views, allowed_views, candidate_views, check_memory_before_training,
                                  seed_views)
from training.config import TrainConfig, config_difference, default_model_path, make_selector, stage_selectors
from training.optim import PositionLRSchedule
from training.state import TrainState, capture_state, fresh_state, restore_state
from training.step import mean_psnr, next_view, training_step
from training.time_estimate import RunTimeEstimator
from utils import dir_lock
from utils.checkpoint import RunDirectory
from utils.errors import UserError
from utils.io import read_json, write_json
from utils.model_dir import CFG_ARGS, INPUT_PLY, SELECTION
from utils.provenance import session_record
from utils.seeding import seed_everything, set_rng_state

PROGRESS_EVERY_S = 30.0  # run_status.json gets the iteration and Gaussian count this often while training


def make_plan(cfg: TrainConfig, pool: int) -> StagePlan:
    """The stage plan; a --iterations shorter than the acquisition schedule is raised to it, with one note (the
    effective total is recorded in cfg_args as `total_iterations`)."""
    a = cfg.active
    if not a.method:
        return StagePlan((), (pool,), (cfg.run.iterations,), cfg.run.iterations)
    num_init = len(a.init_views) or a.num_init_views
    plan = plan_stages(num_init, a.views_per_step, a.max_views, pool, a.iters_per_view, cfg.run.iterations)
    if plan.total_iterations > cfg.run.iterations:
        stages = " + ".join(str(a.iters_per_view * v) for v in plan.views_in_stage[:-1])
        print(f"note: --iterations {cfg.run.iterations} is shorter than the acquisition schedule (stages of {stages} "
              f"= {plan.total_iterations} iterations); training {plan.total_iterations} iterations "
              "(recorded in cfg_args as total_iterations)")
    return plan


@dataclass
class Run:
    """An open run: the loaded scene, its plan, the rasterizer set-up and the training state."""

    cfg: TrainConfig
    run_dir: RunDirectory
    scene: Scene
    plan: StagePlan
    selector: Selector | None
    background: torch.Tensor  # [3]
    settings: RasterSettings
    state: TrainState
    rng: random.Random  # the view order of the training passes
    lr_schedule: PositionLRSchedule
    eta: RunTimeEstimator | None = None  # the one-line wall-time estimate after the first iterations
    progress_written: float = field(default_factory=time.monotonic)  # when run_status.json last got the progress
    sessions: list[dict[str, Any]] = field(default_factory=list)  # provenance of each start/resume (selection.json)
    lock: contextlib.ExitStack | None = None  # the model directory's writer lock (utils.dir_lock), until `close_run`
    stage_selectors: dict[int, Selector] = field(default_factory=dict)  # --stage_method: acquisition -> selector

    def selector_at(self, stage: int) -> Selector | None:
        """The selector of acquisition `stage`: --stage_method's for that stage, else --method's."""
        return self.stage_selectors.get(stage, self.selector)


def open_run(cfg: TrainConfig, model_path: str) -> Run:
    """Take `model_path`'s writer lock, load the scene and resume from the newest checkpoint of `model_path`, or
    start the run there. The lock is held until `close_run` (or the process ends)."""
    lock = dir_lock.hold(model_path, dir_lock.WAYS_OUT["train"])
    try:
        run = _open_run(cfg, model_path)
    except BaseException:
        lock.close()
        raise
    run.lock = lock
    return run


def close_run(run: Run) -> None:
    """Release the run's writer lock."""
    if run.lock is not None:
        run.lock.close()
        run.lock = None


def _open_run(cfg: TrainConfig, model_path: str) -> Run:
    run_dir = RunDirectory(model_path)
    if cfg.run.overwrite:
        run_dir.clear()
    resolution = training_resolution(cfg.model)  # the effective -r (CPU width cap, 3DGS rule), kept in cfg_args
    if resolution is not None:
        cfg = replace(cfg, model=replace(cfg.model, resolution=resolution.resolution))
        if resolution.notice:
            print(resolution.notice)
    scene = Scene.from_config(cfg.model, model_path)
    views = len(scene.train_cameras)
    plan = make_plan(cfg, len(allowed_views(cfg, views)) if cfg.active.method else views)
    seed_everything(cfg.run.seed)
    rng = random.Random(cfg.run.seed)
    checkpoint = run_dir.latest_checkpoint()
    if checkpoint is not None:
        check_resumed_with_own_flags(cfg, model_path)
        state = fresh_state(scene, cfg, [], plan.total_iterations)
        restore_state(state, checkpoint, cfg, scene)
        rng.setstate(checkpoint["train_rng"])
        set_rng_state(checkpoint["rng"])
        print(f"{model_path}: resuming from iteration {state.iteration} (stage {state.stage})")
    else:
        train_views = seed_views(scene, cfg) if cfg.active.method else list(range(len(scene.train_cameras)))
        state = fresh_state(scene, cfg, train_views, plan.total_iterations)
    selector = make_selector(cfg) if cfg.active.method else None
    by_stage = stage_selectors(cfg) if selector is not None else {}
    if by_stage and max(by_stage) >= len(plan.adds):
        raise UserError(f"--stage_method names acquisition {max(by_stage)}, but this run makes {len(plan.adds)} "
                        f"(0 to {len(plan.adds) - 1}; see --max_views and --views_per_step)")
    if selector is not None and state.stage < len(plan.adds):  # the next acquisition's Fisher pass at the largest
        # model the run can reach: refused before any work (and before a fresh run writes anything)
        check_memory_before_training(cfg, by_stage.get(state.stage, selector), state.gaussians,
                                     scene.train_cameras, len(candidate_views(state, scene, cfg)))
    if checkpoint is None:
        run_dir.start({**cfg.to_dict(), "total_iterations": plan.total_iterations, "dataset": scene.dataset_record()})
        scene.write_cameras_json()
        state.gaussians.save_ply(Path(model_path) / INPUT_PLY)
        if plan.adds and plan.adds[-1] != cfg.active.views_per_step:
            print(f"note: K={cfg.active.views_per_step} does not divide the remaining budget; "
                  f"the last step adds {plan.adds[-1]} view(s)")
    sessions = previous_sessions(run_dir.path / SELECTION) if checkpoint is not None else []
    sessions.append(session_record(iteration=state.iteration, device=cfg.model.device))
    return Run(cfg, run_dir, scene, plan, selector, background_color(cfg.model), raster_settings(cfg.pipeline), state,
               rng, PositionLRSchedule.from_config(cfg.optim, scene.extent), sessions=sessions,
               stage_selectors=by_stage)


def check_resumed_with_own_flags(cfg: TrainConfig, model_path: str) -> None:
    """One `error:` line if an interrupted run is resumed with flags other than those it started with (cfg_args), so
    that no run trains its stages, or picks its views, under two configurations."""
    saved = read_json(Path(model_path) / CFG_ARGS, missing="none", damaged="none")
    difference = config_difference(saved, cfg.to_dict(), cfg.active.method) if saved else None
    if difference:
        name, old, new = difference
        raise UserError(f"{model_path} was started with --{name} {old}, this call has {new}: rerun it with the flags "
                        "it started with to resume it (its cfg_args), or pass --overwrite to start it again")


def previous_sessions(selection_path: Path) -> list[dict[str, Any]]:
    """The sessions an earlier start of this run recorded in selection.json ([] when there is none to read)."""
    sessions = (read_json(selection_path, missing="none", damaged="none") or {}).get("sessions", [])
    return [s for s in sessions if isinstance(s, dict)] if isinstance(sessions, list) else []


def train_stage(run: Run, progress: tqdm) -> None:
    """Train until the current stage ends, with the periodic test reports, PLY saves and extra checkpoints."""
    state, run_cfg = run.state, run.cfg.run
    save_its = set(run_cfg.save_iterations) | {run.plan.total_iterations}
    while state.iteration < run.plan.stage_end[state.stage]:
        cam = run.scene.train_cameras[next_view(state, run.rng)]
        loss, train_psnr = training_step(state, cam, run.cfg, run.background, run.settings, run.lr_schedule,
                                         run.scene.extent)
        progress.update(1)
        if run.eta is not None and (note := run.eta.after_iteration(state.iteration)) is not None:
            progress.write(note)
        if time.monotonic() - run.progress_written >= PROGRESS_EVERY_S:
            run.run_dir.progress(state.iteration, run.plan.total_iterations, state.gaussians.num_gaussians)
            run.progress_written = time.monotonic()
        if state.iteration % 10 == 0:
            progress.set_postfix(loss=f"{loss.item():.4f}", psnr=f"{train_psnr.item():.2f}",
                                 gaussians=state.gaussians.num_gaussians, views=len(state.train_views))
        if state.iteration in run_cfg.test_iterations:
            value = mean_psnr(state.gaussians, run.scene.test_cameras, run.background, run.settings)
            progress.write(f"[iter {state.iteration}] test PSNR {value:.2f} dB" if value is not None
                           else f"[iter {state.iteration}] no test views (use --eval)")
        if state.iteration in save_its:
            run.scene.save_gaussians(state.gaussians, state.iteration)
        if state.iteration in run_cfg.checkpoint_iterations:
            run.run_dir.save_checkpoint(capture_state(state, run.rng, run.cfg), keep=run_cfg.keep_checkpoints)


def acquire(run: Run, progress: tqdm) -> None:
    """One acquisition step: select the next views, add them, optionally reset the model, write selection.json and
    the stage checkpoint."""
    state, cfg = run.state, run.cfg
    k = run.plan.adds[state.stage]
    candidates = len(candidate_views(state, run.scene, cfg))
    selector, overridden = run.selector_at(state.stage), state.stage in run.stage_selectors
    progress.write(f"[stage {state.stage}] selecting {k} of {candidates} candidates with {selector.name}"
                   + (f" (--stage_method; the run's --method is {cfg.active.method})" if overridden else ""))
    record = acquire_views(state, run.scene, cfg, selector, k, run.background, run.settings)
    if overridden:
        record = {**record, "stage_method": selector.name}
    for line in (record.get("rule"), record.get("note")):
        if line is not None:
            progress.write(f"[stage {state.stage}] {line}")
    state.stages.append(record)
    state.train_views = state.train_views + record["selected"]
    state.view_stack = []
    state.stage += 1
    if cfg.active.stage_reset:
        reset = fresh_state(run.scene, cfg, state.train_views, run.plan.total_iterations)
        state.gaussians, state.optimizer, state.strategy = reset.gaussians, reset.optimizer, reset.strategy
    write_selection(run)
    run.run_dir.save_checkpoint(capture_state(state, run.rng, cfg), keep=cfg.run.keep_checkpoints)


def finish(run: Run) -> None:
    """Final test PSNR, the final selection record and run_status.json "complete"."""
    state = run.state
    final_psnr = mean_psnr(state.gaussians, run.scene.test_cameras, run.background, run.settings)
    if run.selector is not None:
        write_selection(run, final={"iteration": state.iteration, "train_views": state.train_views,
                                    "test_psnr": final_psnr})
    run.run_dir.finish({"iteration": state.iteration, "num_gaussians": state.gaussians.num_gaussians,
                        "train_views": state.train_views, "test_psnr": final_psnr})
    msg = f"test PSNR {final_psnr:.2f} dB" if final_psnr is not None else "no test views (pass --eval for a test split)"
    print(f"{run.run_dir.path}: trained {state.iteration} iterations on {len(state.train_views)} views, "
          f"{state.gaussians.num_gaussians} Gaussians, {msg}")


def training(cfg: TrainConfig) -> Path:
    """Run (or resume) one training run: open it, then train each stage and acquire after it, then finish."""
    model_path = cfg.model.model_path or default_model_path(cfg)
    if RunDirectory(model_path).is_complete() and not cfg.run.overwrite:
        print(f"{model_path}: this run already finished (run_status.json says complete); "
              "pass --overwrite to train it again")
        return Path(model_path)
    run = open_run(cfg, model_path)
    try:
        run.eta = RunTimeEstimator.for_run(run)
        progress = tqdm(total=run.plan.total_iterations, initial=run.state.iteration, disable=cfg.run.quiet,
                        desc="training", dynamic_ncols=True)
        while True:
            train_stage(run, progress)
            if run.state.stage >= len(run.plan.adds):
                break
            acquire(run, progress)
        progress.close()
        finish(run)
    finally:
        close_run(run)
    return Path(model_path)


def write_selection(run: Run, final: dict[str, Any] | None = None) -> None:
    """selection.json: the active config with the selector's own options, every stage record, the final record."""
    cfg = run.cfg
    data: dict[str, Any] = {"config": {**config_to_dict(cfg.active), "selector_options": run.selector.options(),
                                       "seed": cfg.run.seed, "iterations": cfg.run.iterations,
                                       "source_path": cfg.model.source_path},
                            "stages": run.state.stages, "sessions": run.sessions}
    if final is not None:
        data["final"] = final
    write_json(run.run_dir.path / SELECTION, data)
