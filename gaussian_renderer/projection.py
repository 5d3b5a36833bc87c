"""Projection of 3D Gaussians to the image plane (EWA splatting, pinhole camera). Pure tensor functions."""
from __future__ import annotations

from dataclasses import dataclass

import torch


def quat_to_rotmat(quats: torch.Tensor) -> torch.Tensor:
    """Rotation matrices from quaternions (wxyz, normalised inside). [N,4] -> [N,3,3]"""
    q = quats / quats.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(-1, 3, 3)


def covariance_3d(quats: torch.Tensor, scales: torch.Tensor) -> torch.Tensor:
    """World-space covariance R S S^T R^T. quats [N,4] (wxyz), scales [N,3] -> [N,3,3]"""
    m = quat_to_rotmat(quats) * scales[:, None, :]  # R S
    return m @ m.transpose(1, 2)


@dataclass
class Projection:
    """Screen-space Gaussians. Pixel (x, y) has its centre at (x + 0.5, y + 0.5)."""

    means2d: torch.Tensor  # [N, 2] pixels
    conics: torch.Tensor  # [N, 3] (a, b, c) of the inverse 2D covariance [[a, b], [b, c]]
    depths: torch.Tensor  # [N] camera-space z
    radii: torch.Tensor  # [N] int64, 3-sigma radius in pixels; 0 = culled


def project_gaussians(means: torch.Tensor, quats: torch.Tensor, scales: torch.Tensor, viewmat: torch.Tensor,
                      intrinsics: torch.Tensor, width: int, height: int, near_plane: float = 0.01,
                      dilation: float = 0.3) -> Projection:
    """Project 3D Gaussians with the local affine (EWA) approximation of the perspective map.

    The 2D covariance gets a `dilation` * I low-pass term (anti-aliasing, as in 3DGS); x/z and y/z are clamped to
    1.3x the image bounds before building the Jacobian, measured from the principal point, so off-centre principal
    points work. Gaussians in front of the near plane, with a singular 2D covariance, or whose 3-sigma box misses the
    image get radius 0.

    Args:
        means: world-space centres. [N, 3]
        quats: rotations, wxyz, any norm. [N, 4]
        scales: activated scales. [N, 3]
        viewmat: world-to-camera, OpenCV convention (x right, y down, z forward). [4, 4]
        intrinsics: (fx, fy, cx, cy) in pixels. [4]
    """
    n = means.shape[0]
    assert means.shape == (n, 3) and quats.shape == (n, 4) and scales.shape == (n, 3), \
        f"bad shapes means {tuple(means.shape)} quats {tuple(quats.shape)} scales {tuple(scales.shape)}"
    assert viewmat.shape == (4, 4), f"viewmat must be [4,4], got {tuple(viewmat.shape)}"
    fx, fy, cx, cy = intrinsics.to(means.dtype).unbind(-1)
    rot, trans = viewmat[:3, :3].to(means.dtype), viewmat[:3, 3].to(means.dtype)
    t = means @ rot.T + trans  # [N, 3] camera space
    z = t[:, 2]
    in_front = z > near_plane
    z_safe = torch.where(in_front, z, torch.ones_like(z))
    lim_x_pos, lim_x_neg = 1.3 * (width - cx) / fx, 1.3 * cx / fx
    lim_y_pos, lim_y_neg = 1.3 * (height - cy) / fy, 1.3 * cy / fy
    tx = z_safe * torch.minimum(torch.maximum(t[:, 0] / z_safe, -lim_x_neg), lim_x_pos)
    ty = z_safe * torch.minimum(torch.maximum(t[:, 1] / z_safe, -lim_y_neg), lim_y_pos)
    zeros = torch.zeros_like(z_safe)
    jac = torch.stack([fx / z_safe, zeros, -fx * tx / z_safe**2,
                       zeros, fy / z_safe, -fy * ty / z_safe**2], dim=-1).reshape(n, 2, 3)
    cov_cam = rot @ covariance_3d(quats, scales) @ rot.T  # [N, 3, 3]
    cov2d = jac @ cov_cam @ jac.transpose(1, 2)  # [N, 2, 2]
    a = cov2d[:, 0, 0] + dilation
    b = cov2d[:, 0, 1]
    c = cov2d[:, 1, 1] + dilation
    det = a * c - b * b
    valid = in_front & (det > 0) & torch.isfinite(det) & torch.isfinite(t).all(dim=-1)  # non-finite: culled
    det_safe = torch.where(valid, det, torch.ones_like(det))
    conics = torch.stack([c / det_safe, -b / det_safe, a / det_safe], dim=-1)
    means2d = torch.stack([fx * t[:, 0] / z_safe + cx, fy * t[:, 1] / z_safe + cy], dim=-1)
    with torch.no_grad():
        mid = 0.5 * (a + c)
        lam_max = mid + torch.sqrt(torch.clamp_min(mid * mid - det_safe, 0.1))
        radii = torch.ceil(3.0 * torch.sqrt(lam_max)).clamp_max(1e6)
        radii = torch.where(torch.isfinite(radii), radii, torch.zeros_like(radii)).to(torch.int64)
        mx, my = means2d[:, 0], means2d[:, 1]
        on_screen = (mx + radii > 0) & (mx - radii < width) & (my + radii > 0) & (my - radii < height)
        radii = torch.where(valid & on_screen, radii, torch.zeros_like(radii))
    return Projection(means2d=means2d, conics=conics, depths=z, radii=radii)
