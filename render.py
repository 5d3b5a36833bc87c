"""Render a trained model's train/test views next to their ground truth, in the 3DGS layout.

    python render.py -m output/lego      # writes output/lego/{train,test}/ours_N/{renders,gt}/NNNNN.png
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
from pathlib import Path

import torch
from tqdm import tqdm

from arguments import ModelConfig, PipelineConfig, config_from_dict
from gaussian_renderer import RasterSettings, render
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from scene.scene import Scene
from utils.errors import UserError, run_cli
from utils.image import save_image


def load_model_config(model_path: Path) -> tuple[ModelConfig, PipelineConfig]:
    """The model and pipeline configs saved by train.py in `cfg_args`."""
    cfg_file = model_path / "cfg_args"
    if not cfg_file.is_file():
        raise UserError(f"{model_path} has no cfg_args: it is not a model directory written by train.py")
    try:
        saved = json.loads(cfg_file.read_text())
        return config_from_dict(ModelConfig, saved["model"]), config_from_dict(PipelineConfig, saved["pipeline"])
    except (ValueError, KeyError, TypeError):
        raise UserError(f"{cfg_file} is malformed; retrain the model or restore the file") from None


def find_iteration(model_path: Path, iteration: int) -> int:
    """The requested saved iteration, or the largest one when `iteration` is -1."""
    found = sorted(int(m.group(1)) for p in (model_path / "point_cloud").glob("iteration_*")
                   if (m := re.match(r"iteration_(\d+)$", p.name)) and (p / "point_cloud.ply").is_file())
    if not found:
        raise UserError(f"{model_path} has no point_cloud/iteration_*/point_cloud.ply: train it first (train.py)")
    if iteration == -1:
        return found[-1]
    if iteration not in found:
        raise UserError(f"iteration {iteration} was not saved in {model_path}; saved: {found}")
    return iteration


@torch.no_grad()
def render_set(out_dir: Path, cameras: list[Camera], gaussians: GaussianModel, background: torch.Tensor,
               settings: RasterSettings, quiet: bool) -> None:
    """Write renders/ and gt/ PNGs for `cameras` into `out_dir`, atomically (a finished set or none)."""
    tmp = out_dir.with_name(out_dir.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    for idx, cam in enumerate(tqdm(cameras, desc=f"rendering {out_dir.parent.name}", disable=quiet)):
        image = render(cam, gaussians, background, settings).image.clamp(0, 1)
        save_image(image, tmp / "renders" / f"{idx:05d}.png")
        save_image(cam.image, tmp / "gt" / f"{idx:05d}.png")
    shutil.rmtree(out_dir, ignore_errors=True)
    tmp.rename(out_dir)


def render_model(model_path: str | Path, iteration: int = -1, skip_train: bool = False, skip_test: bool = False,
                 source_path: str | None = None, quiet: bool = False) -> int:
    """Render one model directory; returns the iteration rendered."""
    model_path = Path(model_path)
    model_cfg, pipeline_cfg = load_model_config(model_path)
    iteration = find_iteration(model_path, iteration)
    scene = Scene.load(source_path or model_cfg.source_path, model_path, white_background=model_cfg.white_background,
                       resolution=model_cfg.resolution, eval=model_cfg.eval, images=model_cfg.images,
                       device=model_cfg.device)
    gaussians = GaussianModel.load_ply(model_path / "point_cloud" / f"iteration_{iteration}" / "point_cloud.ply",
                                       device=model_cfg.device)
    background = torch.tensor([1.0] * 3 if model_cfg.white_background else [0.0] * 3, device=model_cfg.device)
    settings = RasterSettings(tile_size=pipeline_cfg.tile_size)
    for split, cameras, skip in (("train", scene.train_cameras, skip_train), ("test", scene.test_cameras, skip_test)):
        if not skip and cameras:
            render_set(model_path / split / f"ours_{iteration}", cameras, gaussians, background, settings, quiet)
    return iteration


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-m", "--model_path", required=True, help="model directory written by train.py")
    parser.add_argument("-s", "--source_path", default=None, help="dataset directory (default: the one in cfg_args)")
    parser.add_argument("--iteration", type=int, default=-1, help="saved iteration to render (-1 = the last)")
    parser.add_argument("--skip_train", action="store_true", help="do not render the training views")
    parser.add_argument("--skip_test", action="store_true", help="do not render the test views")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args()
    it = render_model(args.model_path, args.iteration, args.skip_train, args.skip_test, args.source_path, args.quiet)
    print(f"{args.model_path}: rendered iteration {it}")


if __name__ == "__main__":
    run_cli(main)
