"""Slow, obviously correct twins of the fast rasterizer, for tests: every pixel against every Gaussian."""
from __future__ import annotations

import torch

from gaussian_renderer.settings import RasterSettings
from gaussian_renderer.tiles import tile_ranges


def rasterize_reference(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, colors: torch.Tensor,
                        depths: torch.Tensor, radii: torch.Tensor, width: int, height: int,
                        background: torch.Tensor, settings: RasterSettings | None = None,
                        tile_cutoff: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """Dense front-to-back compositing with plain autograd; same rules and cut-offs as `rasterize`.

    Loops over the non-culled Gaussians (radius > 0) in depth order, each against every pixel:
    alpha = min(alpha_max, o exp(power)), power = -1/2 d^T Q d, d = pixel centre - mean; the pair is skipped when
    alpha < alpha_min or power > 0, and a pixel stops (this Gaussian and all behind it skipped) once its
    transmittance would fall below transmittance_min. With `tile_cutoff` a Gaussian touches a pixel only if the
    pixel's tile lies in the Gaussian's tile rectangle (`tile_ranges`: its opacity-aware reach, capped by the
    3-sigma radius, rounded out to tiles), exactly the binning rule of the fast path; without it, every pixel.
    Returns image [D, H, W] and alpha [H, W] (1 - final transmittance).
    """
    s = settings or RasterSettings()
    ys, xs = torch.meshgrid(torch.arange(height, device=means2d.device), torch.arange(width, device=means2d.device),
                            indexing="ij")
    px, py = xs.reshape(-1).to(means2d.dtype) + 0.5, ys.reshape(-1).to(means2d.dtype) + 0.5  # [H*W]
    tile_x, tile_y = xs.reshape(-1) // s.tile_size, ys.reshape(-1) // s.tile_size
    x0, x1, y0, y1 = tile_ranges(means2d.detach(), conics.detach(), opacities.detach(), radii, width, height,
                                 s.tile_size, s.alpha_min)
    trans = torch.ones(height * width, dtype=means2d.dtype, device=means2d.device)
    done = torch.zeros(height * width, dtype=torch.bool, device=means2d.device)
    image = torch.zeros(height * width, colors.shape[1], dtype=means2d.dtype, device=means2d.device)
    for i in torch.argsort(depths.detach(), stable=True).tolist():
        if radii[i] <= 0:
            continue
        in_rect = (tile_x >= x0[i]) & (tile_x <= x1[i]) & (tile_y >= y0[i]) & (tile_y <= y1[i])
        dx, dy = px - means2d[i, 0], py - means2d[i, 1]
        power = -0.5 * (conics[i, 0] * dx * dx + conics[i, 2] * dy * dy) - conics[i, 1] * dx * dy
        alpha = torch.clamp_max(opacities[i] * torch.exp(power), s.alpha_max)
        use = (in_rect | (not tile_cutoff)) & (power <= 0) & (alpha >= s.alpha_min) & ~done
        stop = use & (trans * (1 - alpha) < s.transmittance_min)
        done = done | stop
        use = use & ~stop
        alpha = torch.where(use, alpha, torch.zeros_like(alpha))
        image = image + (alpha * trans)[:, None] * colors[i]
        trans = trans * (1 - alpha)
    image = image + trans[:, None] * background
    return image.T.reshape(-1, height, width), (1 - trans).reshape(height, width)
