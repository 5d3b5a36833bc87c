"""Transforms files: the shared parsing of `transforms_*.json` (Blender / NeRF-synthetic) and the reader of a
nerfstudio / instant-ngp `transforms.json` (one file for all frames, e.g. a phone capture).

Both list frames with a `file_path` and a camera-to-world `transform_matrix` in OpenGL axes (x right, y up, z back)
and intrinsics at file level, overridable per frame: `fl_x`/`fl_y`/`cx`/`cy` in the pixels of `w` x `h`, or
`camera_angle_x`. A nerfstudio file may add `camera_model` (OPENCV, the default, or OPENCV_FISHEYE) with `k1 k2 k3 k4
p1 p2`, and `ply_file_path` (initial points; `sparse_pc.ply` beside the file is used when present).
"""
from __future__ import annotations

import logging
import math
from pathlib import Path

import torch

from scene.frames import (GL_TO_CV, IMAGE_SUFFIXES, CameraLoader, Frame, PointCloud, SceneInfo, drop_missing,
                          held_out, image_size, scene_extent, stored_scale)
from scene.lens import LENS_MODELS, Lens
from scene.pose_check import checked_c2w
from scene.ply_io import load_points_ply
from utils.errors import UserError
from utils.io import read_json

log = logging.getLogger(__name__)

DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")


def read_transforms_file(path: Path) -> dict:
    """The parsed file, checked to hold a non-empty 'frames' list."""
    data = read_json(path, fix="fix or regenerate it")
    if not isinstance(data.get("frames"), list):
        raise UserError(f"{path}: missing key 'frames' (a list of frames with file_path and transform_matrix)")
    if not data["frames"]:
        raise UserError(f"{path}: 'frames' is empty; the split needs at least one frame")
    return data


def image_path(source: Path, file_path: str) -> Path:
    """The image of a frame: `file_path` as given if it exists, else with `.png` appended (NeRF-synthetic)."""
    given = source / file_path
    if given.is_file() or given.suffix.lower() in IMAGE_SUFFIXES:
        return given
    return given.with_name(given.name + ".png")


def _number(value, key: str, where: str, positive: bool) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise UserError(f"{where}: '{key}' must be a number, got {value!r}") from None
    if not math.isfinite(out) or (positive and out <= 0):
        raise UserError(f"{where}: '{key}' must be a finite{' positive' if positive else ''} number, got {value!r}")
    return out


def frame_pose(source: Path, frame, where: str) -> Frame:
    """The `Frame` of one entry of 'frames' (image path, world-to-camera in OpenCV axes); `where` is "FILE frame i",
    FILE relative to `source`."""
    if not isinstance(frame, dict) or "file_path" not in frame or "transform_matrix" not in frame:
        raise UserError(f"{where}: needs 'file_path' and 'transform_matrix'")
    if not isinstance(frame["file_path"], str):
        raise UserError(f"{where}: 'file_path' must be a string, got {frame['file_path']!r}")
    # the pose rule of every reader (scene.pose_check), its messages naming the file by its path as recommend.py does
    c2w = checked_c2w(frame["transform_matrix"], f"{source / where}")  # [4, 4], OpenGL axes
    return Frame(where, image_path(source, frame["file_path"]), torch.linalg.inv(c2w @ GL_TO_CV))


def frame_lens(data: dict, frame: dict, width: int, height: int, where: str, name: str) -> Lens:
    """The lens of a frame whose image file is `width` x `height`; per-frame keys override the file's.

    Focal lengths and principal points given with `w`/`h` are in those pixels and are scaled to the image when
    it is a clean multiple of them (else a UserError naming the frame).
    """
    def get(key, positive=True):
        value = frame.get(key, data.get(key))
        return None if value is None else _number(value, key, where, positive)

    declared_w, declared_h = get("w") or width, get("h") or height
    fl_x, fl_y = get("fl_x"), get("fl_y")
    if fl_x is None:
        angle = get("camera_angle_x")
        if angle is None:
            raise UserError(f"{where}: needs 'camera_angle_x' or 'fl_x' (the focal length); the file has no "
                            "intrinsics")
        fl_x = 0.5 * declared_w / math.tan(0.5 * angle)
    fl_y = fl_x if fl_y is None else fl_y
    cx, cy = get("cx", False), get("cy", False)
    cx = declared_w / 2 if cx is None else cx
    cy = declared_h / 2 if cy is None else cy
    sx, sy = stored_scale(declared_w, declared_h, width, height, where, name)
    model = frame.get("camera_model", data.get("camera_model", "OPENCV"))
    if model not in LENS_MODELS:
        raise UserError(f"{where}: unknown camera_model {model!r}; supported: {', '.join(LENS_MODELS)} "
                        "(undistort the images first for other models)")
    k1, k2, k3, k4, p1, p2 = (get(k, False) or 0.0 for k in DISTORTION_KEYS)
    if model == "OPENCV_FISHEYE":
        if p1 or p2:
            raise UserError(f"{where}: OPENCV_FISHEYE has no tangential terms, but p1/p2 are {p1}, {p2}")
        dist = (k1, k2, k3, k4)
    elif k4:  # nerfstudio's OPENCV with k4: OpenCV's 8-term rational order, as nerfstudio undistorts it
        dist = (k1, k2, p1, p2, k3, k4, 0.0, 0.0)
    else:
        dist = (k1, k2, p1, p2) + ((k3,) if k3 else ())
    return Lens(width, height, fl_x * sx, fl_y * sy, cx * sx, cy * sy, model,
                dist if any(dist) else ())


def read_points(source: Path, data: dict) -> PointCloud | None:
    """Initial points from `ply_file_path` (relative to the dataset), else `sparse_pc.ply`, else None."""
    rel = data.get("ply_file_path")
    if rel is not None:
        if not isinstance(rel, str) or not (source / rel).is_file():
            raise UserError(f"transforms.json: ply_file_path {rel!r} does not exist under {source}; fix the path "
                            "or remove the key to start from random points")
        path = source / rel
    elif (source / "sparse_pc.ply").is_file():
        path = source / "sparse_pc.ply"
    else:
        return None
    xyz, rgb = load_points_ply(path)
    log.info("initial points: %d from %s", len(xyz), path.name)
    return PointCloud(torch.from_numpy(xyz).float(), torch.from_numpy(rgb).float() / 255.0)


def read_nerfstudio(source: Path, white_background: bool, resolution: int, eval: bool, llffhold: int,
                    skip_missing: bool = False, ignore_distortion: bool = False) -> SceneInfo:
    """Cameras of `transforms.json` sorted by file path; under `eval` every `llffhold`-th is a test view.

    The split is made on the listed frames, before missing ones are dropped, so a missing image never moves
    another frame between train and test.
    """
    if eval and llffhold < 2:
        raise UserError(f"--llffhold must be at least 2 (every N-th image is held out), got {llffhold}")
    data = read_transforms_file(source / "transforms.json")
    if "aabb_scale" in data:
        log.info("transforms.json: aabb_scale %s ignored (instant-ngp's ray-marching bound; not used by 3DGS)",
                 data["aabb_scale"])
    listed = [(frame_pose(source, fr, f"transforms.json frame {i}"), fr) for i, fr in enumerate(data["frames"])]
    listed.sort(key=lambda item: item[1]["file_path"])
    test_ids = {id(f) for i, (f, _) in enumerate(listed) if eval and held_out(i, llffhold)}
    kept, dropped = drop_missing([f for f, _ in listed], skip_missing, source)
    entry = {id(f): fr for f, fr in listed}
    loader = CameraLoader(source, resolution, torch.ones(3) if white_background else torch.zeros(3),
                          ignore_distortion)
    train, test = [], []
    for uid, frame in enumerate(kept):
        size = image_size(frame.path, frame.where)
        lens = frame_lens(data, entry[id(frame)], size[0], size[1], frame.where, frame.path.name)
        (test if id(frame) in test_ids else train).append(loader.camera(uid, frame, lens, size))
    if not train:
        raise UserError(f"transforms.json: no training frames are left (all {len(kept)} frames are test views); "
                        "add frames or train without --eval")
    return SceneInfo(train, test, read_points(source, data), scene_extent(train), "transforms", dropped)
