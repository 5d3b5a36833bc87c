"""A trained model directory read back: its configs, scene, Gaussians at a saved iteration, background, settings.

    trained = load_trained("output/lego")          # the newest saved iteration
    image = render(trained.scene.test_cameras[0], trained.gaussians, trained.background, trained.settings).image

Used by render.py, the benchmarks and anything else that needs a trained model.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import torch

from arguments import ModelConfig, PipelineConfig, config_from_dict
from gaussian_renderer import RasterSettings
from scene.gaussian_model import GaussianModel
from scene.scene import Scene
from utils.errors import UserError
from utils.model_dir import CFG_ARGS, POINT_CLOUD_DIR, point_cloud_ply


@dataclass
class TrainedModel:
    """What `load_trained` returns."""

    path: Path
    model_cfg: ModelConfig
    pipeline_cfg: PipelineConfig
    iteration: int
    scene: Scene
    gaussians: GaussianModel
    background: torch.Tensor  # [3]
    settings: RasterSettings


def raster_settings(pipeline: PipelineConfig) -> RasterSettings:
    """The rasterizer settings of a run's pipeline config (the one place the CLIs turn one into the other)."""
    return RasterSettings(tile_size=pipeline.tile_size, backend=pipeline.raster_backend)


def background_color(model_cfg: ModelConfig, device: str | torch.device | None = None) -> torch.Tensor:
    """White or black, as the run composited its images. [3]"""
    value = 1.0 if model_cfg.white_background else 0.0
    return torch.full((3,), value, device=device or model_cfg.device)


def load_model_config(model_path: Path) -> tuple[ModelConfig, PipelineConfig]:
    """The model and pipeline configs saved by train.py in `cfg_args`."""
    cfg_file = model_path / CFG_ARGS
    if not cfg_file.is_file():
        raise UserError(f"{model_path} has no cfg_args: it is not a model directory written by train.py")
    try:
        saved = json.loads(cfg_file.read_text())
        return config_from_dict(ModelConfig, saved["model"]), config_from_dict(PipelineConfig, saved["pipeline"])
    except (ValueError, KeyError, TypeError):
        raise UserError(f"{cfg_file} is malformed; retrain the model or restore the file") from None


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
                 device: str | None = None) -> TrainedModel:
    """Read a model directory written by train.py: configs, scene (from `source_path` or the recorded one), the
    Gaussians saved at `iteration` (-1 = the last), background and rasterizer settings, on `device` (default: the
    run's)."""
    model_path = Path(model_path)
    model_cfg, pipeline_cfg = load_model_config(model_path)
    device = device or model_cfg.device
    iteration = find_iteration(model_path, iteration)
    scene = Scene.from_config(model_cfg, model_path, source_path, device)
    gaussians = GaussianModel.load_ply(point_cloud_ply(model_path, iteration),
                                       device=device)
    return TrainedModel(model_path, model_cfg, pipeline_cfg, iteration, scene, gaussians,
                        background_color(model_cfg, device), raster_settings(pipeline_cfg))
