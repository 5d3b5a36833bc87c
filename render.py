"""Render a trained model's train/test views next to their ground truth, in the 3DGS layout.

    python render.py -m output/lego      # writes output/lego/{train,test}/ours_N/{renders,gt}/NNNNN.png
    python render.py -m output/lego --uncertainty   # also ours_N/uncertainty/NNNNN.{png,npy} and colorbar.png

Uncertainty maps (`active.uncertainty`): per Gaussian the positional variance u_i = trace of the means block of
(H_train,i + delta_i I)^-1 from the Fisher blocks of the model's training views (selection.json for an active run,
all training cameras otherwise), alpha-composited per pixel; .npy holds the float32 map, the PNG its log10 colour
map on one scale per set, colorbar.png that scale.
"""
from __future__ import annotations

import argparse
import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from active.uncertainty import gaussian_uncertainty, recorded_train_views, uncertainty_map
from arguments import ActiveConfig, config_from_dict
from gaussian_renderer import RasterSettings, render
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from scene.trained import TrainedModel, load_trained
from utils.colormap import colorize_log, log_range, save_colorbar
from utils.errors import run_cli
from utils.image import save_image
from utils.model_dir import CFG_ARGS, render_dir


@torch.no_grad()
def render_set(out_dir: Path, cameras: list[Camera], gaussians: GaussianModel, background: torch.Tensor,
               settings: RasterSettings, quiet: bool, uncertainty: torch.Tensor | None = None) -> None:
    """Write renders/ and gt/ PNGs for `cameras` into `out_dir`, atomically (a finished set or none); with
    `uncertainty` [N] also uncertainty/NNNNN.npy (float32 map), NNNNN.png (log10 colour map) and colorbar.png."""
    tmp = out_dir.with_name(out_dir.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    maps = []
    for idx, cam in enumerate(tqdm(cameras, desc=f"rendering {out_dir.parent.name}", disable=quiet)):
        image = render(cam, gaussians, background, settings).image.clamp(0, 1)
        save_image(image, tmp / "renders" / f"{idx:05d}.png")
        save_image(cam.image, tmp / "gt" / f"{idx:05d}.png")
        if uncertainty is not None:
            maps.append(uncertainty_map(cam, gaussians, uncertainty, settings).cpu().numpy())  # [H, W]
    if uncertainty is not None:
        (tmp / "uncertainty").mkdir(parents=True, exist_ok=True)
        lo, hi = log_range(maps)
        for idx, values in enumerate(maps):
            np.save(tmp / "uncertainty" / f"{idx:05d}.npy", values.astype(np.float32))
            save_image(colorize_log(values, lo, hi), tmp / "uncertainty" / f"{idx:05d}.png")
        save_colorbar(tmp / "uncertainty" / "colorbar.png", lo, hi, "positional variance (log10 scale)")
    shutil.rmtree(out_dir, ignore_errors=True)
    tmp.rename(out_dir)


def model_uncertainty(trained: TrainedModel) -> torch.Tensor:
    """u_i of every Gaussian from the Fisher blocks of the model's recorded training views (the run's sigma, ridge
    and Fisher parameter groups, from cfg_args). [N]"""
    saved = json.loads((trained.path / CFG_ARGS).read_text()).get("active", {})
    active = config_from_dict(ActiveConfig, saved) if saved else ActiveConfig()
    views = recorded_train_views(trained.path, trained.iteration, len(trained.scene.train_cameras), active.method)
    return gaussian_uncertainty(trained.gaussians, trained.scene.train_cameras, views, trained.background,
                                trained.settings, sigma=active.sigma, delta_rel=active.delta_rel,
                                delta_abs=active.delta_abs, param_groups=active.fisher_params)


def render_model(model_path: str | Path, iteration: int = -1, skip_train: bool = False, skip_test: bool = False,
                 source_path: str | None = None, quiet: bool = False, raster_backend: str | None = None,
                 uncertainty: bool = False) -> int:
    """Render one model directory (rasterizer backend: `raster_backend`, else the run's; with `uncertainty`, its
    uncertainty maps too); returns the iteration rendered."""
    trained = load_trained(model_path, iteration, source_path)
    if raster_backend:
        trained = replace(trained, settings=replace(trained.settings, backend=raster_backend))
    u = model_uncertainty(trained) if uncertainty else None
    for split, cameras, skip in (("train", trained.scene.train_cameras, skip_train),
                                 ("test", trained.scene.test_cameras, skip_test)):
        if not skip and cameras:
            render_set(render_dir(trained.path, split, trained.iteration), cameras, trained.gaussians,
                       trained.background, trained.settings, quiet, u)
    return trained.iteration


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-m", "--model_path", required=True, help="model directory written by train.py")
    parser.add_argument("-s", "--source_path", default=None, help="dataset directory (default: the one in cfg_args)")
    parser.add_argument("--iteration", type=int, default=-1, help="saved iteration to render (-1 = the last)")
    parser.add_argument("--skip_train", action="store_true", help="do not render the training views")
    parser.add_argument("--skip_test", action="store_true", help="do not render the test views")
    parser.add_argument("--uncertainty", action="store_true",
                        help="also write uncertainty/NNNNN.{png,npy} (Fisher positional variance per pixel)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--raster_backend", choices=("auto", "compiled", "torch"), default=None,
                        help="rasterizer backend (default: the one the model was trained with, in cfg_args)")
    args = parser.parse_args()
    it = render_model(args.model_path, args.iteration, args.skip_train, args.skip_test, args.source_path, args.quiet,
                      args.raster_backend, args.uncertainty)
    print(f"{args.model_path}: rendered iteration {it}")


if __name__ == "__main__":
    run_cli(main)
