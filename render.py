"""Render a trained model's train/test views next to their ground truth, in the 3DGS layout.

    python render.py -m output/lego      # writes output/lego/{train,test}/ours_N/{renders,gt}/NNNNN.png
"""
from __future__ import annotations

import argparse
import shutil
from dataclasses import replace
from pathlib import Path

import torch
from tqdm import tqdm

from gaussian_renderer import RasterSettings, render
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from scene.trained import load_trained
from utils.errors import run_cli
from utils.image import save_image


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
                 source_path: str | None = None, quiet: bool = False, raster_backend: str | None = None) -> int:
    """Render one model directory (rasterizer backend: `raster_backend`, else the run's); returns the iteration
    rendered."""
    trained = load_trained(model_path, iteration, source_path)
    settings = replace(trained.settings, backend=raster_backend) if raster_backend else trained.settings
    for split, cameras, skip in (("train", trained.scene.train_cameras, skip_train),
                                 ("test", trained.scene.test_cameras, skip_test)):
        if not skip and cameras:
            render_set(trained.path / split / f"ours_{trained.iteration}", cameras, trained.gaussians,
                       trained.background, settings, quiet)
    return trained.iteration


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-m", "--model_path", required=True, help="model directory written by train.py")
    parser.add_argument("-s", "--source_path", default=None, help="dataset directory (default: the one in cfg_args)")
    parser.add_argument("--iteration", type=int, default=-1, help="saved iteration to render (-1 = the last)")
    parser.add_argument("--skip_train", action="store_true", help="do not render the training views")
    parser.add_argument("--skip_test", action="store_true", help="do not render the test views")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--raster_backend", choices=("auto", "compiled", "torch"), default=None,
                        help="rasterizer backend (default: the one the model was trained with, in cfg_args)")
    args = parser.parse_args()
    it = render_model(args.model_path, args.iteration, args.skip_train, args.skip_test, args.source_path, args.quiet,
                      args.raster_backend)
    print(f"{args.model_path}: rendered iteration {it}")


if __name__ == "__main__":
    run_cli(main)
