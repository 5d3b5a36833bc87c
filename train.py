"""Train a 3D Gaussian Splatting model, optionally with active view selection.

    python train.py -s data/lego -r 8 --eval                          # all training views
    python train.py -s data/lego -r 8 --eval --method NAME              # active: seed views + K per step

--method takes any registered selector (listed under --method below); its own options (e.g. --eps) are in the
"Selector options" group.

Every acquisition stage ends with a checkpoint; rerunning the same command resumes from the newest one.
"""
from __future__ import annotations

import argparse
import logging
import random
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import torch
from tqdm import tqdm

from active import Selector, acquisition, build_selector_from, list_selectors
from active.registry import selector_options_dataclass
from active.schedule import StagePlan, farthest_point_views, plan_stages
from arguments import (ActiveConfig, ModelConfig, PipelineConfig, RunConfig, add_config_args, config_from_args,
                       config_to_dict)
from gaussian_renderer import RasterSettings, render
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from scene.resolution_policy import training_resolution
from scene.scene import Scene
from scene.trained import background_color, raster_settings
from training.densify import DensifyConfig, DensifyStrategy
from training.optim import OptimConfig, PositionLRSchedule, create_optimizer
from training.time_estimate import RunTimeEstimator
from utils.checkpoint import RunDirectory
from utils.errors import UserError, run_cli
from utils.io import write_json
from utils.losses import l1_loss, psnr, ssim
from utils.seeding import rng_state, seed_everything, set_rng_state

log = logging.getLogger("train")


SelectorOptions = selector_options_dataclass()  # one flag per option of the registered selectors (e.g. --eps)

# The config groups of a run, once: (attribute of TrainConfig, dataclass, --help section title).
CONFIG_GROUPS: tuple[tuple[str, type, str], ...] = (
    ("model", ModelConfig, "Model"),
    ("pipeline", PipelineConfig, "Pipeline"),
    ("optim", OptimConfig, "Optimization"),
    ("densify", DensifyConfig, "Densification"),
    ("active", ActiveConfig, "Active view selection"),
    ("selector", SelectorOptions, "Selector options (each used by the selectors named in brackets)"),
    ("run", RunConfig, "Run"),
)


@dataclass
class TrainConfig:
    """All config groups of one run (`CONFIG_GROUPS`)."""

    model: ModelConfig
    pipeline: PipelineConfig
    optim: OptimConfig
    densify: DensifyConfig
    active: ActiveConfig
    selector: Any  # SelectorOptions
    run: RunConfig

    def to_dict(self) -> dict[str, Any]:
        return {name: config_to_dict(getattr(self, name)) for name, _, _ in CONFIG_GROUPS}


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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    for _, cls, title in CONFIG_GROUPS:
        add_config_args(parser, cls, title)
    for action in parser._actions:  # list the registered selectors in --method's help
        if action.dest == "method":
            action.help = f"view selector, one of {', '.join(list_selectors())}; empty = train on all training views"
    return parser


def parse_config(argv: list[str] | None = None) -> TrainConfig:
    ns = build_parser().parse_args(argv)
    cfg = TrainConfig(**{name: config_from_args(cls, ns) for name, cls, _ in CONFIG_GROUPS})
    validate_config(cfg)
    return cfg


def validate_config(cfg: TrainConfig) -> None:
    """Reject bad flag values with one clear line each (the selector's own options by its config)."""
    if not cfg.model.source_path:
        raise UserError("no dataset given: pass -s/--source_path DIR (e.g. data/builtin, made by `python -m scene.builtin data/builtin`)")
    if cfg.run.iterations <= 0:
        raise UserError(f"--iterations must be positive, got {cfg.run.iterations}")
    if cfg.model.device == "cuda" and not torch.cuda.is_available():
        raise UserError("--device cuda was asked for but torch sees no CUDA device; use --device cpu")
    raster_settings(cfg.pipeline)  # a bad or unavailable --raster_backend fails before anything is written
    a = cfg.active
    if a.method:
        make_selector(cfg)
        if a.sigma <= 0:
            raise UserError(f"--sigma must be positive, got {a.sigma}")


def make_selector(cfg: TrainConfig) -> Selector:
    """The run's selector, built from --method and the selector flags it declares (validated by its config)."""
    if cfg.active.method not in list_selectors():
        raise UserError(f"unknown --method {cfg.active.method!r}; choose one of: {', '.join(list_selectors())}")
    return build_selector_from(cfg.active.method, config_to_dict(cfg.selector))


def default_model_path(cfg: TrainConfig) -> str:
    name = Path(cfg.model.source_path.rstrip("/")).name or "scene"
    return str(Path("output") / (f"{name}_{cfg.active.method}" if cfg.active.method else name))


# ----------------------------------------------------------------------------------------------- training


def training_step(state: TrainState, camera: Camera, cfg: TrainConfig, background: torch.Tensor,
                  settings: RasterSettings, lr_schedule: PositionLRSchedule,
                  extent: float) -> tuple[torch.Tensor, torch.Tensor]:
    """One optimisation step on one view; returns (loss, psnr) as detached scalar tensors: reading them is a host
    sync on a GPU, so the caller does it only when it logs. The finiteness guard is the step's one sync."""
    it = state.iteration + 1
    lr_schedule.apply(state.optimizer, it)
    if it % 1000 == 0:
        state.gaussians.increase_sh_degree()
    out = render(camera, state.gaussians, background, settings)
    gt = camera.image
    loss = (1.0 - cfg.optim.lambda_dssim) * l1_loss(out.image, gt) + cfg.optim.lambda_dssim * (1.0 - ssim(out.image, gt))
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
def test_psnr(gaussians: GaussianModel, cameras: list[Camera], background: torch.Tensor,
              settings: RasterSettings) -> float | None:
    """Mean PSNR over `cameras` (None when there are none)."""
    if not cameras:
        return None
    values = [float(psnr(render(c, gaussians, background, settings).image.clamp(0, 1), c.image)) for c in cameras]
    return sum(values) / len(values)


# ----------------------------------------------------------------------------------------------- selection


def select_views(state: TrainState, scene: Scene, cfg: TrainConfig, selector: Selector, k: int,
                 background: torch.Tensor, settings: RasterSettings) -> dict[str, Any]:
    """Run the selector for one acquisition step; returns the stage record for selection.json."""
    candidates = [v for v in range(len(scene.train_cameras)) if v not in state.train_views]
    step = acquisition.select_views(selector, state.gaussians, scene.train_cameras, state.train_views, candidates, k,
                                    background, settings, seed=cfg.run.seed, stage=state.stage,
                                    fisher=acquisition.FisherSettings.from_active(cfg.active))
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


# ----------------------------------------------------------------------------------------------- the run


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


def fresh_state(scene: Scene, cfg: TrainConfig, train_views: list[int], total_iterations: int) -> TrainState:
    pcd = scene.initial_point_cloud(cfg.model.num_random_points, cfg.run.seed)
    gaussians = scene.new_gaussians(pcd, cfg.model.sh_degree, cfg.model.device)
    optimizer = create_optimizer(gaussians, cfg.optim, scene.extent)
    return TrainState(gaussians, optimizer, DensifyStrategy(cfg.densify, total_iterations), train_views=list(train_views))


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


PROGRESS_EVERY_S = 30.0  # run_status.json gets the iteration and Gaussian count this often while training


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


def open_run(cfg: TrainConfig, model_path: str) -> Run:
    """Load the scene and resume from the newest checkpoint of `model_path`, or start the run there."""
    run_dir = RunDirectory(model_path)
    if cfg.run.overwrite:
        run_dir.clear()
    resolution = training_resolution(cfg.model)  # the effective -r (CPU width cap, 3DGS rule), kept in cfg_args
    if resolution is not None:
        cfg = replace(cfg, model=replace(cfg.model, resolution=resolution.resolution))
        if resolution.notice:
            print(resolution.notice)
    scene = Scene.from_config(cfg.model, model_path)
    plan = make_plan(cfg, len(scene.train_cameras))
    seed_everything(cfg.run.seed)
    rng = random.Random(cfg.run.seed)
    checkpoint = run_dir.latest_checkpoint()
    if checkpoint is not None:
        state = fresh_state(scene, cfg, [], plan.total_iterations)
        restore_state(state, checkpoint, cfg, scene)
        rng.setstate(checkpoint["train_rng"])
        set_rng_state(checkpoint["rng"])
        print(f"{model_path}: resuming from iteration {state.iteration} (stage {state.stage})")
    else:
        train_views = seed_views(scene, cfg) if cfg.active.method else list(range(len(scene.train_cameras)))
        state = fresh_state(scene, cfg, train_views, plan.total_iterations)
        run_dir.start({**cfg.to_dict(), "total_iterations": plan.total_iterations, "dataset": scene.dataset_record()})
        scene.write_cameras_json()
        state.gaussians.save_ply(Path(model_path) / "input.ply")
        if plan.adds and plan.adds[-1] != cfg.active.views_per_step:
            print(f"note: K={cfg.active.views_per_step} does not divide the remaining budget; "
                  f"the last step adds {plan.adds[-1]} view(s)")
    return Run(cfg, run_dir, scene, plan, make_selector(cfg) if cfg.active.method else None,
               background_color(cfg.model), raster_settings(cfg.pipeline), state, rng,
               PositionLRSchedule.from_config(cfg.optim, scene.extent))


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
            value = test_psnr(state.gaussians, run.scene.test_cameras, run.background, run.settings)
            progress.write(f"[iter {state.iteration}] test PSNR {value:.2f} dB" if value is not None
                           else f"[iter {state.iteration}] no test views (use --eval)")
        if state.iteration in save_its:
            run.scene.save_gaussians(state.gaussians, state.iteration)
        if state.iteration in run_cfg.checkpoint_iterations:
            run.run_dir.save_checkpoint(capture_state(state, run.rng, run.cfg))


def acquire(run: Run, progress: tqdm) -> None:
    """One acquisition step: select the next views, add them, optionally reset the model, write selection.json and
    the stage checkpoint."""
    state, cfg = run.state, run.cfg
    k = run.plan.adds[state.stage]
    progress.write(f"[stage {state.stage}] selecting {k} of {len(run.scene.train_cameras) - len(state.train_views)} "
                   f"candidates with {cfg.active.method}")
    record = select_views(state, run.scene, cfg, run.selector, k, run.background, run.settings)
    state.stages.append(record)
    state.train_views = state.train_views + record["selected"]
    state.view_stack = []
    state.stage += 1
    if cfg.active.stage_reset:
        reset = fresh_state(run.scene, cfg, state.train_views, run.plan.total_iterations)
        state.gaussians, state.optimizer, state.strategy = reset.gaussians, reset.optimizer, reset.strategy
    write_selection(run)
    run.run_dir.save_checkpoint(capture_state(state, run.rng, cfg))


def finish(run: Run) -> None:
    """Final test PSNR, the final selection record and run_status.json "complete"."""
    state = run.state
    final_psnr = test_psnr(state.gaussians, run.scene.test_cameras, run.background, run.settings)
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
    return Path(model_path)


def write_selection(run: Run, final: dict[str, Any] | None = None) -> None:
    """selection.json: the active config with the selector's own options, every stage record, the final record."""
    cfg = run.cfg
    data: dict[str, Any] = {"config": {**config_to_dict(cfg.active), "selector_options": run.selector.options(),
                                       "seed": cfg.run.seed, "iterations": cfg.run.iterations,
                                       "source_path": cfg.model.source_path},
                            "stages": run.state.stages}
    if final is not None:
        data["final"] = final
    write_json(run.run_dir.path / "selection.json", data)


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
    state.gaussians.load_state_dict(ckpt["model"])
    state.optimizer = create_optimizer(state.gaussians, cfg.optim, scene.extent)
    state.optimizer.load_state_dict(ckpt["optimizer"])
    state.strategy.load_state_dict(ckpt["densify"])
    state.iteration, state.stage = ckpt["iteration"], ckpt["stage"]
    state.train_views, state.stages, state.view_stack = ckpt["train_views"], ckpt["stages"], ckpt["view_stack"]


def main() -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cfg = parse_config()
    torch.set_num_threads(torch.get_num_threads())
    training(cfg)


if __name__ == "__main__":
    run_cli(main)
