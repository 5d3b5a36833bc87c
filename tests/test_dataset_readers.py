"""Blender loader: poses and pixels against hand-written closed forms, resolution handling, bad inputs."""
from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from scene.dataset_readers import load_scene_info, target_size
from utils.errors import UserError

W, H = 40, 20
ANGLE_X = 2 * math.atan(0.5)  # fx = 0.5 W / tan(angle / 2) = W = 40 px

# Blender camera-to-world matrices written by hand (columns: camera right, up, back; last column: centre).
# Camera A on +z looking at the origin with +y up.
C2W_A = [[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5], [0, 0, 0, 1]]
# Camera B on +x looking at the origin with +z up: right = +y, up = +z, back = +x.
C2W_B = [[0.0, 0, 1, 5], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1]]


def rgba_image(seed: int, size=(W, H)) -> np.ndarray:
    """Random RGBA uint8 pixels with alpha >= 128. [H, W, 4]"""
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 256, (size[1], size[0], 4), dtype=np.uint8)
    img[..., 3] = rng.integers(128, 256, (size[1], size[0]))
    return img


def write_blender(root: Path, train=(C2W_A, C2W_B), test=(C2W_B,), extra: dict | None = None) -> Path:
    """A tiny Blender dataset: RGBA PNGs (seeded by frame) and transforms files without image extensions."""
    for split, poses in (("train", train), ("test", test)):
        (root / split).mkdir(parents=True, exist_ok=True)
        frames = []
        for i, c2w in enumerate(poses):
            Image.fromarray(rgba_image(100 * (split == "test") + i)).save(root / split / f"r_{i}.png")
            frames.append({"file_path": f"./{split}/r_{i}", "transform_matrix": c2w})
        (root / f"transforms_{split}.json").write_text(json.dumps({"camera_angle_x": ANGLE_X, "frames": frames,
                                                                   **(extra or {})}))
    return root


def pixel(cam, point) -> list[float]:
    x = cam.viewmat.double() @ torch.tensor([*point, 1.0], dtype=torch.float64)
    fx, fy, cx, cy = cam.intrinsics.double()
    return [float(fx * x[0] / x[2] + cx), float(fy * x[1] / x[2] + cy)]


def test_blender_poses_project_known_points(tmp_path):
    info = load_scene_info(str(write_blender(tmp_path)))
    assert info.kind == "blender" and info.point_cloud is None
    assert [c.uid for c in info.train_cameras + info.test_cameras] == [0, 1, 2]
    a, b = info.train_cameras
    assert (a.width, a.height) == (W, H)
    assert [a.fx, a.fy, a.cx, a.cy] == pytest.approx([40.0, 40.0, 20.0, 10.0], rel=1e-12)  # tan() rounding
    # Camera A: (1, 2, 0) is 5 ahead, 1 right, 2 up -> (cx + fx/5, cy - 2 fy/5) = (28, -6).
    assert pixel(a, (1.0, 2.0, 0.0)) == pytest.approx([28.0, -6.0], abs=1e-4)  # float32 viewmat
    # Camera B: (0, 1, 2) is 5 ahead, 1 right (+y), 2 up (+z).
    assert pixel(b, (0.0, 1.0, 2.0)) == pytest.approx([28.0, -6.0], abs=1e-4)
    assert b.camera_center.tolist() == pytest.approx([5.0, 0.0, 0.0], abs=1e-6)
    # Extent: centres (0,0,5) and (5,0,0), mean (2.5,0,2.5), distance 2.5 sqrt 2.
    assert info.scene_extent == pytest.approx(1.1 * 2.5 * math.sqrt(2), rel=1e-6)


def composited(seed: int, background: float) -> torch.Tensor:
    """The expected image of `rgba_image(seed)` over a uniform background, in float64. [3, H, W]"""
    rgba = torch.from_numpy(rgba_image(seed).astype(np.float64) / 255).permute(2, 0, 1)
    return rgba[:3] * rgba[3:] + background * (1 - rgba[3:])


@pytest.mark.parametrize("white", [False, True])
def test_rgba_composited_on_background(tmp_path, white):
    info = load_scene_info(str(write_blender(tmp_path)), white_background=white)
    bg = 1.0 if white else 0.0
    got = info.train_cameras[1].image
    assert got.shape == (3, H, W) and got.dtype == torch.float32
    # float32 arithmetic on exact 8-bit values: a few ulps.
    torch.testing.assert_close(got.double(), composited(1, bg), atol=1e-6, rtol=0)
    torch.testing.assert_close(info.test_cameras[0].image.double(), composited(100, bg), atol=1e-6, rtol=0)


@pytest.mark.parametrize("resolution, size, scale", [(-1, (40, 20), 1.0), (1, (40, 20), 1.0), (2, (20, 10), 0.5),
                                                     (4, (10, 5), 0.25), (10, (10, 5), 0.25), (20, (20, 10), 0.5)])
def test_resolution_scales_image_and_intrinsics(tmp_path, resolution, size, scale):
    info = load_scene_info(str(write_blender(tmp_path)), resolution=resolution, white_background=True)
    cam = info.train_cameras[0]
    assert (cam.width, cam.height) == size
    assert [cam.fx, cam.fy, cam.cx, cam.cy] == pytest.approx([40 * scale, 40 * scale, 20 * scale, 10 * scale])
    # The image is the box average of the full-size composited image.
    full = load_scene_info(str(tmp_path), white_background=True).train_cameras[0].image
    k = round(1 / scale)
    expected = torch.nn.functional.avg_pool2d(full[None], k)[0]
    # Pillow resamples 8-bit premultiplied RGBA and rounds twice: a few levels of 1/255 (alpha >= 1/2).
    torch.testing.assert_close(cam.image, expected, atol=4 / 255, rtol=0)
    # A point keeps its position relative to the image size.
    assert pixel(cam, (1.0, 2.0, 0.0)) == pytest.approx([28.0 * scale, -6.0 * scale], abs=1e-4)


def test_target_size_rules():
    assert target_size(800, 600, 8) == (100, 75)
    assert target_size(800, 600, 400) == (400, 300)
    for bad in (0, -2, -8):
        with pytest.raises(UserError, match="--resolution"):
            target_size(800, 600, bad)


def test_per_frame_intrinsics_and_extensions(tmp_path):
    write_blender(tmp_path, extra={"fl_x": 999.0, "w": 80, "h": 40})  # file-level keys, overridden below
    data = json.loads((tmp_path / "transforms_train.json").read_text())
    data["frames"][0].update({"fl_x": 100.0, "fl_y": 90.0, "cx": 41.0, "cy": 19.0, "file_path": "./train/r_0.png"})
    (tmp_path / "transforms_train.json").write_text(json.dumps(data))
    a, b = load_scene_info(str(tmp_path)).train_cameras
    # Declared in 80x40 pixels, image is 40x20: everything halves.
    assert [a.fx, a.fy, a.cx, a.cy] == pytest.approx([50.0, 45.0, 20.5, 9.5])
    assert [b.fx, b.fy, b.cx, b.cy] == pytest.approx([499.5, 499.5, 20.0, 10.0])
    assert a.image_name == "r_0" and b.image_name == "r_1"


def test_scene_moves_to_device(tmp_path):
    info = load_scene_info(str(write_blender(tmp_path)), device="meta")  # no accelerator needed to see the move
    assert all(c.viewmat.device.type == "meta" and c.image.device.type == "meta"
               for c in info.train_cameras + info.test_cameras)


# ------------------------------------------------------------------------------------------- bad inputs


def edit_train(root: Path, edit) -> None:
    data = json.loads((root / "transforms_train.json").read_text())
    edit(data)
    (root / "transforms_train.json").write_text(json.dumps(data))


def test_missing_and_empty_paths(tmp_path):
    with pytest.raises(UserError, match="does not exist"):
        load_scene_info(str(tmp_path / "nope"))
    with pytest.raises(UserError, match="does not exist"):
        load_scene_info("")
    (tmp_path / "empty").mkdir()
    with pytest.raises(UserError, match="empty"):
        load_scene_info(str(tmp_path / "empty"))


def test_neither_layout(tmp_path):
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(UserError, match=r"neither a Blender dataset \(transforms_train\.json\), a nerfstudio / "
                                        r"instant-ngp one \(transforms\.json\) nor a COLMAP one \(sparse/0"):
        load_scene_info(str(tmp_path))


@pytest.mark.parametrize("resolution", [0, -2])
def test_bad_resolution(tmp_path, resolution):
    with pytest.raises(UserError, match="--resolution"):
        load_scene_info(str(write_blender(tmp_path)), resolution=resolution)


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.pop("frames"), "missing key 'frames'"),
    (lambda d: d.update(frames=[]), "'frames' is empty"),
    (lambda d: d["frames"][1].pop("transform_matrix"), "frame 1: needs 'file_path' and 'transform_matrix'"),
    (lambda d: d["frames"][0].pop("file_path"), "frame 0: needs"),
    (lambda d: d["frames"][1].update(transform_matrix=[[1, 0], [0, 1]]),
     r"frame 1: the pose must be a 4x4 or 3x4 matrix, got shape \(2, 2\)"),
    (lambda d: d["frames"][1]["transform_matrix"][2].__setitem__(1, float("nan")),
     r"frame 1: the pose holds a non-finite value \(nan\) at row 2, column 1"),
    (lambda d: d["frames"][1].update(transform_matrix="eye"), r"frame 1: the pose is not a matrix of numbers"),
    (lambda d: d["frames"][0].update(transform_matrix=[[0.0] * 4] * 4), "frame 0: the rotation part of the pose is not a rotation"),
    (lambda d: d.pop("camera_angle_x"), "frame 0: needs 'camera_angle_x' or 'fl_x'"),
    (lambda d: d.update(camera_angle_x="wide"), "'camera_angle_x' must be a number"),
    (lambda d: d["frames"][1].update(fl_x=-3), "frame 1: 'fl_x' must be a finite positive"),
    (lambda d: d["frames"][1].update(file_path=7), "frame 1: 'file_path' must be a string"),
])
def test_bad_transforms(tmp_path, edit, message):
    root = write_blender(tmp_path)
    edit_train(root, edit)
    with pytest.raises(UserError, match=message) as err:
        load_scene_info(str(root))
    assert "transforms_train.json" in str(err.value) and "\n" not in str(err.value)


def test_malformed_json(tmp_path):
    root = write_blender(tmp_path)
    (root / "transforms_test.json").write_text('{"frames": [')
    with pytest.raises(UserError, match=r"transforms_test\.json is not valid JSON"):
        load_scene_info(str(root))


def test_missing_images_error_or_skip(tmp_path, caplog):
    root = write_blender(tmp_path)
    (root / "train" / "r_1.png").unlink()
    with pytest.raises(UserError, match=r"1 of 3 listed images are missing \(train/r_1\.png; first listed at "
                                        r"transforms_train\.json frame 1\).*--skip_missing_images"):
        load_scene_info(str(root))
    with caplog.at_level(logging.WARNING):
        info = load_scene_info(str(root), skip_missing_images=True)
    assert [c.image_name for c in info.train_cameras] == ["r_0"] and len(info.test_cameras) == 1
    assert info.dropped_images == ["train/r_1.png"]
    assert any("dropped 1 of 3" in r.getMessage() for r in caplog.records)


def test_many_missing_images_name_the_first_few(tmp_path):
    root = write_blender(tmp_path, train=(C2W_A, C2W_B, C2W_A, C2W_B, C2W_A))
    for i in range(1, 5):
        (root / "train" / f"r_{i}.png").unlink()
    with pytest.raises(UserError, match=r"^4 of 6 listed images are missing \(train/r_1\.png, train/r_2\.png, "
                                        r"train/r_3\.png, \.\.\.;"):
        load_scene_info(str(root))


def test_truncated_image_is_one_line(tmp_path):
    root = write_blender(tmp_path)
    data = (root / "train" / "r_1.png").read_bytes()
    (root / "train" / "r_1.png").write_bytes(data[: len(data) // 2])  # header intact, pixels cut short
    with pytest.raises(UserError, match=r"transforms_train\.json frame 1: cannot read image .*r_1\.png "
                                        r"\(.*truncated.*\); the file is truncated or corrupt") as err:
        load_scene_info(str(root))
    assert "\n" not in str(err.value)


def test_unreadable_image(tmp_path):
    root = write_blender(tmp_path)
    (root / "test" / "r_0.png").write_bytes(b"not a png")
    with pytest.raises(UserError, match=r"transforms_test\.json frame 0: cannot read image"):
        load_scene_info(str(root))


@pytest.mark.parametrize("split, frame", [("train", 1), ("test", 0)])
def test_mixed_sizes(tmp_path, split, frame):
    root = write_blender(tmp_path)
    Image.fromarray(rgba_image(5, size=(W, H + 2))).save(root / split / f"r_{frame}.png")
    with pytest.raises(UserError, match=f"transforms_{split}.json frame {frame}: image r_{frame}.png is 40x22 "
                                        "but r_0.png is 40x20; .*one size"):
        load_scene_info(str(root))


def test_lego_at_resolution_8(shared_dir):
    lego = shared_dir / "data" / "lego"
    if not (lego / "transforms_train.json").is_file():
        pytest.skip(f"lego not found at {lego}")
    info = load_scene_info(str(lego), resolution=8, white_background=True)
    assert (len(info.train_cameras), len(info.test_cameras)) == (80, 20)
    assert all((c.width, c.height) == (100, 100) and c.image.shape == (3, 100, 100)
               for c in info.train_cameras + info.test_cameras)
    cam = info.train_cameras[0]
    assert cam.fx == pytest.approx(50 / math.tan(0.5 * 0.6911112070083618), rel=1e-6)  # lego's camera_angle_x
    # Every camera looks at the object near the origin: it projects close to the image centre.
    for c in info.train_cameras:
        assert pixel(c, (0.0, 0.0, 0.0)) == pytest.approx([50.0, 50.0], abs=15.0)
