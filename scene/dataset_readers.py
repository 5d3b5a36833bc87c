"""Dataset loaders: Blender/NeRF-synthetic (`transforms_*.json`) and COLMAP (`sparse/0`), with clear errors."""
from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from scene import colmap_io
from scene.cameras import Camera
from utils.errors import UserError

log = logging.getLogger(__name__)

# OpenGL/Blender camera axes (x right, y up, z back) -> OpenCV (x right, y down, z forward).
_GL_TO_CV = torch.diag(torch.tensor([1.0, -1.0, -1.0, 1.0], dtype=torch.float64))


@dataclass
class PointCloud:
    points: torch.Tensor  # [P, 3]
    colors: torch.Tensor  # [P, 3] in [0, 1]


@dataclass
class SceneInfo:
    train_cameras: list[Camera]
    test_cameras: list[Camera]
    point_cloud: PointCloud | None
    scene_extent: float
    kind: str  # "blender" | "colmap"


def target_size(width: int, height: int, resolution: int) -> tuple[int, int]:
    """Image size for `--resolution`: -1/1 as is, 2/4/8 a downscale factor, any other positive value a width."""
    if resolution in (-1, 1):
        return width, height
    if resolution <= 0:
        raise UserError(f"--resolution must be -1, a factor 1/2/4/8 or a target width > 0; got {resolution}")
    if resolution in (2, 4, 8):
        return max(1, round(width / resolution)), max(1, round(height / resolution))
    return resolution, max(1, round(height * resolution / width))


def _load_image(path: Path, size: tuple[int, int], background: torch.Tensor, where: str) -> tuple[torch.Tensor, tuple]:
    """RGB(A) image resized to `size` with box filtering and composited on `background`. [3, H, W]"""
    if not path.is_file():
        raise UserError(f"{where}: image file {path} is missing")
    try:
        with Image.open(path) as im:
            original = im.size
            rgba = im.convert("RGBA").resize(size, Image.Resampling.BOX) if im.size != size else im.convert("RGBA")
            arr = np.asarray(rgba, dtype=np.float32) / 255.0
    except OSError as exc:
        raise UserError(f"{where}: cannot read image {path} ({exc})") from None
    t = torch.from_numpy(arr).permute(2, 0, 1)
    rgb, alpha = t[:3], t[3:4]
    return rgb * alpha + background[:, None, None] * (1 - alpha), original


def scene_extent(cameras: list[Camera]) -> float:
    """3DGS 'nerf normalization': 1.1 x the largest distance of a camera centre from their mean."""
    centers = torch.stack([c.camera_center.double() for c in cameras])
    return float(1.1 * (centers - centers.mean(0)).norm(dim=1).max().clamp_min(1e-6))


# ----------------------------------------------------------------------------------------------- Blender


def _read_transforms(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except ValueError as exc:
        raise UserError(f"{path} is not valid JSON ({exc}); fix or regenerate it") from None
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise UserError(f"{path}: missing key 'frames' (a list of frames with file_path and transform_matrix)")
    return data


def _blender_cameras(source: Path, split: str, background: torch.Tensor, resolution: int,
                     uid_offset: int) -> list[Camera]:
    path = source / f"transforms_{split}.json"
    data = _read_transforms(path)
    cameras: list[Camera] = []
    first_size = None
    for idx, frame in enumerate(data["frames"]):
        where = f"{path.name} frame {idx}"
        if not isinstance(frame, dict) or "file_path" not in frame or "transform_matrix" not in frame:
            raise UserError(f"{where}: needs 'file_path' and 'transform_matrix'")
        try:
            c2w = torch.tensor(frame["transform_matrix"], dtype=torch.float64)
        except (TypeError, ValueError):
            raise UserError(f"{where}: 'transform_matrix' is not a 4x4 list of numbers") from None
        if c2w.shape != (4, 4) or not torch.isfinite(c2w).all():
            raise UserError(f"{where}: 'transform_matrix' must be a finite 4x4 matrix, got shape {tuple(c2w.shape)}")
        file_path = source / frame["file_path"]
        if file_path.suffix.lower() not in (".png", ".jpg", ".jpeg"):
            file_path = file_path.with_name(file_path.name + ".png")
        if not file_path.is_file():
            raise UserError(f"{where}: image file {file_path} is missing")
        with Image.open(file_path) as im:
            full_w, full_h = im.size
        if first_size is None:
            first_size = (full_w, full_h)
        elif (full_w, full_h) != first_size:
            raise UserError(f"{where}: image {file_path.name} is {full_w}x{full_h} but earlier images are "
                            f"{first_size[0]}x{first_size[1]}; all images of a split must have one size")
        w, h = target_size(full_w, full_h, resolution)
        fx, fy, cx, cy = _blender_intrinsics(data, frame, full_w, full_h, where)
        sx, sy = w / full_w, h / full_h
        image, _ = _load_image(file_path, (w, h), background, where)
        viewmat = torch.linalg.inv(c2w @ _GL_TO_CV).float()
        cameras.append(Camera(uid_offset + idx, file_path.stem, viewmat, fx * sx, fy * sy, cx * sx, cy * sy, w, h,
                              image))
    if not cameras:
        raise UserError(f"{path} has no frames")
    return cameras


def _blender_intrinsics(data: dict, frame: dict, width: int, height: int, where: str):
    get = lambda key: frame.get(key, data.get(key))
    fl_x, fl_y = get("fl_x"), get("fl_y")
    if fl_x is None:
        angle = get("camera_angle_x")
        if angle is None:
            raise UserError(f"{where}: needs 'camera_angle_x' or 'fl_x' (focal length)")
        fl_x = 0.5 * width / math.tan(0.5 * float(angle))
    fl_y = fl_x if fl_y is None else fl_y
    cx, cy = get("cx"), get("cy")
    return float(fl_x), float(fl_y), float(width / 2 if cx is None else cx), float(height / 2 if cy is None else cy)


def read_blender(source: Path, white_background: bool, resolution: int) -> SceneInfo:
    background = torch.ones(3) if white_background else torch.zeros(3)
    train = _blender_cameras(source, "train", background, resolution, 0)
    test = (_blender_cameras(source, "test", background, resolution, len(train))
            if (source / "transforms_test.json").is_file() else [])
    return SceneInfo(train, test, None, scene_extent(train), "blender")


# ----------------------------------------------------------------------------------------------- COLMAP


def read_colmap(source: Path, images: str, resolution: int, eval: bool, llffhold: int) -> SceneInfo:
    cams, imgs, (xyz, rgb) = colmap_io.read_model(source / "sparse" / "0")
    image_dir = source / images
    cameras: list[Camera] = []
    warned = False
    for idx, im in enumerate(sorted(imgs.values(), key=lambda i: i.name)):
        cam = cams.get(im.camera_id)
        if cam is None:
            raise UserError(f"COLMAP image {im.name} refers to camera {im.camera_id}, which is not in cameras")
        fx, fy, cx, cy, distorted = colmap_io.pinhole_intrinsics(cam)
        if distorted and not warned:
            log.warning("COLMAP camera model %s has distortion; treating it as a pinhole (undistort for accuracy)",
                        cam.model)
            warned = True
        w, h = target_size(cam.width, cam.height, resolution)
        image, original = _load_image(image_dir / im.name, (w, h), torch.zeros(3), f"COLMAP image {im.name}")
        sx, sy = w / original[0], h / original[1]
        scale_x, scale_y = original[0] / cam.width, original[1] / cam.height  # images may be pre-downscaled
        viewmat = torch.eye(4, dtype=torch.float64)
        viewmat[:3, :3] = torch.from_numpy(colmap_io.qvec_to_rotmat(im.qvec))
        viewmat[:3, 3] = torch.from_numpy(im.tvec)
        cameras.append(Camera(idx, Path(im.name).stem, viewmat.float(), fx * scale_x * sx, fy * scale_y * sy,
                              cx * scale_x * sx, cy * scale_y * sy, w, h, image))
    if not cameras:
        raise UserError(f"COLMAP model in {source / 'sparse' / '0'} has no images")
    if eval:
        train = [c for i, c in enumerate(cameras) if i % llffhold != 0]
        test = [c for i, c in enumerate(cameras) if i % llffhold == 0]
    else:
        train, test = cameras, []
    pcd = PointCloud(torch.from_numpy(xyz).float(), torch.from_numpy(rgb).float() / 255.0) if len(xyz) else None
    return SceneInfo(train, test, pcd, scene_extent(train), "colmap")


# ----------------------------------------------------------------------------------------------- entry


def load_scene_info(source_path: str, *, white_background: bool = False, resolution: int = -1, eval: bool = False,
                    images: str = "images", llffhold: int = 8, device: str = "cpu") -> SceneInfo:
    """Detect the dataset layout and load it; every problem is a one-line `UserError`."""
    source = Path(source_path)
    if not source_path or not source.exists():
        raise UserError(f"dataset path {source_path!r} does not exist; pass -s/--source_path with a Blender or "
                        "COLMAP dataset (or make the built-in one: python -m scene.builtin data/builtin)")
    if not source.is_dir() or not any(source.iterdir()):
        raise UserError(f"dataset path {source} is empty or not a directory")
    if resolution != -1:
        target_size(100, 100, resolution)  # validates the flag before any image is read
    if (source / "transforms_train.json").is_file():
        info = read_blender(source, white_background, resolution)
    elif (source / "sparse" / "0").is_dir():
        info = read_colmap(source, images, resolution, eval, llffhold)
    else:
        raise UserError(f"{source} is neither a Blender dataset (transforms_train.json) nor a COLMAP one "
                        "(sparse/0/cameras.bin|txt); point -s at the dataset root")
    if device != "cpu":
        info.train_cameras = [c.to(device) for c in info.train_cameras]
        info.test_cameras = [c.to(device) for c in info.test_cameras]
    return info
