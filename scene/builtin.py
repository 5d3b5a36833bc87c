"""The built-in scene: a small Blender-format dataset generated procedurally and rendered by our rasterizer.

A few coloured objects made of Gaussians (a sphere, a box, a ring and a ground disc) seen from `num_train` training
and `num_test` test cameras on a hemisphere (radius 4, looking at the origin, the NeRF-synthetic field of view).
Deterministic for a given seed, so the README's main command needs no download. `--layout clutter` draws a new
arrangement of seven objects for every seed instead (scene/clutter.py): scenes for held-out checks.

    python -m scene.builtin data/builtin [--seed 0] [--resolution 128] [--layout clutter]
"""
from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path

import torch

from gaussian_renderer import rasterization
from scene.cameras import look_at
from scene.clutter import clutter_points
from scene.dataset_readers import GL_TO_CV
from utils.errors import UserError, run_cli
from utils.image import save_image
from utils.io import read_json, write_json

CAMERA_RADIUS = 4.0
CAMERA_ANGLE_X = 0.6911  # NeRF-synthetic field of view
STAMP = "builtin_scene.json"

log = logging.getLogger(__name__)


def _object_points(g: torch.Generator) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Centres [N,3], colours [N,3] and isotropic scales [N] of the scene's Gaussians."""
    parts = []

    def add(points, base_rgb, jitter, scale):
        colors = (torch.tensor(base_rgb) + jitter * (torch.rand(points.shape[0], 3, generator=g) - 0.5)).clamp(0, 1)
        parts.append((points, colors, torch.full((points.shape[0],), scale)))

    # Sphere (red, with a yellow band so its rotation is observable).
    n = 900
    u = torch.rand(n, generator=g) * 2 - 1
    phi = torch.rand(n, generator=g) * 2 * math.pi
    r = torch.sqrt(1 - u * u)
    sphere = torch.stack([r * torch.cos(phi), r * torch.sin(phi), u], 1) * 0.45 + torch.tensor([0.5, 0.3, 0.45])
    band = u.abs() < 0.2
    add(sphere[~band], (0.85, 0.15, 0.1), 0.15, 0.05)
    add(sphere[band], (0.95, 0.85, 0.1), 0.1, 0.05)
    # Box (blue faces), surface samples.
    n = 900
    p = torch.rand(n, 3, generator=g) * 2 - 1
    axis = torch.randint(0, 3, (n,), generator=g)
    p[torch.arange(n), axis] = torch.sign(p[torch.arange(n), axis])
    add(p * torch.tensor([0.3, 0.35, 0.3]) + torch.tensor([-0.55, -0.35, 0.3]), (0.15, 0.3, 0.9), 0.2, 0.045)
    # Ring (green torus) standing up.
    n = 700
    a, b = torch.rand(n, generator=g) * 2 * math.pi, torch.rand(n, generator=g) * 2 * math.pi
    ring = torch.stack([(0.4 + 0.1 * torch.cos(b)) * torch.cos(a), 0.1 * torch.sin(b),
                        (0.4 + 0.1 * torch.cos(b)) * torch.sin(a)], 1) + torch.tensor([-0.1, 0.6, 0.55])
    add(ring, (0.1, 0.75, 0.25), 0.2, 0.04)
    parts.append(_ground_disc(g))
    means = torch.cat([q[0] for q in parts])
    colors = torch.cat([q[1] for q in parts])
    scales = torch.cat([q[2] for q in parts])
    return means, colors, scales


def _ground_disc(g: torch.Generator) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The checkered grey/white ground disc (radius 1.2) every layout stands on: centres, colours, scales."""
    n = 1500
    rad = torch.sqrt(torch.rand(n, generator=g)) * 1.2
    ang = torch.rand(n, generator=g) * 2 * math.pi
    disc = torch.stack([rad * torch.cos(ang), rad * torch.sin(ang), torch.zeros(n)], 1)
    checker = ((torch.floor(disc[:, 0] / 0.3) + torch.floor(disc[:, 1] / 0.3)) % 2 == 0)
    points = [disc[checker], disc[~checker]]
    colors = [(torch.tensor(rgb) + 0.05 * (torch.rand(p.shape[0], 3, generator=g) - 0.5)).clamp(0, 1)
              for p, rgb in zip(points, ((0.9, 0.9, 0.85), (0.35, 0.35, 0.4)))]
    return torch.cat(points), torch.cat(colors), torch.full((n,), 0.06)


def _clutter_layout(g: torch.Generator) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    means, colors, scales, _ = clutter_points(g)
    disc = _ground_disc(g)
    return torch.cat([means, disc[0]]), torch.cat([colors, disc[1]]), torch.cat([scales, disc[2]])


LAYOUTS = {"objects": _object_points, "clutter": _clutter_layout}  # name -> generator -> centres, colours, scales


def _check_layout(layout: str) -> None:
    if layout not in LAYOUTS:
        raise UserError(f"--layout {layout!r}: choose one of {', '.join(LAYOUTS)}")


def hemisphere_positions(count: int, offset: float) -> torch.Tensor:
    """Camera centres spread over the upper hemisphere (elevation 10..75 degrees) by a golden-angle spiral. [V, 3]"""
    i = torch.arange(count, dtype=torch.float64) + offset
    elevation = torch.deg2rad(10 + 65 * (i / (count + offset)))
    azimuth = i * math.pi * (3 - math.sqrt(5))
    return CAMERA_RADIUS * torch.stack([torch.cos(elevation) * torch.cos(azimuth),
                                        torch.cos(elevation) * torch.sin(azimuth), torch.sin(elevation)], 1)


def scene_gaussians(seed: int, layout: str = "objects"
                    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The scene as rasterizer inputs: means [N,3], quats [N,4], scales [N,3], opacities [N], colours [N,3]."""
    _check_layout(layout)
    means, colors, scales = LAYOUTS[layout](torch.Generator().manual_seed(seed))
    n = means.shape[0]
    quats = torch.zeros(n, 4)
    quats[:, 0] = 1
    return means, quats, scales[:, None].repeat(1, 3), torch.full((n,), 0.9), colors  # isotropic scales


def render_rgba(viewmat: torch.Tensor, intrinsics: torch.Tensor, width: int, height: int, seed: int = 0,
                gaussians: tuple[torch.Tensor, ...] | None = None) -> torch.Tensor:
    """The scene's ground truth from any pose: straight (un-premultiplied) RGB and alpha, as the dataset's PNGs.

    Args:
        viewmat: world-to-camera, OpenCV axes. [4, 4]
        intrinsics: (fx, fy, cx, cy) in pixels. [4]
        gaussians: `scene_gaussians(seed)` when already computed.
    Returns:
        RGBA in [0, 1]. [4, H, W]
    """
    means, quats, scales3, opacities, colors = gaussians or scene_gaussians(seed)
    out = rasterization(means, quats, scales3, opacities, colors, viewmat.float(), intrinsics.float(), width, height)
    straight = (out.image / out.alpha.clamp(1e-6, 1)).clamp(0, 1)  # un-premultiply (black background)
    return torch.cat([straight, out.alpha[None]])


def _render_splits(out: Path, seed: int, layout: str, resolution: int, num_train: int, num_test: int) -> None:
    """Render the scene's Gaussians from every camera; write the RGBA PNGs and both transforms files."""
    means, quats, scales3, opacities, colors = scene_gaussians(seed, layout)
    focal = 0.5 * resolution / math.tan(0.5 * CAMERA_ANGLE_X)
    intrinsics = torch.tensor([focal, focal, resolution / 2, resolution / 2])
    for split, count, offset in (("train", num_train, 0.5), ("test", num_test, 0.25)):
        frames = []
        for idx, eye in enumerate(hemisphere_positions(count, offset)):
            viewmat = look_at(eye)
            save_image(render_rgba(viewmat, intrinsics, resolution, resolution, seed, (means, quats, scales3,
                                                                                      opacities, colors)),
                       out / split / f"r_{idx}.png")
            c2w = torch.linalg.inv(viewmat) @ GL_TO_CV  # the flip is its own inverse
            frames.append({"file_path": f"./{split}/r_{idx}", "transform_matrix": c2w.tolist()})
        write_json(out / f"transforms_{split}.json", {"camera_angle_x": CAMERA_ANGLE_X, "frames": frames})


def make_builtin_scene(out_dir: str | Path, seed: int = 0, resolution: int = 128, num_train: int = 100,
                       num_test: int = 25, layout: str = "objects") -> Path:
    """Write the dataset (skipped when `out_dir` already holds one made with the same parameters)."""
    out = Path(out_dir)
    params = {"seed": seed, "resolution": resolution, "num_train": num_train, "num_test": num_test, "version": 1}
    if layout != "objects":  # the default layout's stamp predates layouts: it stays valid
        params["layout"] = layout
    _check_layout(layout)
    if resolution < 8:
        raise UserError(f"--resolution must be at least 8 pixels, got {resolution}")
    if num_train < 1 or num_test < 1:
        raise UserError(f"--num_train and --num_test must be at least 1, got {num_train} and {num_test}")
    stamp = out / STAMP
    if read_json(stamp, missing="none", damaged="none") == params:  # absent or damaged: regenerate
        log.info("built-in scene already in %s", out)
        return out
    stamp.unlink(missing_ok=True)  # a crash part-way must not leave a stamp that claims a complete scene
    # Small renders run several times faster on one thread, and far faster on a shared, busy CPU.
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        _render_splits(out, seed, layout, resolution, num_train, num_test)
    finally:
        torch.set_num_threads(threads)
    write_json(stamp, params)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out_dir", help="where to write the dataset")
    parser.add_argument("--seed", type=int, default=0,
                        help="objects: resamples the same objects' surface points; clutter: a new arrangement")
    parser.add_argument("--layout", choices=list(LAYOUTS), default="objects",
                        help="objects (default): sphere, box, ring on a disc, the same scene for every seed; "
                             "clutter: seven objects drawn by the seed (scene/clutter.py), a new scene per seed")
    parser.add_argument("--resolution", type=int, default=128, help="image width and height in pixels")
    parser.add_argument("--num_train", type=int, default=100)
    parser.add_argument("--num_test", type=int, default=25)
    args = parser.parse_args()
    out = make_builtin_scene(args.out_dir, args.seed, args.resolution, args.num_train, args.num_test, args.layout)
    print(f"built-in scene ready in {out}")


if __name__ == "__main__":
    run_cli(main)
