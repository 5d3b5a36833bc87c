"""`Camera`: a pinhole camera (OpenCV convention) with its ground-truth image, and `look_at`."""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import torch

from gaussian_renderer.projection import camera_center


@dataclass
class Camera:
    """A pinhole camera with its (optional) image.

    `viewmat` is world-to-camera in the OpenCV convention (x right, y down, z forward); the intrinsics are in
    pixels with pixel (x, y) centred at (x + 0.5, y + 0.5).
    """

    uid: int
    image_name: str
    viewmat: torch.Tensor  # [4, 4] float32
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    image: torch.Tensor | None = None  # [3, H, W] float32 in [0, 1], composited on the background

    @property
    def intrinsics(self) -> torch.Tensor:
        """(fx, fy, cx, cy) in the dtype and on the device of `viewmat`. [4]"""
        return torch.tensor([self.fx, self.fy, self.cx, self.cy], dtype=self.viewmat.dtype,
                            device=self.viewmat.device)

    @property
    def camera_center(self) -> torch.Tensor:
        """Camera position in world coordinates. [3]"""
        return camera_center(self.viewmat)

    @property
    def fov_x(self) -> float:
        """Full horizontal field of view in radians (assumes the principal point at the centre)."""
        return 2 * math.atan(self.width / (2 * self.fx))

    @property
    def fov_y(self) -> float:
        """Full vertical field of view in radians (assumes the principal point at the centre)."""
        return 2 * math.atan(self.height / (2 * self.fy))

    def to(self, device: str | torch.device) -> "Camera":
        """A copy with `viewmat` and `image` on `device`."""
        return replace(self, viewmat=self.viewmat.to(device),
                       image=None if self.image is None else self.image.to(device))

    def to_json(self, idx: int) -> dict:
        """The 3DGS `cameras.json` entry: camera centre and camera-to-world rotation (OpenCV axes)."""
        cam_to_world = torch.linalg.inv(self.viewmat.double().cpu())
        return {"id": idx, "img_name": self.image_name, "width": self.width, "height": self.height,
                "position": cam_to_world[:3, 3].tolist(), "rotation": cam_to_world[:3, :3].tolist(),
                "fx": self.fx, "fy": self.fy}


def look_at(eye: torch.Tensor | Sequence[float], target: torch.Tensor | Sequence[float] = (0.0, 0.0, 0.0),
            up: torch.Tensor | Sequence[float] = (0.0, 0.0, 1.0), dtype: torch.dtype = torch.float64
            ) -> torch.Tensor:
    """World-to-camera matrix (OpenCV axes) of a camera at `eye` looking at `target`, `up` pointing up on screen.

    Args:
        eye: camera centre. [3]
        target: the point imaged at the principal point. [3]
        up: world direction that appears up in the image (not parallel to `target - eye`). [3]
    Returns:
        viewmat [4, 4] in `dtype`.
    """
    eye, target, up = (torch.as_tensor(v, dtype=dtype) for v in (eye, target, up))
    forward = target - eye
    forward = forward / forward.norm()
    right = torch.linalg.cross(forward, up)
    if right.norm() < 1e-9 * up.norm():
        raise ValueError(f"look_at: up {up.tolist()} is parallel to the viewing direction {forward.tolist()}")
    right = right / right.norm()
    down = torch.linalg.cross(forward, right)
    view = torch.eye(4, dtype=dtype)
    view[:3, :3] = torch.stack([right, down, forward])  # rows: camera axes in world coordinates
    view[:3, 3] = -view[:3, :3] @ eye
    return view
