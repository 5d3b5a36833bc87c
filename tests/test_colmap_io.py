"""COLMAP reader: binary and text round trips through a small writer, camera models, the COLMAP loader."""
from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from scene import colmap_io
from scene.dataset_readers import load_scene_info
from scene.lens import Lens, Undistorter
from utils.errors import UserError

MODEL_IDS = {"SIMPLE_PINHOLE": 0, "PINHOLE": 1, "SIMPLE_RADIAL": 2, "RADIAL": 3, "OPENCV": 4, "OPENCV_FISHEYE": 5,
             "FULL_OPENCV": 6}


# ------------------------------------------------------------------------------------ writers (COLMAP formats)


def write_binary(sparse: Path, cameras, images, points) -> None:
    """cameras: [(id, model, w, h, params)], images: [(id, qvec, tvec, cam_id, name)], points: [(xyz, rgb)]."""
    sparse.mkdir(parents=True, exist_ok=True)
    with open(sparse / "cameras.bin", "wb") as fh:
        fh.write(struct.pack("<Q", len(cameras)))
        for cid, model, w, h, params in cameras:
            fh.write(struct.pack("<iiQQ", cid, MODEL_IDS[model], w, h) + struct.pack(f"<{len(params)}d", *params))
    with open(sparse / "images.bin", "wb") as fh:
        fh.write(struct.pack("<Q", len(images)))
        for iid, q, t, cid, name in images:
            fh.write(struct.pack("<i7di", iid, *q, *t, cid) + name.encode() + b"\x00")
            fh.write(struct.pack("<Q", 2) + struct.pack("<ddq", 1.5, 2.5, -1) + struct.pack("<ddq", 3.0, 4.0, 0))
    with open(sparse / "points3D.bin", "wb") as fh:
        fh.write(struct.pack("<Q", len(points)))
        for pid, (xyz, rgb) in enumerate(points):
            fh.write(struct.pack("<Q3d3Bd", pid, *xyz, *rgb, 0.5))
            fh.write(struct.pack("<Q", 2) + struct.pack("<ii", 1, 0) + struct.pack("<ii", 2, 1))


def write_text(sparse: Path, cameras, images, points) -> None:
    """Same content as `write_binary`, in COLMAP's text format (with comments and empty 2D-point lines)."""
    sparse.mkdir(parents=True, exist_ok=True)
    lines = ["# Camera list with one line of data per camera:"]
    lines += [f"{cid} {model} {w} {h} " + " ".join(repr(p) for p in params) for cid, model, w, h, params in cameras]
    (sparse / "cameras.txt").write_text("\n".join(lines) + "\n")
    lines = ["# Image list with two lines of data per image:", "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
    for k, (iid, q, t, cid, name) in enumerate(images):
        lines.append(" ".join(str(v) for v in (iid, *q, *t, cid, name)))
        lines.append("" if k % 2 else "1.5 2.5 -1 3.0 4.0 0")  # an empty points line for every other image
    (sparse / "images.txt").write_text("\n".join(lines) + "\n")
    lines = ["# 3D point list"]
    lines += [" ".join(str(v) for v in (pid, *xyz, *rgb, 0.5, 1, 0, 2, 1)) for pid, (xyz, rgb) in enumerate(points)]
    (sparse / "points3D.txt").write_text("\n".join(lines) + "\n")


def quat_about_z(angle: float) -> tuple[float, float, float, float]:
    return (math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2))


def sample_model(num_images: int = 3, model: str = "PINHOLE", params=(50.0, 55.0, 20.0, 10.0)):
    cameras = [(1, model, 40, 20, list(params))]
    # Names deliberately out of order; an image name with a space and a numeric stem.
    names = [f"img_{(7 * k) % num_images:02d}.png" for k in range(num_images)]
    names[0] = "001 a.png" if num_images > 1 else names[0]
    images = [(10 + k, quat_about_z(0.3 * k), (0.1 * k, -0.2, 4.0 + k), 1, names[k]) for k in range(num_images)]
    points = [((0.5, -1.0, 2.0), (255, 0, 128)), ((-1.0, 0.25, 0.0), (10, 20, 30))]
    return cameras, images, points


# ------------------------------------------------------------------------------------------- readers


@pytest.mark.parametrize("fmt", ["binary", "text"])
def test_round_trip(tmp_path, fmt):
    cameras, images, points = sample_model(4, "OPENCV", (50.0, 55.0, 20.0, 10.0, 0.1, -0.01, 0.001, 0.002))
    (write_binary if fmt == "binary" else write_text)(tmp_path, cameras, images, points)
    cams, imgs, (xyz, rgb) = colmap_io.read_model(tmp_path)
    assert list(cams) == [1] and cams[1].model == "OPENCV" and (cams[1].width, cams[1].height) == (40, 20)
    np.testing.assert_array_equal(cams[1].params, cameras[0][4])
    assert sorted(imgs) == [10, 11, 12, 13]
    for iid, q, t, cid, name in images:
        got = imgs[iid]
        assert got.name == name and got.camera_id == cid
        np.testing.assert_array_equal(got.qvec, q)  # exact: binary doubles, and str() of a float round-trips
        np.testing.assert_array_equal(got.tvec, t)
    np.testing.assert_array_equal(xyz, [p[0] for p in points])
    np.testing.assert_array_equal(rgb, [p[1] for p in points])
    assert rgb.dtype == np.uint8


@pytest.mark.parametrize("fmt", ["binary", "text"])
def test_point_tracks(tmp_path, fmt):
    cameras, images, points = sample_model(3)
    (write_binary if fmt == "binary" else write_text)(tmp_path, cameras, images, points)
    tracks = colmap_io.read_point_tracks(tmp_path)
    assert [t.tolist() for t in tracks] == [[1, 2], [1, 2]]  # both writers give every point the track (1, 2)


def test_text_writer_round_trip(tmp_path):
    cameras, images, points = sample_model(4, "OPENCV", (50.0, 55.0, 20.0, 10.0, 0.1, -0.01, 0.001, 0.002))
    write_binary(tmp_path / "bin", cameras, images, points)
    cams, imgs, (xyz, rgb) = colmap_io.read_model(tmp_path / "bin")
    colmap_io.write_model_text(tmp_path / "txt", cams, imgs, xyz[1:], rgb[1:])
    cams2, imgs2, (xyz2, rgb2) = colmap_io.read_model(tmp_path / "txt")
    assert sorted(cams2) == sorted(cams)
    for cid, cam in cams.items():
        assert (cams2[cid].model, cams2[cid].width, cams2[cid].height) == (cam.model, cam.width, cam.height)
        np.testing.assert_array_equal(cams2[cid].params, cam.params)
    assert sorted(imgs2) == sorted(imgs)
    for iid, im in imgs.items():
        assert imgs2[iid].name == im.name and imgs2[iid].camera_id == im.camera_id
        np.testing.assert_array_equal(imgs2[iid].qvec, im.qvec)
        np.testing.assert_array_equal(imgs2[iid].tvec, im.tvec)
    np.testing.assert_array_equal(xyz2, xyz[1:])
    np.testing.assert_array_equal(rgb2, rgb[1:])
    assert [t.tolist() for t in colmap_io.read_point_tracks(tmp_path / "txt")] == [[]]


def quat_rotate(q, v) -> np.ndarray:
    """Slow twin: rotate v by the unit quaternion q (wxyz) as q v q*."""
    def mul(a, b):
        w1, x1, y1, z1 = a
        w2, x2, y2, z2 = b
        return (w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2)
    q = np.asarray(q) / np.linalg.norm(q)
    return np.array(mul(mul(q, (0.0, *v)), (q[0], -q[1], -q[2], -q[3]))[1:])


def test_qvec_to_rotmat():
    np.testing.assert_allclose(colmap_io.qvec_to_rotmat(np.array(quat_about_z(math.pi / 2))),
                               [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)  # float64 rounding
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = rng.normal(size=4) * 3  # unnormalised on purpose
        v = rng.normal(size=3)
        np.testing.assert_allclose(colmap_io.qvec_to_rotmat(q) @ v, quat_rotate(q, v), atol=1e-12)


@pytest.mark.parametrize("model, params, intrinsics, lens_model, dist", [
    ("SIMPLE_PINHOLE", (50.0, 20.0, 10.0), (50.0, 50.0, 20.0, 10.0), "OPENCV", ()),
    ("PINHOLE", (50.0, 55.0, 20.0, 10.0), (50.0, 55.0, 20.0, 10.0), "OPENCV", ()),
    ("SIMPLE_RADIAL", (50.0, 20.0, 10.0, 0.1), (50.0, 50.0, 20.0, 10.0), "OPENCV", (0.1, 0.0, 0.0, 0.0)),
    ("RADIAL", (50.0, 20.0, 10.0, 0.1, 0.01), (50.0, 50.0, 20.0, 10.0), "OPENCV", (0.1, 0.01, 0.0, 0.0)),
    ("OPENCV", (50.0, 55.0, 20.0, 10.0, 0.1, 0.01, 0.002, 0.003), (50.0, 55.0, 20.0, 10.0), "OPENCV",
     (0.1, 0.01, 0.002, 0.003)),
    ("FULL_OPENCV", (50.0, 55.0, 20.0, 10.0, *range(1, 9)), (50.0, 55.0, 20.0, 10.0), "OPENCV",
     tuple(float(v) for v in range(1, 9))),
    ("OPENCV_FISHEYE", (50.0, 55.0, 20.0, 10.0, 0.1, 0.01, 0.002, 0.003), (50.0, 55.0, 20.0, 10.0),
     "OPENCV_FISHEYE", (0.1, 0.01, 0.002, 0.003)),
])
def test_camera_models(model, params, intrinsics, lens_model, dist):
    lens = colmap_io.camera_lens(colmap_io.ColmapCamera(3, model, 40, 20, np.array(params, dtype=float)))
    assert (lens.width, lens.height, lens.fx, lens.fy, lens.cx, lens.cy) == (40, 20, *intrinsics)
    assert (lens.model, lens.dist) == (lens_model, dist)


def test_unsupported_model_and_wrong_param_count():
    with pytest.raises(UserError, match="FOV.*undistort"):
        colmap_io.camera_lens(colmap_io.ColmapCamera(3, "FOV", 40, 20, np.zeros(5)))
    with pytest.raises(UserError, match=r"camera 3 \(PINHOLE\) has 3 parameters, expected 4"):
        colmap_io.camera_lens(colmap_io.ColmapCamera(3, "PINHOLE", 40, 20, np.zeros(3)))


def test_incomplete_and_truncated_models(tmp_path):
    write_binary(tmp_path / "a", *sample_model())
    (tmp_path / "a" / "points3D.bin").unlink()
    with pytest.raises(UserError, match="points3D.bin is missing"):
        colmap_io.read_model(tmp_path / "a")
    write_binary(tmp_path / "b", *sample_model())
    data = (tmp_path / "b" / "images.bin").read_bytes()
    (tmp_path / "b" / "images.bin").write_bytes(data[:-30])
    with pytest.raises(UserError, match="corrupt or truncated"):
        colmap_io.read_model(tmp_path / "b")
    write_text(tmp_path / "c", *sample_model())
    (tmp_path / "c" / "cameras.txt").write_text("1 PINHOLE forty 20 1 2 3 4\n")
    with pytest.raises(UserError, match="corrupt or truncated"):
        colmap_io.read_model(tmp_path / "c")


# ------------------------------------------------------------------------------------------- loader


def write_colmap_scene(root: Path, num_images: int, model="PINHOLE", params=(50.0, 55.0, 20.0, 10.0), fmt="binary",
                       image_size=(40, 20), images_dir="images") -> list[tuple]:
    cameras, images, points = sample_model(num_images, model, params)
    (write_binary if fmt == "binary" else write_text)(root / "sparse" / "0", cameras, images, points)
    (root / images_dir).mkdir(parents=True)
    for k, (_, _, _, _, name) in enumerate(images):
        Image.new("RGB", image_size, (k, 2 * k, 3 * k)).save(root / images_dir / name)
    return images


@pytest.mark.parametrize("fmt", ["binary", "text"])
def test_colmap_loader_poses_and_points(tmp_path, fmt):
    images = write_colmap_scene(tmp_path, 3, fmt=fmt)
    info = load_scene_info(str(tmp_path))
    assert info.kind == "colmap" and len(info.train_cameras) == 3 and info.test_cameras == []
    by_name = {c.image_name: c for c in info.train_cameras}
    for _, q, t, _, name in images:
        cam = by_name[Path(name).stem]
        assert (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy) == (40, 20, 50.0, 55.0, 20.0, 10.0)
        # A world point X maps to R X + t in camera coordinates (the slow twin rotates by the quaternion).
        x = np.array([0.3, -0.7, 1.1])
        expected = quat_rotate(q, x) + np.array(t)
        got = (cam.viewmat.double() @ torch.tensor([*x, 1.0], dtype=torch.float64))[:3]
        np.testing.assert_allclose(got.numpy(), expected, atol=1e-5)  # float32 viewmat
        assert cam.image.shape == (3, 20, 40)
    assert [c.image_name for c in info.train_cameras] == sorted(c.image_name for c in info.train_cameras)
    torch.testing.assert_close(info.point_cloud.points, torch.tensor([[0.5, -1.0, 2.0], [-1.0, 0.25, 0.0]]))
    torch.testing.assert_close(info.point_cloud.colors, torch.tensor([[255, 0, 128], [10, 20, 30]]) / 255.0)


def test_llffhold_split(tmp_path):
    write_colmap_scene(tmp_path, 10)
    info = load_scene_info(str(tmp_path), eval=True, llffhold=8)
    names = sorted(Path(n).stem for *_, n in sample_model(10)[1])
    assert [c.image_name for c in info.test_cameras] == [names[0], names[8]]
    assert [c.image_name for c in info.train_cameras] == [n for i, n in enumerate(names) if i % 8]
    assert sorted(c.uid for c in info.train_cameras + info.test_cameras) == list(range(10))
    with pytest.raises(UserError, match="--llffhold"):
        load_scene_info(str(tmp_path), eval=True, llffhold=0)


def test_distorted_models_are_undistorted_to_pinhole(tmp_path):
    write_colmap_scene(tmp_path, 3, "SIMPLE_RADIAL", (50.0, 20.0, 10.0, -0.1))
    cam = load_scene_info(str(tmp_path)).train_cameras[0]
    expected = Undistorter(Lens(40, 20, 50.0, 50.0, 20.0, 10.0, "OPENCV", (-0.1, 0.0, 0.0, 0.0)), "t").pinhole
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == pytest.approx((expected.fx, expected.fy, expected.cx, expected.cy))
    assert cam.fx < 50.0  # barrel distortion: even the cropped (no-border) pinhole sees a wider field
    assert len(list((tmp_path / ".undistorted").rglob("*.png"))) == 3  # cached beside the dataset
    raw = load_scene_info(str(tmp_path), ignore_distortion=True).train_cameras[0]
    assert (raw.fx, raw.cx) == (50.0, 20.0)


def test_resolution_and_stored_size(tmp_path):
    # Calibrated at 40x20 but stored at 20x10 (a pre-downscaled folder): intrinsics follow the files.
    write_colmap_scene(tmp_path, 2, image_size=(20, 10), images_dir="images_2")
    cam = load_scene_info(str(tmp_path), images="images_2").train_cameras[0]
    assert (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy) == (20, 10, 25.0, 27.5, 10.0, 5.0)
    cam = load_scene_info(str(tmp_path), images="images_2", resolution=2).train_cameras[0]
    assert (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy) == (10, 5, 12.5, 13.75, 5.0, 2.5)
    with pytest.raises(UserError, match="--images"):
        load_scene_info(str(tmp_path))  # the default images/ folder does not exist


def test_missing_image_file(tmp_path):
    images = write_colmap_scene(tmp_path, 2)
    (tmp_path / "images" / images[1][4]).unlink()
    with pytest.raises(UserError, match=f"1 of 2 listed images are missing \\({images[1][4]}; first listed at "
                                        f"COLMAP image {images[1][4]}\\).*--skip_missing_images"):
        load_scene_info(str(tmp_path))
    info = load_scene_info(str(tmp_path), skip_missing_images=True)
    assert [c.image_name for c in info.train_cameras] == [Path(images[0][4]).stem]
    assert info.dropped_images == [images[1][4]]
