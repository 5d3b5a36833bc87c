"""Render a trained model's train/test views next to their ground truth, in the 3DGS layout.

    python render.py -m output/lego      # writes output/lego/{train,test}/ours_N/{renders,gt}/NNNNN.png
    python render.py -m output/lego --uncertainty   # also ours_N/uncertainty/KIND/NNNNN.{png,npy}, colorbar.png

Uncertainty maps (`active.uncertainty`), one folder per kind (`--uncertainty_kind`, comma-separated, default all):
"position_variance": per Gaussian u_i = trace of the means block of (H_train,i + delta_i I)^-1 from the Fisher blocks
of the model's training views (selection.json for an active run, all training cameras otherwise), alpha-composited
per pixel; "fisherrf" / "fisherrf_view": FisherRF's recipe (information x depth, from the training views' colour
Fisher / the view's own). .npy holds the float32 map, the PNG its log10 colour map on one scale per set,
colorbar.png that scale. For Blender scenes (RGBA images) `uncertainty/object_mask/NNNNN.png` marks the pixels where
the ground truth or the render differs from the background (metrics.py's "object" region).
"""
from __future__ import annotations

if __name__ == "__main__":  # a second writer into a directory being written is refused before the slow imports
    from utils.dir_lock import WAYS_OUT, refuse_if_locked
    refuse_if_locked(("-m", "--model_path"), WAYS_OUT["render"])

import argparse
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from active.fisher import FISHER_PARAM_GROUPS, REFERENCE_DIAGONAL_GROUPS
from active.memory_budget import (FisherWork, block_size, device_available_bytes, estimate, fit_fisher_memory,
                                  largest_pixels, pass_label)
from active.uncertainty import (COLOUR_GROUPS, UNCERTAINTY_KINDS, fisherrf_information, fisherrf_map,
                                gaussian_uncertainty, parse_uncertainty_kinds, uncertainty_map, view_information)
from arguments import ActiveConfig, FisherSettings, config_from_dict
from gaussian_renderer import RasterSettings, render
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from scene.trained import TrainedModel, load_trained, recorded_train_views
from utils.colormap import colorize_log, log_range, save_colorbar
from utils.errors import run_cli
from utils.image import save_image
from utils.dir_lock import WAYS_OUT, writer_lock
from utils.io import disk_write_error
from utils.model_dir import render_dir



@torch.no_grad()
def render_set(out_dir: Path, cameras: list[Camera], gaussians: GaussianModel, background: torch.Tensor,
               settings: RasterSettings, quiet: bool, uncertainty: dict[str, torch.Tensor | None] | None = None,
               object_mask: bool = False) -> None:
    """Write renders/ and gt/ PNGs for `cameras` into `out_dir`, atomically (a finished set or none). With
    `uncertainty` {kind: per-Gaussian values [N], or None for "fisherrf_view" (computed per view)} also
    uncertainty/KIND/NNNNN.npy (float32 map), NNNNN.png (log10 colour map) and colorbar.png; with `object_mask`
    uncertainty/object_mask/NNNNN.png (255 where the ground truth or the render differs from the background)."""
    tmp = out_dir.with_name(out_dir.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        _render_into(tmp, cameras, gaussians, background, settings, quiet, uncertainty, object_mask,
                     out_dir.parent.name)
    except OSError as exc:  # a full disk or a permission error: one line, and no partial folder left behind
        shutil.rmtree(tmp, ignore_errors=True)
        if (err := disk_write_error(exc.filename or tmp, exc)) is not None:
            raise err from None
        raise
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    shutil.rmtree(out_dir, ignore_errors=True)
    tmp.rename(out_dir)


def _render_into(tmp: Path, cameras: list[Camera], gaussians: GaussianModel, background: torch.Tensor,
                 settings: RasterSettings, quiet: bool, uncertainty: dict[str, torch.Tensor | None] | None,
                 object_mask: bool, split: str) -> None:
    """render_set's writing, into the temporary folder `tmp`."""
    uncertainty = uncertainty or {}
    maps: dict[str, list[np.ndarray]] = {kind: [] for kind in uncertainty}
    for idx, cam in enumerate(tqdm(cameras, desc=f"rendering {split}", disable=quiet)):
        image = render(cam, gaussians, background, settings).image.clamp(0, 1)
        save_image(image, tmp / "renders" / f"{idx:05d}.png")
        save_image(cam.image, tmp / "gt" / f"{idx:05d}.png")
        for kind, values in uncertainty.items():
            maps[kind].append(kind_map(kind, cam, gaussians, background, settings, values).cpu().numpy())  # [H, W]
        if uncertainty and object_mask:
            save_image(object_pixels(image, cam.image, background).float()[None].expand(3, -1, -1),
                       tmp / "uncertainty" / "object_mask" / f"{idx:05d}.png")
    for kind, kind_maps in maps.items():
        folder = tmp / "uncertainty" / kind
        folder.mkdir(parents=True, exist_ok=True)
        lo, hi = log_range(kind_maps)
        for idx, values in enumerate(kind_maps):
            np.save(folder / f"{idx:05d}.npy", values.astype(np.float32))
            save_image(colorize_log(values, lo, hi), folder / f"{idx:05d}.png")
        save_colorbar(folder / "colorbar.png", lo, hi, f"{UNCERTAINTY_KINDS[kind]} (log10 scale)")


def kind_map(kind: str, camera: Camera, gaussians: GaussianModel, background: torch.Tensor,
             settings: RasterSettings, values: torch.Tensor | None) -> torch.Tensor:
    """One view's uncertainty map of `kind` from the per-Gaussian `values` (None for "fisherrf_view"). [H, W]"""
    if kind == "position_variance":
        return uncertainty_map(camera, gaussians, values, settings)
    if kind == "fisherrf":
        return fisherrf_map(camera, gaussians, values, settings, clamp_depth=True)
    return fisherrf_map(camera, gaussians, view_information(gaussians, camera, background, settings), settings,
                        clamp_depth=False)


def object_pixels(image: torch.Tensor, gt: torch.Tensor, background: torch.Tensor) -> torch.Tensor:
    """Pixels where the 8-bit ground truth or render differs from the 8-bit background colour. [3,H,W] x2 -> [H,W]"""
    bg = (background.to(image) * 255).round()[:, None, None]
    return (((image * 255).round() != bg) | ((gt.to(image) * 255).round() != bg)).any(0)


def recorded_active(trained: TrainedModel) -> ActiveConfig:
    """The run's active-selection config from its cfg_args (the defaults for a run that recorded none)."""
    saved = trained.record.get("active", {})
    return config_from_dict(ActiveConfig, saved) if saved else ActiveConfig()


def model_uncertainty(trained: TrainedModel, kinds: tuple[str, ...]) -> dict[str, torch.Tensor | None]:
    """Per kind, the per-Gaussian values from the model's recorded training views: u_i (the run's sigma, ridge and
    Fisher parameter groups, from cfg_args) for "position_variance", FisherRF's colour information for "fisherrf",
    None for "fisherrf_view" (it needs each rendered view). {kind: [N] or None}"""
    active = recorded_active(trained)
    views = recorded_train_views(trained.path, trained.iteration, len(trained.scene.train_cameras), active.method)
    cameras, out = trained.scene.train_cameras, {}
    for kind in kinds:
        if kind == "position_variance":
            out[kind] = gaussian_uncertainty(trained.gaussians, cameras, views, trained.background, trained.settings,
                                             fisher=FisherSettings.from_active(active))
        elif kind == "fisherrf":
            out[kind] = fisherrf_information(trained.gaussians, cameras, views, trained.background, trained.settings)
        else:
            out[kind] = None
    return out


def check_uncertainty_memory(trained: TrainedModel, kinds: tuple[str, ...]) -> None:
    """Each kind's Fisher pass checked against the available memory before any work (one `UserError` line naming
    the estimate, the available memory and the kinds that fit): the dense blocks of "position_variance" (the run's
    --fisher_params), the diagonals of FisherRF's kinds."""
    params = recorded_active(trained).fisher_params
    gaussians, pixels = trained.gaussians, largest_pixels(trained.scene.train_cameras + trained.scene.test_cameras)
    n = gaussians.num_gaussians
    works = {"position_variance": FisherWork("uncertainty", n, block_size(gaussians, FISHER_PARAM_GROUPS[params]),
                                             pixels),
             "fisherrf": FisherWork("diagonal", n, block_size(gaussians, COLOUR_GROUPS), pixels),
             "fisherrf_view": FisherWork("diagonal", n, block_size(gaussians, REFERENCE_DIAGONAL_GROUPS), pixels)}
    available = device_available_bytes(gaussians.device)
    for kind in kinds:
        others = [k for k in works if k != kind]
        remedy = {f"--uncertainty_kind {','.join(others)}": max((works[k] for k in others),
                                                                 key=lambda w: estimate(w).peak)}
        fit_fisher_memory(works[kind], FisherSettings(), pass_label(f"{kind} uncertainty", works[kind], params), remedy,
                          "render without --uncertainty or on a larger machine", available)


def render_model(model_path: str | Path, iteration: int = -1, skip_train: bool = False, skip_test: bool = False,
                 source_path: str | None = None, quiet: bool = False, raster_backend: str | None = None,
                 uncertainty: bool = False, uncertainty_kinds: tuple[str, ...] = tuple(UNCERTAINTY_KINDS)) -> int:
    """Render one model directory (rasterizer backend: `raster_backend`, else the run's; with `uncertainty`, its
    uncertainty maps of `uncertainty_kinds` too), holding its writer lock; returns the iteration rendered."""
    with writer_lock(model_path, WAYS_OUT["render"], create=False):  # a missing directory: load_trained says so
        return _render_model(model_path, iteration, skip_train, skip_test, source_path, quiet, raster_backend,
                             uncertainty, uncertainty_kinds)


def _render_model(model_path: str | Path, iteration: int, skip_train: bool, skip_test: bool, source_path: str | None,
                  quiet: bool, raster_backend: str | None, uncertainty: bool,
                  uncertainty_kinds: tuple[str, ...]) -> int:
    trained = load_trained(model_path, iteration, source_path)
    if raster_backend:
        trained = replace(trained, settings=replace(trained.settings, backend=raster_backend))
    if uncertainty:
        check_uncertainty_memory(trained, uncertainty_kinds)
    u = model_uncertainty(trained, uncertainty_kinds) if uncertainty else None
    with_mask = trained.scene.info.kind == "blender"  # Blender frames are RGBA: an object region exists
    for split, cameras, skip in (("train", trained.scene.train_cameras, skip_train),
                                 ("test", trained.scene.test_cameras, skip_test)):
        if not skip and cameras:
            render_set(render_dir(trained.path, split, trained.iteration), cameras, trained.gaussians,
                       trained.background, trained.settings, quiet, u, with_mask)
    return trained.iteration


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-m", "--model_path", required=True, help="model directory written by train.py")
    parser.add_argument("-s", "--source_path", default=None, help="dataset directory (default: the one in cfg_args)")
    parser.add_argument("--iteration", type=int, default=-1, help="saved iteration to render (-1 = the last)")
    parser.add_argument("--skip_train", action="store_true", help="do not render the training views")
    parser.add_argument("--skip_test", action="store_true", help="do not render the test views")
    parser.add_argument("--uncertainty", action="store_true",
                        help="also write uncertainty/KIND/NNNNN.{png,npy} (per-pixel uncertainty maps)")
    parser.add_argument("--uncertainty_kind", default=",".join(UNCERTAINTY_KINDS),
                        help=f"comma-separated map kinds: {', '.join(UNCERTAINTY_KINDS)} (default: all)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--raster_backend", choices=("auto", "compiled", "torch"), default=None,
                        help="rasterizer backend (default: the one the model was trained with, in cfg_args)")
    args = parser.parse_args()
    kinds = parse_uncertainty_kinds(args.uncertainty_kind)
    it = render_model(args.model_path, args.iteration, args.skip_train, args.skip_test, args.source_path, args.quiet,
                      args.raster_backend, args.uncertainty, kinds)
    print(f"{args.model_path}: rendered iteration {it}")


if __name__ == "__main__":
    run_cli(main)
