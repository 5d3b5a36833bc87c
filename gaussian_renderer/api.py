"""The public rasterization entry point and the per-Gaussian projection Jacobian used by the Fisher oracle."""
from __future__ import annotations

from dataclasses import dataclass

import torch

from gaussian_renderer.projection import project_gaussians
from gaussian_renderer.rasterize import rasterize
from gaussian_renderer.settings import RasterSettings
from gaussian_renderer.sh import num_sh_bases, sh_to_colors
from utils.errors import UserError


@dataclass
class RasterOutput:
    """What `rasterization` returns."""

    image: torch.Tensor  # [D, H, W]
    alpha: torch.Tensor  # [H, W]
    means2d: torch.Tensor  # [N, 2] pixels; .grad holds the screen-space gradient after backward (densification)
    radii: torch.Tensor  # [N] int64, 0 = not rendered
    visible: torch.Tensor  # [N] bool
    depths: torch.Tensor  # [N]


def camera_center(viewmat: torch.Tensor) -> torch.Tensor:
    """World position of the camera of a world-to-camera matrix. [4,4] -> [3]"""
    rot, trans = viewmat[:3, :3], viewmat[:3, 3]
    return -rot.T @ trans


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


PARAM_GROUPS = ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest")  # raw parameters, in order


def projection_jacobian(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
                        logit_opacities: torch.Tensor, sh_coeffs: torch.Tensor, sh_degree: int,
                        viewmat: torch.Tensor, intrinsics: torch.Tensor, width: int, height: int,
                        param_groups: tuple[str, ...] = ("means", "quats", "log_scales", "logit_opacities", "sh_dc"),
                        ) -> torch.Tensor:
    """Jacobian of each Gaussian's 2D attributes w.r.t. its own raw parameters.

    2D attributes (A = 9): mean2d x, y, conic a, b, c, opacity, colour RGB. Raw parameters, in `param_groups`
    order: means (3), quats (4, unnormalised), log_scales (3), logit_opacities (1), sh_dc (3), and with "sh_rest"
    the remaining SH coefficients (3 (K-1)). Gaussians are independent, so one backward pass per attribute gives
    that row for every Gaussian at once (A passes, no loop over Gaussians). Where the colour clamp max(., 0) is
    active the colour rows are 0 (as autograd of the renderer gives). Rows of culled Gaussians are finite but
    meaningless (the rasterizer gives them no pixels).

    Args:
        means: [N, 3]; quats: raw wxyz [N, 4]; log_scales: [N, 3]; logit_opacities: [N]; sh_coeffs: [N, K, 3]
        sh_degree: active SH degree for the colour; viewmat [4, 4], intrinsics [4], width, height: the camera.
        param_groups: which raw parameters form the columns, a subsequence of
            ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest") in any order.
    Returns:
        J, in the dtype of `means`. [N, A, P]
    """
    bad = [g for g in param_groups if g not in PARAM_GROUPS]
    if bad or len(set(param_groups)) != len(param_groups) or not param_groups:
        raise UserError(f"Fisher parameter groups {tuple(param_groups)} are invalid; choose distinct names from "
                        f"{', '.join(PARAM_GROUPS)}")
    n = means.shape[0]
    assert sh_coeffs.ndim == 3 and sh_coeffs.shape[0] == n and sh_coeffs.shape[1] >= num_sh_bases(sh_degree), \
        f"sh_coeffs must be [N,K,3] with N = {n}, K >= {num_sh_bases(sh_degree)}, got {tuple(sh_coeffs.shape)}"
    assert logit_opacities.shape == (n,), f"logit_opacities must be [N], got {tuple(logit_opacities.shape)}"
    assert log_scales.shape == (n, 3), f"log_scales must be [N,3], got {tuple(log_scales.shape)}"
    sh_dc, sh_rest = sh_coeffs[:, :1], sh_coeffs[:, 1:]
    raw = {"means": means, "quats": quats, "log_scales": log_scales, "logit_opacities": logit_opacities[:, None],
           "sh_dc": sh_dc, "sh_rest": sh_rest}
    leaves = {k: raw[k].detach().clone().requires_grad_(True) for k in param_groups}
    get = {k: leaves[k] if k in leaves else raw[k].detach() for k in raw}
    with torch.enable_grad():
        proj = project_gaussians(get["means"], get["quats"], torch.exp(get["log_scales"]), viewmat, intrinsics,
                                 width, height)
        colors = sh_to_colors(torch.cat([get["sh_dc"], get["sh_rest"]], dim=1), get["means"],
                              camera_center(viewmat).to(means.dtype), sh_degree)
        attrs = torch.cat([proj.means2d, proj.conics, torch.sigmoid(get["logit_opacities"]), colors], dim=1)  # [N, A]
        rows = []
        inputs = [leaves[k] for k in param_groups]
        for a in range(attrs.shape[1]):
            grads = torch.autograd.grad(attrs[:, a].sum(), inputs, retain_graph=True, allow_unused=True)
            rows.append(torch.cat([(g if g is not None else torch.zeros_like(x)).reshape(x.shape[0], -1)
                                   for g, x in zip(grads, inputs)], dim=1))
    return torch.stack(rows, dim=1)  # [N, A, P]
