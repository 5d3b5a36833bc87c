"""Camera: projection conventions against closed forms, look_at, fields of view, cameras.json entries."""
from __future__ import annotations

import json
import math

import pytest
import torch

from scene.cameras import Camera, look_at


def project(cam: Camera, point) -> torch.Tensor:
    """Pixel coordinates of a world point through `cam` (pinhole, OpenCV). [2]"""
    x = cam.viewmat.double() @ torch.tensor([*point, 1.0], dtype=torch.float64)
    fx, fy, cx, cy = cam.intrinsics.double()
    return torch.stack([fx * x[0] / x[2] + cx, fy * x[1] / x[2] + cy])


def make_camera(viewmat: torch.Tensor, width: int = 64, height: int = 48) -> Camera:
    return Camera(uid=0, image_name="a", viewmat=viewmat.float(), fx=50.0, fy=55.0, cx=31.0, cy=25.0,
                  width=width, height=height)


def test_look_at_axes_closed_form():
    # Camera on +z looking at the origin with world +y up: x right = +x, y down = -y, z forward = -z.
    view = look_at((0.0, 0.0, 5.0), up=(0.0, 1.0, 0.0))
    expected = torch.tensor([[1.0, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 5], [0, 0, 0, 1]], dtype=torch.float64)
    torch.testing.assert_close(view, expected, atol=1e-12, rtol=0)  # float64 rounding only
    cam = make_camera(view)
    # (1, 2, 0) is 5 in front, 1 right, 2 up -> pixel (cx + fx/5, cy - 2 fy/5).
    torch.testing.assert_close(project(cam, (1.0, 2.0, 0.0)), torch.tensor([31 + 10.0, 25 - 22.0],
                               dtype=torch.float64), atol=1e-5, rtol=0)  # float32 viewmat


@pytest.mark.parametrize("eye", [(3.0, -2.0, 1.5), (-0.5, 0.2, -4.0), (1e-3, 2.0, 0.3)])
def test_look_at_properties(eye):
    target = torch.tensor([0.2, -0.1, 0.3], dtype=torch.float64)
    view = look_at(eye, target)
    rot = view[:3, :3]
    torch.testing.assert_close(rot @ rot.T, torch.eye(3, dtype=torch.float64), atol=1e-12, rtol=0)
    assert torch.linalg.det(rot) == pytest.approx(1.0, abs=1e-12)  # proper rotation, not a reflection
    cam = Camera(0, "a", view, 10.0, 10.0, 5.0, 5.0, 10, 10)
    torch.testing.assert_close(cam.camera_center, torch.tensor(eye, dtype=torch.float64), atol=1e-12, rtol=0)
    in_cam = view @ torch.cat([target, torch.ones(1, dtype=torch.float64)])
    assert abs(in_cam[0]) < 1e-12 and abs(in_cam[1]) < 1e-12 and in_cam[2] > 0  # target on the optical axis
    # World +z (the up vector) appears upwards in the image: negative camera y.
    above = view @ torch.cat([target + torch.tensor([0, 0, 0.1], dtype=torch.float64),
                              torch.ones(1, dtype=torch.float64)])
    assert above[1] < 0


def test_look_at_rejects_parallel_up():
    with pytest.raises(ValueError, match="parallel"):
        look_at((0.0, 0.0, 3.0), up=(0.0, 0.0, 1.0))


def test_fov_and_intrinsics():
    cam = make_camera(look_at((0.0, 2.0, 2.0)), width=64, height=48)
    assert cam.fov_x == pytest.approx(2 * math.atan(32 / 50))
    assert cam.fov_y == pytest.approx(2 * math.atan(24 / 55))
    assert cam.intrinsics.tolist() == [50.0, 55.0, 31.0, 25.0]
    assert cam.intrinsics.dtype == cam.viewmat.dtype


def test_to_device_copies():
    cam = make_camera(look_at((1.0, 2.0, 3.0)))
    cam.image = torch.rand(3, 48, 64)
    moved = cam.to("meta")  # a device without data: shows both tensors move, with no accelerator needed
    assert moved.viewmat.device.type == "meta" and moved.image.device.type == "meta"
    assert moved.intrinsics.device.type == "meta"
    assert cam.viewmat.device.type == "cpu" and moved.fx == cam.fx and moved.image_name == cam.image_name


def test_to_json_entry():
    eye = (1.0, -2.0, 3.0)
    cam = make_camera(look_at(eye))
    entry = cam.to_json(7)
    json.dumps(entry)  # must be plain JSON
    assert entry["id"] == 7 and entry["img_name"] == "a" and (entry["width"], entry["height"]) == (64, 48)
    assert entry["fx"] == 50.0 and entry["fy"] == 55.0
    torch.testing.assert_close(torch.tensor(entry["position"]), torch.tensor(eye), atol=1e-5, rtol=0)  # float32
    # rotation = camera-to-world: the transpose of the world-to-camera rotation.
    torch.testing.assert_close(torch.tensor(entry["rotation"], dtype=torch.float32), cam.viewmat[:3, :3].T,
                               atol=1e-6, rtol=0)  # float32 inverse
