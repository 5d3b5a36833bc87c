"""`Camera`: a pinhole camera (OpenCV convention) with its ground-truth image."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import torch


@dataclass
class Camera:
    """World-to-camera `viewmat` (x right, y down, z forward), intrinsics in pixels, optional image [3, H, W]."""

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
        """(fx, fy, cx, cy). [4]"""
        return torch.tensor([self.fx, self.fy, self.cx, self.cy], dtype=self.viewmat.dtype,
                            device=self.viewmat.device)

    @property
    def camera_center(self) -> torch.Tensor:
        """Camera position in world coordinates. [3]"""
        return -self.viewmat[:3, :3].T @ self.viewmat[:3, 3]

    @property
    def fov_x(self) -> float:
        return 2 * math.atan(self.width / (2 * self.fx))

    @property
    def fov_y(self) -> float:
        return 2 * math.atan(self.height / (2 * self.fy))

    def to(self, device: str | torch.device) -> "Camera":
        return replace(self, viewmat=self.viewmat.to(device),
                       image=None if self.image is None else self.image.to(device))

    def to_json(self, idx: int) -> dict:
        """The 3DGS `cameras.json` entry (position and camera-to-world rotation)."""
        cam_to_world = torch.linalg.inv(self.viewmat.double().cpu())
        return {"id": idx, "img_name": self.image_name, "width": self.width, "height": self.height,
                "position": cam_to_world[:3, 3].tolist(), "rotation": cam_to_world[:3, :3].tolist(),
                "fx": self.fx, "fy": self.fy}
