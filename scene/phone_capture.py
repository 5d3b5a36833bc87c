"""A synthetic phone capture of the built-in scene: portrait frames through a distorted lens, written as an
instant-ngp / nerfstudio `transforms.json` (fl_x, fl_y, cx, cy, w, h, k1, k2, p1, p2) with a few frames missing.

Each frame is rendered by our rasterizer as a pinhole image on a canvas wide enough for the lens, then distorted
with OpenCV (`scene.lens.distortion_maps`), so the lens is known exactly. Deterministic for a given seed.

    python -m scene.phone_capture data/phone [--width 1080 --height 1920 --frames 20 --missing 3]
"""
from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path

import cv2
import numpy as np
import torch
from PIL import Image

from gaussian_renderer import rasterization
from scene.builtin import hemisphere_positions, scene_gaussians
from scene.cameras import look_at
from scene.frames import GL_TO_CV
from scene.lens import Lens, distortion_maps, pixel_grid, undistort_points
from utils.errors import UserError, run_cli
from utils.io import read_json, write_json

DISTORTION = {"k1": -0.12, "k2": 0.03, "p1": 0.001, "p2": -0.0015}  # a wide phone lens, barrel
FOCAL_PER_HEIGHT = 0.75  # fx = fy = 0.75 x image height: a ~67 degree vertical field, as a phone's main camera
STAMP = "phone_capture.json"

log = logging.getLogger(__name__)


def capture_lens(width: int, height: int, distortion: dict[str, float] | None = None) -> Lens:
    """The capture's lens: centred principal point, square pixels, OpenCV coefficients (k1, k2, p1, p2)."""
    d = DISTORTION if distortion is None else distortion
    f = FOCAL_PER_HEIGHT * height
    return Lens(width, height, f, f, width / 2, height / 2, "OPENCV",
                (d.get("k1", 0.0), d.get("k2", 0.0), d.get("p1", 0.0), d.get("p2", 0.0)))


def pinhole_canvas(lens: Lens, margin: int = 2) -> Lens:
    """A pinhole lens with `lens`'s focal lengths whose image covers every ray the distorted frame sees."""
    border = pixel_grid(lens.width, lens.height).reshape(lens.height, lens.width, 1, 2)
    border = np.concatenate([border[0], border[-1], border[:, 0], border[:, -1]])  # [2(W+H), 1, 2]
    xy = undistort_points(lens, border, lens.pinhole())[:, 0]  # [2(W+H), 2] in the same-K pinhole's pixels
    x0, y0 = math.floor(xy[:, 0].min()) - margin, math.floor(xy[:, 1].min()) - margin
    x1, y1 = math.ceil(xy[:, 0].max()) + margin, math.ceil(xy[:, 1].max()) + margin
    return Lens(x1 - x0 + 1, y1 - y0 + 1, lens.fx, lens.fy, lens.cx - x0, lens.cy - y0)


def render_distorted(gaussians: tuple[torch.Tensor, ...], viewmat: torch.Tensor, lens: Lens,
                     canvas: Lens | None = None, maps: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The frame `lens` sees from `viewmat` [4, 4]: a pinhole render on `canvas`, distorted. [H, W, 3] uint8

    `canvas` and `maps` (from `pinhole_canvas` and `distortion_maps`) may be passed to reuse them across frames.
    """
    canvas = canvas or pinhole_canvas(lens)
    map_x, map_y = maps or distortion_maps(lens, canvas)
    means, quats, scales, opacities, colors = gaussians
    intrinsics = torch.tensor([canvas.fx, canvas.fy, canvas.cx, canvas.cy])
    out = rasterization(means, quats, scales, opacities, colors, viewmat.float(), intrinsics, canvas.width,
                        canvas.height)
    pinhole = (out.image.clamp(0, 1).permute(1, 2, 0).numpy() * 255 + 0.5).astype(np.uint8)  # on black
    return cv2.remap(pinhole, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def missing_frames(num_frames: int, missing: int) -> set[int]:
    """Which frames are deleted: evenly spread, never frame 0 (the first test view under --eval)."""
    if missing <= 0:
        return set()
    return {1 + round((i + 0.5) * (num_frames - 1) / missing - 0.5) for i in range(missing)}


def make_phone_capture(out_dir: str | Path, width: int = 1080, height: int = 1920, num_frames: int = 20,
                       missing: int = 3, seed: int = 0, distortion: dict[str, float] | None = None) -> Path:
    """Write `images/frame_NNNNN.jpg` and `transforms.json` (skipped when `out_dir` holds the same capture)."""
    out = Path(out_dir)
    lens = capture_lens(width, height, distortion)
    params = {"width": width, "height": height, "num_frames": num_frames, "missing": missing, "seed": seed,
              "dist": list(lens.dist), "version": 1}
    if width < 8 or height < 8:
        raise UserError(f"--width and --height must be at least 8 pixels, got {width}x{height}")
    if num_frames < 2 or not 0 <= missing < num_frames - 1:
        raise UserError(f"need --frames >= 2 and 0 <= --missing < frames - 1, got {num_frames} and {missing}")
    stamp = out / STAMP
    if read_json(stamp, missing="none", damaged="none") == params:  # absent or damaged: capture again
        log.info("phone capture already in %s", out)
        return out
    stamp.unlink(missing_ok=True)
    gaussians = scene_gaussians(seed)
    canvas = pinhole_canvas(lens)
    maps = distortion_maps(lens, canvas)
    skip = missing_frames(num_frames, missing)
    (out / "images").mkdir(parents=True, exist_ok=True)
    frames = []
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small per-tile work: one thread is faster on a busy CPU
    try:
        for idx, eye in enumerate(hemisphere_positions(num_frames, 0.5)):
            viewmat = look_at(eye)
            name = f"images/frame_{idx + 1:05d}.jpg"
            (out / name).unlink(missing_ok=True)
            if idx not in skip:
                image = render_distorted(gaussians, viewmat, lens, canvas, maps)
                Image.fromarray(image).save(out / name, quality=95)
            frames.append({"file_path": name, "transform_matrix": (torch.linalg.inv(viewmat) @ GL_TO_CV).tolist()})
    finally:
        torch.set_num_threads(threads)
    write_json(out / "transforms.json", {
        "camera_model": "OPENCV", "fl_x": lens.fx, "fl_y": lens.fy, "cx": lens.cx, "cy": lens.cy, "w": width,
        "h": height, **dict(zip(("k1", "k2", "p1", "p2"), lens.dist)), "aabb_scale": 16, "frames": frames})
    write_json(stamp, params)
    return out


def main() -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out_dir", help="where to write the capture")
    parser.add_argument("--width", type=int, default=1080)
    parser.add_argument("--height", type=int, default=1920)
    parser.add_argument("--frames", type=int, default=20, help="frames listed in transforms.json")
    parser.add_argument("--missing", type=int, default=3, help="listed frames whose image is not written")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    out = make_phone_capture(args.out_dir, args.width, args.height, args.frames, args.missing, args.seed)
    print(f"phone capture ready in {out}")


if __name__ == "__main__":
    run_cli(main)
