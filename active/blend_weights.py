"""How much of a view's image each Gaussian paints: its blend weight summed over the pixels, sum_px alpha_i T_i.

The rendered colour is linear in the colours, C(px) = sum_i c_i alpha_i(px) T_i(px), so with one scalar colour
c_i = 1 per Gaussian the gradient of the summed image with respect to c_i is exactly sum_px alpha_i(px) T_i(px):
one forward and one backward pass of the rasterizer per view, occlusion included (a Gaussian behind an opaque
surface gets ~0). The weights of a view sum to its summed alpha (every pixel's opacity, split among the Gaussians
that paint it).
"""
from __future__ import annotations

import torch

from gaussian_renderer import rasterization
from gaussian_renderer.settings import RasterSettings
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel

VISIBLE_PIXELS = 1.0 / 255.0  # a Gaussian is visible in a view when it paints at least one 8-bit level of one pixel


def blend_weights(gaussians: GaussianModel, camera: Camera, settings: RasterSettings | None = None) -> torch.Tensor:
    """sum over `camera`'s pixels of each Gaussian's blend weight alpha_i T_i, in pixels. [N] float64, on the CPU"""
    ones = torch.ones(gaussians.means.shape[0], 1, dtype=gaussians.means.dtype, device=gaussians.means.device,
                      requires_grad=True)  # [N, 1] one scalar colour per Gaussian
    with torch.enable_grad():
        out = rasterization(gaussians.means.detach(), gaussians.quats.detach(), gaussians.scales.detach(),
                            gaussians.opacities.detach(), ones, camera.viewmat, camera.intrinsics, camera.width,
                            camera.height, background=torch.zeros(1, device=ones.device), settings=settings)
        (weights,) = torch.autograd.grad(out.image.sum(), ones)
    return weights[:, 0].detach().double().cpu()
