"""Dataset loaders: Blender/NeRF-synthetic (`transforms_*.json`) and COLMAP (`sparse/0`), with clear errors.

Both produce a `SceneInfo` whose cameras are in the OpenCV convention (world-to-camera, x right, y down,
z forward) with images composited on the background and resampled to the requested `resolution`.
"""
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

# OpenGL/Blender camera axes (x right, y up, z back) -> OpenCV (x right, y down, z forward): flip y and z.
GL_TO_CV = torch.diag(torch.tensor([1.0, -1.0, -1.0, 1.0], dtype=torch.float64))
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


@dataclass
class PointCloud:
    """Initial points (SfM or random) with colours."""

    points: torch.Tensor  # [P, 3]
    colors: torch.Tensor  # [P, 3] in [0, 1]


@dataclass
class SceneInfo:
    """Everything a dataset provides: cameras, optional SfM points, the normalisation extent."""

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


def load_composited(path: Path, size: tuple[int, int], background: torch.Tensor) -> torch.Tensor:
    """An image file resized to `size` (box filter, alpha-aware) and composited on `background` [3]. [3, H, W]"""
    with Image.open(path) as im:
        rgba = im.convert("RGBA")
    if rgba.size != size:
        rgba = rgba.resize(size, Image.Resampling.BOX)  # Pillow resamples RGBA premultiplied by alpha
    t = torch.from_numpy(np.asarray(rgba, dtype=np.float32) / 255.0).permute(2, 0, 1)  # [4, H, W]
    rgb, alpha = t[:3], t[3:4]
    return (rgb * alpha + background[:, None, None] * (1 - alpha)).contiguous()


def _image_size(path: Path, where: str) -> tuple[int, int]:
    """(width, height) of an image file, or a UserError naming `where` and the file."""
    if not path.is_file():
        raise UserError(f"{where}: image file {path} is missing")
    try:
        with Image.open(path) as im:
            return im.size
    except OSError as exc:
        raise UserError(f"{where}: cannot read image {path} ({exc}); replace the file") from None


def scene_extent(cameras: list[Camera]) -> float:
    """3DGS 'nerf normalization': 1.1 x the largest distance of a camera centre from their mean."""
    centers = torch.stack([c.camera_center.double().cpu() for c in cameras])  # [C, 3]
    return float(1.1 * (centers - centers.mean(0)).norm(dim=1).max().clamp_min(1e-6))


# ----------------------------------------------------------------------------------------------- Blender


def _read_transforms(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except ValueError as exc:
        raise UserError(f"{path} is not valid JSON ({exc}); fix or regenerate it") from None
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise UserError(f"{path}: missing key 'frames' (a list of frames with file_path and transform_matrix)")
    if not data["frames"]:
        raise UserError(f"{path}: 'frames' is empty; the split needs at least one frame")
    return data


def _blender_image_path(source: Path, file_path: str) -> Path:
    """The image of a frame: `file_path` as given if it exists, else with `.png` appended (NeRF-synthetic)."""
    given = source / file_path
    if given.is_file() or given.suffix.lower() in IMAGE_SUFFIXES:
        return given
    return given.with_name(given.name + ".png")


def _number(value, key: str, where: str) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise UserError(f"{where}: '{key}' must be a number, got {value!r}") from None
    if not math.isfinite(out) or (out <= 0 and key not in ("cx", "cy")):
        raise UserError(f"{where}: '{key}' must be a finite positive number, got {value!r}")
    return out


def _blender_intrinsics(data: dict, frame: dict, width: int, height: int, where: str
                        ) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) for an image of `width` x `height`; per-frame keys override the file's.

    Focal lengths and principal points given with `w`/`h` are in those pixels and are scaled to the image.
    """
    def get(key):
        value = frame.get(key, data.get(key))
        return None if value is None else _number(value, key, where)

    declared_w, declared_h = get("w") or width, get("h") or height
    fl_x, fl_y = get("fl_x"), get("fl_y")
    if fl_x is None:
        angle = get("camera_angle_x")
        if angle is None:
            raise UserError(f"{where}: needs 'camera_angle_x' or 'fl_x' (the focal length)")
        fl_x = 0.5 * declared_w / math.tan(0.5 * angle)
    fl_y = fl_x if fl_y is None else fl_y
    cx, cy = get("cx"), get("cy")
    cx = declared_w / 2 if cx is None else cx
    cy = declared_h / 2 if cy is None else cy
    sx, sy = width / declared_w, height / declared_h
    return fl_x * sx, fl_y * sy, cx * sx, cy * sy


def _blender_c2w(frame: dict, where: str) -> torch.Tensor:
    """The frame's camera-to-world matrix (Blender axes). [4, 4] float64"""
    try:
        c2w = torch.tensor(frame["transform_matrix"], dtype=torch.float64)
    except (TypeError, ValueError):
        raise UserError(f"{where}: 'transform_matrix' is not a 4x4 list of numbers") from None
    if c2w.shape != (4, 4):
        raise UserError(f"{where}: 'transform_matrix' must be a 4x4 matrix, got shape {tuple(c2w.shape)}")
    if not torch.isfinite(c2w).all():
        row, col = (int(i) for i in torch.nonzero(~torch.isfinite(c2w))[0])
        raise UserError(f"{where}: 'transform_matrix' holds a non-finite value ({float(c2w[row, col])}) at row {row}, "
                        f"column {col}; fix the pose")
    if abs(float(torch.linalg.det(c2w[:3, :3]))) < 1e-9:
        raise UserError(f"{where}: 'transform_matrix' has a singular rotation part; fix the pose")
    return c2w


def read_blender(source: Path, white_background: bool, resolution: int) -> SceneInfo:
    """Cameras of `transforms_train.json` and (when present) `transforms_test.json`."""
    background = torch.ones(3) if white_background else torch.zeros(3)
    splits = [("train", _read_transforms(source / "transforms_train.json"))]
    if (source / "transforms_test.json").is_file():
        splits.append(("test", _read_transforms(source / "transforms_test.json")))
    cameras: dict[str, list[Camera]] = {"train": [], "test": []}
    first: tuple[str, tuple[int, int]] | None = None  # (image, size) of the first frame, for the size check
    uid = 0
    for split, data in splits:
        for idx, frame in enumerate(data["frames"]):
            where = f"transforms_{split}.json frame {idx}"
            if not isinstance(frame, dict) or "file_path" not in frame or "transform_matrix" not in frame:
                raise UserError(f"{where}: needs 'file_path' and 'transform_matrix'")
            if not isinstance(frame["file_path"], str):
                raise UserError(f"{where}: 'file_path' must be a string, got {frame['file_path']!r}")
            c2w = _blender_c2w(frame, where)
            path = _blender_image_path(source, frame["file_path"])
            full = _image_size(path, where)
            if first is None:
                first = (path.name, full)
            elif full != first[1]:
                raise UserError(f"{where}: image {path.name} is {full[0]}x{full[1]} but {first[0]} is "
                                f"{first[1][0]}x{first[1][1]}; all images of a dataset must have one size")
            fx, fy, cx, cy = _blender_intrinsics(data, frame, full[0], full[1], where)
            w, h = target_size(full[0], full[1], resolution)
            sx, sy = w / full[0], h / full[1]
            viewmat = torch.linalg.inv(c2w @ GL_TO_CV).float()
            image = load_composited(path, (w, h), background)
            cameras[split].append(Camera(uid, path.stem, viewmat, fx * sx, fy * sy, cx * sx, cy * sy, w, h, image))
            uid += 1
    return SceneInfo(cameras["train"], cameras["test"], None, scene_extent(cameras["train"]), "blender")


# ----------------------------------------------------------------------------------------------- COLMAP


def read_colmap(source: Path, images: str, resolution: int, eval: bool, llffhold: int) -> SceneInfo:
    """Cameras from `sparse/0` and images from `source/images`; every `llffhold`-th image is test under `eval`."""
    if eval and llffhold < 2:
        raise UserError(f"--llffhold must be at least 2 (every N-th image is held out), got {llffhold}")
    sparse = source / "sparse" / "0"
    cams, imgs, (xyz, rgb) = colmap_io.read_model(sparse)
    image_dir = source / images
    if not image_dir.is_dir():
        raise UserError(f"COLMAP images folder {image_dir} does not exist; pass --images with the folder name")
    if not imgs:
        raise UserError(f"COLMAP model in {sparse} has no images")
    cameras: list[Camera] = []
    warned = False  # one distortion warning per dataset
    for idx, im in enumerate(sorted(imgs.values(), key=lambda i: i.name)):
        where = f"COLMAP image {im.name}"
        cam = cams.get(im.camera_id)
        if cam is None:
            raise UserError(f"{where} refers to camera {im.camera_id}, which is not in the cameras file")
        fx, fy, cx, cy, distorted = colmap_io.pinhole_intrinsics(cam)
        if distorted and not warned:
            log.warning("COLMAP camera model %s has lens distortion; treating it as a pinhole "
                        "(undistort the images with COLMAP for accuracy)", cam.model)
            warned = True
        path = image_dir / im.name
        full = _image_size(path, where)
        # The images may be stored smaller than the calibration (e.g. an images_4 folder): scale to the file.
        w, h = target_size(full[0], full[1], resolution)
        sx, sy = w / cam.width, h / cam.height
        viewmat = torch.eye(4, dtype=torch.float64)
        viewmat[:3, :3] = torch.from_numpy(colmap_io.qvec_to_rotmat(im.qvec))
        viewmat[:3, 3] = torch.from_numpy(im.tvec)
        image = load_composited(path, (w, h), torch.zeros(3))
        cameras.append(Camera(idx, Path(im.name).stem, viewmat.float(), fx * sx, fy * sy, cx * sx, cy * sy, w, h,
                              image))
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
    """Detect the dataset layout (Blender or COLMAP) and load it.

    Args:
        source_path: dataset root holding `transforms_train.json` or `sparse/0/`.
        white_background: composite RGBA images on white (else black).
        resolution: -1/1 as is, 2/4/8 downscale factor, other positive values a target width in pixels.
        eval: COLMAP only: hold out every `llffhold`-th image (sorted by name) as test.
        images: COLMAP image folder name under `source_path`.
        device: where the cameras' tensors and the point cloud go.
    Every problem with the input is a one-line `UserError`.
    """
    source = Path(source_path)
    if not source_path or not source.exists():
        raise UserError(f"dataset path {source_path!r} does not exist; pass -s/--source_path with a Blender or "
                        "COLMAP dataset (or make the built-in one: python -m scene.builtin data/builtin)")
    if not source.is_dir() or not any(source.iterdir()):
        raise UserError(f"dataset path {source} is empty or not a directory; point -s at a dataset root")
    target_size(100, 100, resolution)  # validates the flag before any image is read
    if (source / "transforms_train.json").is_file():
        info = read_blender(source, white_background, resolution)
    elif (source / "sparse" / "0").is_dir():
        info = read_colmap(source, images, resolution, eval, llffhold)
    else:
        raise UserError(f"{source} is neither a Blender dataset (transforms_train.json) nor a COLMAP one "
                        "(sparse/0/cameras.bin|txt); point -s at the dataset root")
    info.train_cameras = [c.to(device) for c in info.train_cameras]
    info.test_cameras = [c.to(device) for c in info.test_cameras]
    if info.point_cloud is not None:
        info.point_cloud = PointCloud(info.point_cloud.points.to(device), info.point_cloud.colors.to(device))
    return info
