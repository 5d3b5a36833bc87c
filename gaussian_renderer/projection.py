"""Projection of 3D Gaussians to the image plane (EWA splatting, pinhole camera). Pure tensor functions.

Conventions: quaternions are wxyz and normalised here (raw parameters may have any norm); `viewmat` is
world-to-camera in the OpenCV convention (x right, y down, z forward); intrinsics are (fx, fy, cx, cy) in pixels
and pixel (x, y) has its centre at (x + 0.5, y + 0.5), so a camera-space point lands at u = fx x / z + cx.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

FRUSTUM_MARGIN = 0.3  # 3DGS: x/z, y/z are clamped 0.3 tan(fov/2) beyond the image edges before building J
SIGMA_EXTENT = 3.0  # radius in standard deviations of the largest axis of the 2D covariance
MAX_RADIUS = 1e6  # keeps the integer radius finite for nearly degenerate, huge splats


def camera_center(viewmat: torch.Tensor) -> torch.Tensor:
    """World position of the camera of a world-to-camera matrix. [4,4] -> [3]"""
    return -viewmat[:3, :3].T @ viewmat[:3, 3]


def camera_centers(viewmats: torch.Tensor) -> torch.Tensor:
    """`camera_center` of a stack of world-to-camera matrices. [C, 4, 4] -> [C, 3]"""
    rot, trans = viewmats[:, :3, :3], viewmats[:, :3, 3]
    return -(rot.transpose(1, 2) @ trans[:, :, None])[:, :, 0]


def look_at_point(viewmats: torch.Tensor) -> torch.Tensor:
    """The point closest, in least squares, to every camera's optical axis (the scene centre the cameras look at).

    Minimises sum_c |(I - d_c d_c^T)(x - o_c)|^2 over x, with o_c the centre and d_c the viewing direction (+z of the
    camera frame) of camera c; a small ridge towards the mean centre keeps parallel axes well posed. [C, 4, 4] -> [3]
    """
    centers = camera_centers(viewmats).double()  # [C, 3]
    dirs = viewmats[:, 2, :3].double()  # camera +z in world coordinates (rows of R) [C, 3]
    dirs = dirs / dirs.norm(dim=-1, keepdim=True)
    eye = torch.eye(3, dtype=torch.float64, device=viewmats.device)
    proj = eye - dirs[:, :, None] * dirs[:, None, :]  # [C, 3, 3]
    ridge = 1e-9 * len(centers)
    lhs = proj.sum(0) + ridge * eye
    rhs = (proj @ centers[:, :, None]).sum(0)[:, 0] + ridge * centers.mean(0)
    return torch.linalg.solve(lhs, rhs).to(viewmats.dtype)


def quat_to_rotmat(quats: torch.Tensor) -> torch.Tensor:
    """Rotation matrices from quaternions (wxyz, normalised inside).

    Args:
        quats: rotations, any non-zero norm. [N, 4]
    Returns:
        R with R v = q v q*. [N, 3, 3]
    """
    assert quats.ndim == 2 and quats.shape[1] == 4, f"quats must be [N,4], got {tuple(quats.shape)}"
    q = quats / quats.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(-1, 3, 3)


def covariance_3d(quats: torch.Tensor, scales: torch.Tensor) -> torch.Tensor:
    """World-space covariance R S S^T R^T.

    Args:
        quats: rotations, wxyz, any norm. [N, 4]
        scales: activated (positive) standard deviations along the local axes. [N, 3]
    Returns:
        covariances. [N, 3, 3]
    """
    assert scales.ndim == 2 and scales.shape == (quats.shape[0], 3), \
        f"scales must be [N,3] with N = {quats.shape[0]}, got {tuple(scales.shape)}"
    m = quat_to_rotmat(quats) * scales[:, None, :]  # R S  [N, 3, 3]
    return m @ m.transpose(1, 2)


def near_plane_depths(z: torch.Tensor, near_plane: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(in_front [N] bool: z > near_plane, z_safe [N]: z there and 1 behind, so culled rows stay finite)."""
    in_front = z > near_plane
    return in_front, torch.where(in_front, z, torch.ones_like(z))


def frustum_limits(fx: torch.Tensor, fy: torch.Tensor, cx: torch.Tensor, cy: torch.Tensor, width: int,
                   height: int) -> tuple[tuple[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]:
    """((neg, pos) of x/z, (neg, pos) of y/z): where 3DGS clamps the ratios before building the EWA Jacobian, the
    image edges plus a margin of `FRUSTUM_MARGIN` tan(fov/2) (fov from fx/width and fy/height), each edge measured
    from the principal point; the ratio stays in [-neg, pos]."""
    margin_x, margin_y = FRUSTUM_MARGIN * width / (2 * fx), FRUSTUM_MARGIN * height / (2 * fy)
    pos_x, neg_x = (width - cx) / fx + margin_x, cx / fx + margin_x
    pos_y, neg_y = (height - cy) / fy + margin_y, cy / fy + margin_y
    return (neg_x, pos_x), (neg_y, pos_y)


def clamp_ratio(coord: torch.Tensor, z_safe: torch.Tensor, neg: torch.Tensor,
                pos: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """coord / z clamped to [-neg, pos] (`frustum_limits`), and where the clamp is inactive (derivative 1). [N] each"""
    ratio = coord / z_safe
    return torch.minimum(torch.maximum(ratio, -neg), pos), (ratio > -neg) & (ratio < pos)


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

    Sigma2D = J W Sigma W^T J^T + dilation I, where W is the camera rotation and J the Jacobian of
    (x, y, z) -> (fx x / z + cx, fy y / z + cy). As in 3DGS, x/z and y/z are clamped before building J to the
    image edges plus a margin of 0.3 tan(fov/2) (fov from fx/width and fy/height), each edge measured from the
    principal point so off-centre principal points work; for a centred one this is the 3DGS 1.3 tan(fov/2).
    The clamp only shapes J: means2d are the true projections. The `dilation` term is the 3DGS anti-aliasing
    low-pass filter. radius = ceil(3 sqrt(largest eigenvalue of Sigma2D)). Culled (radius 0): centres with
    z <= near_plane, non-invertible or non-finite 2D covariances, and Gaussians whose radius box
    [u - r, u + r] x [v - r, v + r] misses the image [0, width] x [0, height].

    Args:
        means: world-space centres. [N, 3]
        quats: rotations, wxyz, any norm. [N, 4]
        scales: activated scales. [N, 3]
        viewmat: world-to-camera, OpenCV convention (x right, y down, z forward). [4, 4]
        intrinsics: (fx, fy, cx, cy) in pixels. [4]
        width, height: image size in pixels.
        near_plane: smallest camera-space depth that is rendered.
        dilation: pixels^2 added to the diagonal of the 2D covariance.
    Returns:
        `Projection` (means2d [N, 2], conics [N, 3], depths [N], radii [N] int64). Differentiable w.r.t. means,
        quats, scales (and viewmat, intrinsics); radii are not.
    """
    n = means.shape[0]
    assert means.ndim == 2 and means.shape[1] == 3, f"means must be [N,3], got {tuple(means.shape)}"
    assert quats.shape == (n, 4), f"quats must be [N,4] with N = {n}, got {tuple(quats.shape)}"
    assert scales.shape == (n, 3), f"scales must be [N,3] with N = {n}, got {tuple(scales.shape)}"
    assert viewmat.shape == (4, 4), f"viewmat must be [4,4], got {tuple(viewmat.shape)}"
    assert intrinsics.shape == (4,), f"intrinsics must be [4] = (fx, fy, cx, cy), got {tuple(intrinsics.shape)}"
    fx, fy, cx, cy = intrinsics.to(means.dtype).unbind(-1)
    rot, trans = viewmat[:3, :3].to(means.dtype), viewmat[:3, 3].to(means.dtype)
    t = means @ rot.T + trans  # [N, 3] camera space
    z = t[:, 2]
    in_front, z_safe = near_plane_depths(z, near_plane)  # z_safe keeps culled rows finite (and their gradients 0)
    (neg_x, pos_x), (neg_y, pos_y) = frustum_limits(fx, fy, cx, cy, width, height)
    tx = z_safe * clamp_ratio(t[:, 0], z_safe, neg_x, pos_x)[0]  # [N]
    ty = z_safe * clamp_ratio(t[:, 1], z_safe, neg_y, pos_y)[0]
    zeros = torch.zeros_like(z_safe)
    jac = torch.stack([fx / z_safe, zeros, -fx * tx / z_safe**2,
                       zeros, fy / z_safe, -fy * ty / z_safe**2], dim=-1).reshape(n, 2, 3)  # [N, 2, 3]
    cov_cam = rot @ covariance_3d(quats, scales) @ rot.T  # [N, 3, 3]
    cov2d = jac @ cov_cam @ jac.transpose(1, 2)  # [N, 2, 2]
    a = cov2d[:, 0, 0] + dilation
    b = cov2d[:, 0, 1]
    c = cov2d[:, 1, 1] + dilation
    det = a * c - b * b
    valid = in_front & (det > 0) & torch.isfinite(det) & torch.isfinite(t).all(dim=-1)
    det_safe = torch.where(valid, det, torch.ones_like(det))
    conics = torch.stack([c / det_safe, -b / det_safe, a / det_safe], dim=-1)  # [N, 3]
    means2d = torch.stack([fx * t[:, 0] / z_safe + cx, fy * t[:, 1] / z_safe + cy], dim=-1)  # [N, 2]
    with torch.no_grad():
        mid = 0.5 * (a + c)
        lam_max = mid + torch.sqrt(torch.clamp_min(mid * mid - det_safe, 0.0))  # largest eigenvalue of Sigma2D
        radii = torch.ceil(SIGMA_EXTENT * torch.sqrt(lam_max)).clamp_max(MAX_RADIUS)
        radii = torch.where(torch.isfinite(radii), radii, torch.zeros_like(radii)).to(torch.int64)
        u, v, r = means2d[:, 0], means2d[:, 1], radii.to(means2d.dtype)
        on_screen = (u + r > 0) & (u - r < width) & (v + r > 0) & (v - r < height)
        radii = torch.where(valid & on_screen, radii, torch.zeros_like(radii))
    return Projection(means2d=means2d, conics=conics, depths=z, radii=radii)
