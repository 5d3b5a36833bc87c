"""The public rasterization entry point: project, colour (SH), rasterize."""
from __future__ import annotations

from dataclasses import dataclass

import torch

from gaussian_renderer.projection import camera_center, project_gaussians
from gaussian_renderer.rasterize import rasterize
from gaussian_renderer.settings import RasterSettings
from gaussian_renderer.sh import num_sh_bases, sh_to_colors


@dataclass
class RasterOutput:
    """What `rasterization` returns."""

    image: torch.Tensor  # [D, H, W]
    alpha: torch.Tensor  # [H, W]
    means2d: torch.Tensor  # [N, 2] pixels; .grad holds the screen-space gradient after backward (densification)
    radii: torch.Tensor  # [N] int64, 0 = not rendered
    visible: torch.Tensor  # [N] bool
    depths: torch.Tensor  # [N]


def rasterization(means: torch.Tensor, quats: torch.Tensor, scales: torch.Tensor, opacities: torch.Tensor,
                  colors: torch.Tensor, viewmat: torch.Tensor, intrinsics: torch.Tensor, width: int, height: int,
                  sh_degree: int | None = None, background: torch.Tensor | None = None,
                  settings: RasterSettings | None = None) -> RasterOutput:
    """Render 3D Gaussians from one pinhole camera (differentiable w.r.t. every tensor input).

    Projects with `project_gaussians` (EWA, 0.3 px^2 dilation), evaluates SH colours if asked
    (view direction = mean - camera centre, colour = max(SH + 0.5, 0)), then composites with the tile rasterizer.
    After backward, `out.means2d.grad` holds the screen-space gradient 3DGS densification reads.

    Args:
        means: world-space centres. [N, 3]
        quats: rotations, wxyz, any norm. [N, 4]
        scales: activated scales. [N, 3]
        opacities: activated opacities. [N]
        colors: precomputed colours [N, D], or SH coefficients [N, K, 3] when `sh_degree` is given.
        viewmat: world-to-camera, OpenCV convention. [4, 4]
        intrinsics: (fx, fy, cx, cy) in pixels; pixel (x, y) has its centre at (x + 0.5, y + 0.5). [4]
        sh_degree: SH degree to evaluate (None = `colors` are final colours).
        background: colour behind the Gaussians (default black). [D]
        settings: tile size, chunk size and compositing cut-offs (default `RasterSettings()`).
    Returns:
        `RasterOutput` (image [D, H, W], alpha [H, W], means2d [N, 2], radii [N], visible [N], depths [N]).
        With zero Gaussians the image is the background and alpha is 0.
    """
    n = means.shape[0]
    assert means.ndim == 2 and means.shape[1] == 3, f"means must be [N,3], got {tuple(means.shape)}"
    assert quats.shape == (n, 4), f"quats must be [N,4] with N = {n}, got {tuple(quats.shape)}"
    assert scales.shape == (n, 3), f"scales must be [N,3] with N = {n}, got {tuple(scales.shape)}"
    assert opacities.shape == (n,), f"opacities must be [N] with N = {n}, got {tuple(opacities.shape)}"
    assert isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0, \
        f"width and height must be positive ints, got {width!r} x {height!r}"
    if sh_degree is not None:
        assert colors.ndim == 3 and colors.shape[0] == n and colors.shape[2] == 3 \
            and colors.shape[1] >= num_sh_bases(sh_degree), \
            f"SH colors must be [N,K,3] with N = {n}, K >= {num_sh_bases(sh_degree)}, got {tuple(colors.shape)}"
        colors = sh_to_colors(colors, means, camera_center(viewmat).to(means.dtype), sh_degree)
    assert colors.ndim == 2 and colors.shape[0] == n, \
        f"colors must be [N,D] with N = {n} (or [N,K,3] with sh_degree set), got {tuple(colors.shape)}"
    if background is None:
        background = torch.zeros(colors.shape[1], dtype=means.dtype, device=means.device)
    assert background.shape == (colors.shape[1],), \
        f"background must be [D] with D = {colors.shape[1]}, got {tuple(background.shape)}"
    proj = project_gaussians(means, quats, scales, viewmat, intrinsics, width, height)
    means2d = proj.means2d
    if means2d.requires_grad:
        means2d.retain_grad()
    image, alpha = rasterize(means2d, proj.conics, opacities, colors, proj.depths, proj.radii, width, height,
                             background.to(dtype=means.dtype, device=means.device), settings)
    return RasterOutput(image, alpha, means2d, proj.radii, proj.radii > 0, proj.depths)
