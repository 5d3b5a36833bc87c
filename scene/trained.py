"""A trained model directory read back: its configs, scene, Gaussians at a saved iteration, background, settings.

    trained = load_trained("output/lego")          # the newest saved iteration
    image = render(trained.scene.test_cameras[0], trained.gaussians, trained.background, trained.settings).image

    trained = load_trained("output/lego", cameras_only=True)   # no dataset read: cameras from cameras.json
    views = recorded_train_views(trained.path, trained.iteration, len(trained.train_cameras), "lite_gs")

The one way render.py, recommend.py (`recommender`), the benchmarks and anything else read a model directory.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import torch

from arguments import ModelConfig, PipelineConfig, config_from_dict
from gaussian_renderer import RasterSettings
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from scene.pose_files import read_pose_file
from scene.scene import Scene
from utils.errors import UserError
from utils.io import read_json
from utils.model_dir import CAMERAS, CFG_ARGS, POINT_CLOUD_DIR, SELECTION, point_cloud_ply


@dataclass
class TrainedModel:
    """What `load_trained` returns."""

    path: Path
    model_cfg: ModelConfig
    pipeline_cfg: PipelineConfig
    iteration: int
    scene: Scene | None  # None when loaded with cameras_only (no dataset read)
    gaussians: GaussianModel
    background: torch.Tensor  # [3]
    settings: RasterSettings
    train_cameras: list[Camera] = field(default_factory=list)  # view id = index (the scene's, or cameras.json's)
    record: dict = field(default_factory=dict)  # cfg_args as saved: "model", "pipeline", "active", "dataset", ...


def raster_settings(pipeline: PipelineConfig) -> RasterSettings:
    """The rasterizer settings of a run's pipeline config (the one place the CLIs turn one into the other)."""
    return RasterSettings(tile_size=pipeline.tile_size, backend=pipeline.raster_backend)


def background_color(model_cfg: ModelConfig, device: str | torch.device | None = None) -> torch.Tensor:
    """White or black, as the run composited its images. [3]"""
    value = 1.0 if model_cfg.white_background else 0.0
    return torch.full((3,), value, device=device or model_cfg.device)


def read_model_record(model_path: Path) -> dict:
    """`cfg_args` as train.py saved it (groups "model", "pipeline", "active", "dataset", ...)."""
    saved = read_json(model_path / CFG_ARGS, missing="none", fix="retrain the model or restore the file")
    if saved is None:
        raise UserError(f"{model_path} has no cfg_args: it is not a model directory written by train.py")
    return saved


def load_model_config(model_path: Path) -> tuple[ModelConfig, PipelineConfig]:
    """The model and pipeline configs saved by train.py in `cfg_args`."""
    return _configs(model_path, read_model_record(model_path))


def _configs(model_path: Path, saved: dict) -> tuple[ModelConfig, PipelineConfig]:
    try:
        return config_from_dict(ModelConfig, saved["model"]), config_from_dict(PipelineConfig, saved["pipeline"])
    except (ValueError, KeyError, TypeError):
        raise UserError(f"{model_path / CFG_ARGS} is malformed; retrain the model or restore the file") from None


def find_iteration(model_path: Path, iteration: int = -1) -> int:
    """The requested saved iteration, or the largest one when `iteration` is -1."""
    found = sorted(int(m.group(1)) for p in (model_path / POINT_CLOUD_DIR).glob("iteration_*")
                   if (m := re.match(r"iteration_(\d+)$", p.name))
                   and point_cloud_ply(model_path, int(m.group(1))).is_file())
    if not found:
        raise UserError(f"{model_path} has no point_cloud/iteration_*/point_cloud.ply: train it first (train.py)")
    if iteration == -1:
        return found[-1]
    if iteration not in found:
        raise UserError(f"iteration {iteration} was not saved in {model_path}; saved: {found}")
    return iteration


def load_trained(model_path: str | Path, iteration: int = -1, source_path: str | None = None,
                 device: str | None = None, *, cameras_only: bool = False,
                 sh_degree_as_trained: bool = False) -> TrainedModel:
    """Read a model directory written by train.py: configs, scene (from `source_path` or the recorded one), the
    Gaussians saved at `iteration` (-1 = the last), background and rasterizer settings, on `device` (default: the
    run's).

    `cameras_only`: no dataset is read (`scene` None); `train_cameras` are the run's training cameras from its
    cameras.json (poses and intrinsics, no image). `sh_degree_as_trained`: the active SH degree the run had at
    `iteration` (`GaussianModel.trained_sh_degree`) instead of every band the PLY holds."""
    model_path = Path(model_path)
    saved = read_model_record(model_path)
    model_cfg, pipeline_cfg = _configs(model_path, saved)
    device = device or model_cfg.device
    iteration = find_iteration(model_path, iteration)
    if cameras_only:
        scene, train_cameras = None, recorded_train_cameras(model_path, saved, device)
    else:
        scene = Scene.from_config(model_cfg, model_path, source_path, device)
        train_cameras = scene.train_cameras
    gaussians = GaussianModel.load_ply(point_cloud_ply(model_path, iteration),
                                       device=device)
    if sh_degree_as_trained:
        gaussians.active_sh_degree = GaussianModel.trained_sh_degree(
            iteration, gaussians.max_sh_degree, bool(saved.get("model", {}).get("init_ply")))
    return TrainedModel(model_path, model_cfg, pipeline_cfg, iteration, scene, gaussians,
                        background_color(model_cfg, device), raster_settings(pipeline_cfg), train_cameras, saved)


def recorded_train_cameras(model_path: Path, saved: dict, device: str | torch.device) -> list[Camera]:
    """The run's training cameras from its cameras.json (test cameras first, then training: `Scene.write_cameras_json`),
    split by the dataset record in cfg_args; no image read."""
    dataset = saved.get("dataset")
    if not isinstance(dataset, dict) or "num_test" not in dataset:
        raise UserError(f"{model_path / CFG_ARGS} records no dataset split (num_test); retrain the model with this "
                        "train.py")
    cameras_json = model_path / CAMERAS
    if not cameras_json.is_file():
        raise UserError(f"{model_path} has no {CAMERAS}; retrain the model or restore the file")
    return [c.to(device) for c in read_pose_file(cameras_json)[dataset["num_test"]:]]


def recorded_train_views(model_path: Path, iteration: int, num_train: int, method: str) -> list[int]:
    """The training views of the model saved at `iteration`: from selection.json for an active run (the set of the
    stage that iteration belongs to), all `num_train` training cameras for a run without --method (`method` "").

    Raises:
        UserError: an active run without a readable selection.json, or a run with no training cameras.
    """
    if not method:
        if num_train == 0:
            raise UserError(f"{model_path}: the scene has no training cameras, so no training views to take the "
                            "uncertainty from")
        return list(range(num_train))
    selection = read_json(model_path / SELECTION, missing="none", damaged="none") or {}  # either: the error below
    try:
        stages, final = selection["stages"], selection.get("final")
        for stage in stages:  # the training set before acquisition s trained up to stage s's iteration
            if iteration <= stage["iteration"]:
                return list(stage["train_views"])
        if final is not None:
            return list(final["train_views"])
    except (KeyError, TypeError):
        pass
    raise UserError(f"{model_path}: no training views recorded for iteration {iteration} (selection.json missing, "
                    "unfinished or malformed); --uncertainty needs a finished train.py run")
