"""Dataset loaders: Blender/NeRF-synthetic (`transforms_train.json`), nerfstudio / instant-ngp (`transforms.json`)
and COLMAP (`sparse/0`), with clear errors.

All produce a `SceneInfo` whose cameras are pinhole cameras in the OpenCV convention (world-to-camera, x right,
y down, z forward), distorted lenses undistorted once (scene/lens.py, cached beside the dataset), with images
composited on the background and resampled to the requested `resolution`.
"""
from __future__ import annotations

import logging
from pathlib import Path

import torch

from scene import colmap_io
from scene.frames import (GL_TO_CV, LLFFHOLD, CameraLoader, Frame, PointCloud, SceneInfo, drop_missing, held_out,
                          image_size, load_composited, scene_extent, stored_scale, target_size)
from scene.transforms_json import frame_lens, frame_pose, read_nerfstudio, read_transforms_file
from utils.errors import UserError

__all__ = ["GL_TO_CV", "PointCloud", "SceneInfo", "load_composited", "load_scene_info", "scene_extent",
           "target_size"]

log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------------------------- Blender


def read_blender(source: Path, white_background: bool, resolution: int, skip_missing: bool = False,
                 ignore_distortion: bool = False) -> SceneInfo:
    """Cameras of `transforms_train.json` and (when present) `transforms_test.json`."""
    splits = [("train", read_transforms_file(source / "transforms_train.json"))]
    if (source / "transforms_test.json").is_file():
        splits.append(("test", read_transforms_file(source / "transforms_test.json")))
    listed = []  # (split, frame, file entry, file data)
    for split, data in splits:
        for idx, entry in enumerate(data["frames"]):
            listed.append((split, frame_pose(source, entry, f"transforms_{split}.json frame {idx}"), entry, data))
    kept, dropped = drop_missing([f for _, f, _, _ in listed], skip_missing, source)
    kept_ids = {id(f) for f in kept}
    loader = CameraLoader(source, resolution, torch.ones(3) if white_background else torch.zeros(3),
                          ignore_distortion)
    cameras: dict[str, list] = {"train": [], "test": []}
    first: tuple[str, tuple[int, int]] | None = None  # (image, size) of the first frame, for the size check
    uid = 0
    for split, frame, entry, data in listed:
        if id(frame) not in kept_ids:
            continue
        full = image_size(frame.path, frame.where)
        if first is None:
            first = (frame.path.name, full)
        elif full != first[1]:
            raise UserError(f"{frame.where}: image {frame.path.name} is {full[0]}x{full[1]} but {first[0]} is "
                            f"{first[1][0]}x{first[1][1]}; all images of a dataset must have one size")
        lens = frame_lens(data, entry, full[0], full[1], frame.where, frame.path.name)
        cameras[split].append(loader.camera(uid, frame, lens, full))
        uid += 1
    if not cameras["train"]:
        raise UserError("transforms_train.json: none of its images exists; check the dataset")
    return SceneInfo(cameras["train"], cameras["test"], None, scene_extent(cameras["train"]), "blender", dropped)


# ----------------------------------------------------------------------------------------------- COLMAP


def read_colmap(source: Path, images: str, resolution: int, eval: bool, llffhold: int, skip_missing: bool = False,
                ignore_distortion: bool = False) -> SceneInfo:
    """Cameras from `sparse/0` and images from `source/images`; every `llffhold`-th image is test under `eval`.

    The split is made on the listed images (sorted by name) before missing ones are dropped.
    """
    if eval and llffhold < 2:
        raise UserError(f"--llffhold must be at least 2 (every N-th image is held out), got {llffhold}")
    sparse = source / "sparse" / "0"
    cams, imgs, (xyz, rgb) = colmap_io.read_model(sparse)
    image_dir = source / images
    if not image_dir.is_dir():
        raise UserError(f"COLMAP images folder {image_dir} does not exist; pass --images with the folder name")
    if not imgs:
        raise UserError(f"COLMAP model in {sparse} has no images")
    listed = []  # (frame, COLMAP camera)
    for im in sorted(imgs.values(), key=lambda i: i.name):
        where = f"COLMAP image {im.name}"
        cam = cams.get(im.camera_id)
        if cam is None:
            raise UserError(f"{where} refers to camera {im.camera_id}, which is not in the cameras file")
        viewmat = torch.eye(4, dtype=torch.float64)
        viewmat[:3, :3] = torch.from_numpy(colmap_io.qvec_to_rotmat(im.qvec))
        viewmat[:3, 3] = torch.from_numpy(im.tvec)
        listed.append((Frame(where, image_dir / im.name, viewmat), cam))
    test_ids = {id(f) for i, (f, _) in enumerate(listed) if eval and held_out(i, llffhold)}
    kept, dropped = drop_missing([f for f, _ in listed], skip_missing, image_dir)
    camera_of = {id(f): cam for f, cam in listed}
    loader = CameraLoader(source, resolution, torch.zeros(3), ignore_distortion)
    train, test = [], []
    for uid, frame in enumerate(kept):
        lens = colmap_io.camera_lens(camera_of[id(frame)])
        # The images may be stored smaller than the calibration (e.g. an images_4 folder): scale to the file.
        full = image_size(frame.path, frame.where)
        stored_scale(lens.width, lens.height, full[0], full[1], frame.where, frame.path.name)
        camera = loader.camera(uid, frame, lens.scaled(*full), full)
        (test if id(frame) in test_ids else train).append(camera)
    if not train:
        raise UserError(f"COLMAP model in {sparse}: no training images are left; add images or train without --eval")
    pcd = PointCloud(torch.from_numpy(xyz).float(), torch.from_numpy(rgb).float() / 255.0) if len(xyz) else None
    return SceneInfo(train, test, pcd, scene_extent(train), "colmap", dropped)


# ----------------------------------------------------------------------------------------------- entry


def load_scene_info(source_path: str, *, white_background: bool = False, resolution: int = -1, eval: bool = False,
                    images: str = "images", llffhold: int = LLFFHOLD, device: str = "cpu",
                    skip_missing_images: bool = False, ignore_distortion: bool = False) -> SceneInfo:
    """Detect the dataset layout (Blender, nerfstudio / instant-ngp or COLMAP) and load it.

    Args:
        source_path: dataset root holding `transforms_train.json`, `transforms.json` or `sparse/0/`.
        white_background: composite RGBA images on white (else black).
        resolution: -1/1 as is, 2/4/8 downscale factor, other positive values a target width in pixels.
        eval: COLMAP and transforms.json: hold out every `llffhold`-th image (sorted by name) as test
            (Blender: transforms_test.json is always the test split).
        images: COLMAP image folder name under `source_path`.
        device: where the cameras' tensors and the point cloud go.
        skip_missing_images: drop listed frames whose image file is missing (else an error lists them).
        ignore_distortion: treat distorted lenses as pinholes (no undistortion; for comparisons).
    Every problem with the input is a one-line `UserError`.
    """
    source = Path(source_path)
    if not source_path or not source.exists():
        raise UserError(f"dataset path {source_path!r} does not exist; pass -s/--source_path with a Blender, "
                        "nerfstudio or COLMAP dataset (or make the built-in one: python -m scene.builtin data/builtin)")
    if not source.is_dir() or not any(source.iterdir()):
        raise UserError(f"dataset path {source} is empty or not a directory; point -s at a dataset root")
    target_size(100, 100, resolution)  # validates the flag before any image is read
    if (source / "transforms_train.json").is_file():
        info = read_blender(source, white_background, resolution, skip_missing_images, ignore_distortion)
    elif (source / "transforms.json").is_file():
        info = read_nerfstudio(source, white_background, resolution, eval, llffhold, skip_missing_images,
                               ignore_distortion)
    elif (source / "sparse" / "0").is_dir():
        info = read_colmap(source, images, resolution, eval, llffhold, skip_missing_images, ignore_distortion)
    else:
        raise UserError(f"{source} is neither a Blender dataset (transforms_train.json), a nerfstudio / instant-ngp "
                        "one (transforms.json) nor a COLMAP one (sparse/0/cameras.bin|txt); point -s at the "
                        "dataset root")
    info.train_cameras = [c.to(device) for c in info.train_cameras]
    info.test_cameras = [c.to(device) for c in info.test_cameras]
    if info.point_cloud is not None:
        info.point_cloud = PointCloud(info.point_cloud.points.to(device), info.point_cloud.colors.to(device))
    return info
