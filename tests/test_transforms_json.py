"""nerfstudio / instant-ngp transforms.json: poses against a closed form and against the Blender loader, intrinsics,
--eval hold-out, distortion, initial points, missing frames, the phone-capture generator, bad inputs."""
from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image
from plyfile import PlyData, PlyElement

from scene.dataset_readers import load_scene_info
from scene.lens import Undistorter
from scene.phone_capture import capture_lens, make_phone_capture
from tests.test_dataset_readers import C2W_A, C2W_B, pixel, rgba_image
from utils.errors import UserError

# The dataset generators (scene.builtin, scene.phone_capture) render with the default backend, as for a user;
# the rasterizer's backends are tested in test_rasterize.py and test_compiled_rasterizer.py.
pytestmark = pytest.mark.auto_backend

W, H = 40, 20


def write_ns(root: Path, poses=(C2W_A, C2W_B, C2W_A), extra: dict | None = None, size=(W, H)) -> Path:
    """A tiny nerfstudio dataset: images/frame_i.png and transforms.json with fl_x/fl_y/cx/cy/w/h."""
    (root / "images").mkdir(parents=True, exist_ok=True)
    frames = []
    for i, c2w in enumerate(poses):
        Image.fromarray(rgba_image(i, size)[..., :3]).save(root / "images" / f"frame_{i:02d}.png")
        frames.append({"file_path": f"images/frame_{i:02d}.png", "transform_matrix": c2w})
    data = {"fl_x": 40.0, "fl_y": 44.0, "cx": 21.0, "cy": 9.0, "w": W, "h": H, "frames": frames[::-1],
            **(extra or {})}
    (root / "transforms.json").write_text(json.dumps(data))
    return root


def edit(root: Path, change) -> None:
    data = json.loads((root / "transforms.json").read_text())
    change(data)
    (root / "transforms.json").write_text(json.dumps(data))


def test_poses_intrinsics_and_order(tmp_path):
    info = load_scene_info(str(write_ns(tmp_path)))
    assert info.kind == "transforms" and info.test_cameras == [] and info.point_cloud is None
    a, b, c = info.train_cameras  # sorted by file path although the file lists them backwards
    assert [x.image_name for x in (a, b, c)] == ["frame_00", "frame_01", "frame_02"]
    assert (a.width, a.height, a.fx, a.fy, a.cx, a.cy) == (W, H, 40.0, 44.0, 21.0, 9.0)
    # OpenGL axes -> OpenCV: camera A on +z looking at the origin, +y up; (1, 2, 0) is 5 ahead, 1 right, 2 up.
    assert pixel(a, (1.0, 2.0, 0.0)) == pytest.approx([21 + 40 / 5, 9 - 2 * 44 / 5], abs=1e-4)
    assert pixel(b, (0.0, 1.0, 2.0)) == pytest.approx([21 + 40 / 5, 9 - 2 * 44 / 5], abs=1e-4)
    expected = torch.from_numpy(rgba_image(1)[..., :3].astype(np.float32) / 255).permute(2, 0, 1)
    torch.testing.assert_close(b.image, expected, atol=1e-6, rtol=0)


def test_builtin_scene_as_transforms_json_matches_blender_loader(tiny_scene, tmp_path):
    root = tmp_path / "ns"
    shutil.copytree(tiny_scene, root, ignore=shutil.ignore_patterns("transforms_*.json"))
    frames = []
    for split in ("train", "test"):
        data = json.loads((tiny_scene / f"transforms_{split}.json").read_text())
        frames += [{"file_path": f["file_path"] + ".png", "transform_matrix": f["transform_matrix"]}
                   for f in data["frames"]]
    angle = data["camera_angle_x"]
    (root / "transforms.json").write_text(json.dumps({"camera_angle_x": angle, "aabb_scale": 4, "frames": frames}))
    blender = load_scene_info(str(tiny_scene))
    ns = load_scene_info(str(root))
    by_path = {f"{s}/r_{c.image_name[2:]}.png": c for s, cams in (("train", blender.train_cameras),
                                                                   ("test", blender.test_cameras)) for c in cams}
    ordered = sorted(by_path)
    assert len(ns.train_cameras) == len(ordered)
    for path, got in zip(ordered, ns.train_cameras):
        want = by_path[path]
        torch.testing.assert_close(got.viewmat, want.viewmat, atol=1e-6, rtol=0)
        assert (got.fx, got.fy, got.cx, got.cy, got.width, got.height) == pytest.approx(
            (want.fx, want.fy, want.cx, want.cy, want.width, want.height), abs=1e-6)
        torch.testing.assert_close(got.image, want.image, atol=0, rtol=0)


def test_eval_holds_out_every_8th_and_per_frame_intrinsics(tmp_path):
    write_ns(tmp_path, poses=[C2W_A, C2W_B] * 5)
    edit(tmp_path, lambda d: d["frames"][-1].update(fl_x=80.0, w=2 * W, h=2 * H))  # frame_00, in 80x40 pixels
    info = load_scene_info(str(tmp_path), eval=True)
    assert [c.image_name for c in info.test_cameras] == ["frame_00", "frame_08"]
    assert [c.image_name for c in info.train_cameras] == [f"frame_{i:02d}" for i in range(10) if i % 8]
    first = info.test_cameras[0]
    assert (first.fx, first.fy, first.cx, first.cy) == (40.0, 22.0, 10.5, 4.5)  # per-frame keys, halved


def test_distortion_undistorts_and_ignore_keeps_pinhole(tmp_path):
    write_ns(tmp_path, extra={"k1": -0.1, "k2": 0.01, "p1": 0.001, "p2": 0.0})
    cam = load_scene_info(str(tmp_path)).train_cameras[0]
    from scene.lens import Lens
    pinhole = Undistorter(Lens(W, H, 40.0, 44.0, 21.0, 9.0, "OPENCV", (-0.1, 0.01, 0.001, 0.0)), "t").pinhole
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == pytest.approx((pinhole.fx, pinhole.fy, pinhole.cx, pinhole.cy))
    raw = load_scene_info(str(tmp_path), ignore_distortion=True).train_cameras[0]
    assert (raw.fx, raw.fy, raw.cx, raw.cy) == (40.0, 44.0, 21.0, 9.0)
    edit(tmp_path, lambda d: d.update(camera_model="OPENCV_FISHEYE", k3=0.001, k4=0.0, p1=0.0))
    fish = load_scene_info(str(tmp_path)).train_cameras[0]
    assert fish.fx != cam.fx


def test_initial_points_from_ply_file_path_and_sparse_pc(tmp_path, caplog):
    write_ns(tmp_path)
    vertex = np.array([(0.5, -1.0, 2.0, 255, 0, 128), (1.0, 2.0, 3.0, 10, 20, 30)],
                      dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    PlyData([PlyElement.describe(vertex, "vertex")]).write(str(tmp_path / "sparse_pc.ply"))
    pcd = load_scene_info(str(tmp_path)).point_cloud
    torch.testing.assert_close(pcd.points, torch.tensor([[0.5, -1.0, 2.0], [1.0, 2.0, 3.0]]))
    torch.testing.assert_close(pcd.colors, torch.tensor([[255, 0, 128], [10, 20, 30]]) / 255.0)
    (tmp_path / "sparse_pc.ply").rename(tmp_path / "points.ply")
    edit(tmp_path, lambda d: d.update(ply_file_path="points.ply", aabb_scale=16))
    with caplog.at_level(logging.INFO):
        assert load_scene_info(str(tmp_path)).point_cloud.points.shape == (2, 3)
    assert any("aabb_scale 16 ignored" in r.getMessage() for r in caplog.records)


def test_random_points_are_announced(tmp_path, caplog):
    from scene.scene import Scene
    scene = Scene.load(str(write_ns(tmp_path)), tmp_path / "m", white_background=False, resolution=-1, eval=False)
    with caplog.at_level(logging.INFO):
        pcd = scene.initial_point_cloud(123, seed=0)
    assert pcd.points.shape == (123, 3)
    assert [r.getMessage() for r in caplog.records if "random points" in r.getMessage()] == [
        "no initial point file in the dataset (sparse_pc.ply, ply_file_path or points3D): starting from 123 "
        "random points"]


def test_phone_capture_generator_tiny(tmp_path):
    root = make_phone_capture(tmp_path / "phone", 27, 48, num_frames=6, missing=1)
    data = json.loads((root / "transforms.json").read_text())
    assert (data["w"], data["h"], len(data["frames"])) == (27, 48, 6)
    assert [data[k] for k in ("k1", "k2", "p1", "p2")] == list(capture_lens(27, 48).dist)
    assert len(list((root / "images").glob("*.jpg"))) == 5
    with pytest.raises(UserError, match=r"1 of 6 listed images are missing \(images/frame_00004\.jpg;"):
        load_scene_info(str(root))
    info = load_scene_info(str(root), eval=True, skip_missing_images=True)
    assert info.dropped_images == ["images/frame_00004.jpg"]
    assert [c.image_name for c in info.test_cameras] == ["frame_00001"]
    assert len(info.train_cameras) == 4
    pinhole = Undistorter(capture_lens(27, 48), "t").pinhole
    cam = info.train_cameras[0]
    assert (cam.width, cam.height, cam.fx, cam.cy) == (27, 48, pytest.approx(pinhole.fx), pytest.approx(pinhole.cy))


# ------------------------------------------------------------------------------------------- bad inputs


@pytest.mark.parametrize("change, message", [
    (lambda d: [d.pop(k) for k in ("fl_x", "fl_y", "cx", "cy")], r"frame \d: needs 'camera_angle_x' or 'fl_x'.*no "
                                                                 "intrinsics"),
    (lambda d: d.update(w=50, h=25), r"frame \d: image frame_0\d\.png is 40x20 but the intrinsics are for 50x25"),
    (lambda d: d.update(camera_model="EQUIRECTANGULAR"), "unknown camera_model 'EQUIRECTANGULAR'"),
    (lambda d: d.update(k1=-1.0), "undistortion failed.*folds over"),
    (lambda d: d.update(k1="big"), "'k1' must be a number"),
    (lambda d: d.update(ply_file_path="nope.ply"), "ply_file_path 'nope.ply' does not exist"),
    (lambda d: d.update(camera_model="OPENCV_FISHEYE", p1=0.1), "no tangential terms"),
])
def test_bad_transforms_json(tmp_path, change, message):
    write_ns(tmp_path)
    edit(tmp_path, change)
    with pytest.raises(UserError, match=message) as err:
        load_scene_info(str(tmp_path))
    assert "\n" not in str(err.value)


def test_clean_multiple_sizes_scale(tmp_path):
    write_ns(tmp_path)
    edit(tmp_path, lambda d: d.update(w=4 * W, h=4 * H, fl_x=160.0, fl_y=176.0, cx=84.0, cy=36.0))
    cam = load_scene_info(str(tmp_path)).train_cameras[0]
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (40.0, 44.0, 21.0, 9.0)


def test_unreadable_points_file(tmp_path):
    write_ns(tmp_path)
    (tmp_path / "sparse_pc.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 5\n")
    with pytest.raises(UserError, match="cannot read points file .*sparse_pc.ply"):
        load_scene_info(str(tmp_path))
