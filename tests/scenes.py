"""Small procedural scenes for tests (float64 by default)."""
from __future__ import annotations

import math

import torch


def look_at_viewmat(eye, target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), dtype=torch.float64) -> torch.Tensor:
    """World-to-camera [4,4] (OpenCV: x right, y down, z forward) for a camera at `eye` looking at `target`."""
    eye, target, up = (torch.tensor(v, dtype=dtype) for v in (eye, target, up))
    forward = target - eye
    forward = forward / forward.norm()
    right = torch.linalg.cross(forward, up)
    right = right / right.norm()
    down = torch.linalg.cross(forward, right)
    rot = torch.stack([right, down, forward])  # rows: camera axes in world coordinates
    view = torch.eye(4, dtype=dtype)
    view[:3, :3] = rot
    view[:3, 3] = -rot @ eye
    return view


def intrinsics_for(width: int, height: int, fov_x_deg: float = 60.0, cx=None, cy=None, dtype=torch.float64):
    fx = 0.5 * width / math.tan(math.radians(fov_x_deg) / 2)
    return torch.tensor([fx, fx, width / 2 if cx is None else cx, height / 2 if cy is None else cy], dtype=dtype)


def random_gaussians(n: int, seed: int = 0, spread: float = 0.6, scale: float = 0.15, sh_degree: int = 0,
                     dtype=torch.float64) -> dict[str, torch.Tensor]:
    """Raw parameters of `n` random Gaussians near the origin."""
    g = torch.Generator().manual_seed(seed)
    k = (sh_degree + 1) ** 2
    return {
        "means": (torch.rand(n, 3, generator=g, dtype=dtype) * 2 - 1) * spread,
        "quats": torch.randn(n, 4, generator=g, dtype=dtype),
        "log_scales": torch.log(scale * (0.5 + torch.rand(n, 3, generator=g, dtype=dtype))),
        "logit_opacities": torch.randn(n, generator=g, dtype=dtype),
        "sh_coeffs": torch.randn(n, k, 3, generator=g, dtype=dtype) * 0.5,
    }
