"""The torch rasterizer: tile-binned, depth-chunked alpha compositing of 2D Gaussians, with a recomputing backward.

Runs on any device (the compiled CPU kernels, `gaussian_renderer.compiled`, take CPU calls unless
`RasterSettings.backend` says "torch"). Binning, the chunk replay and the per-pair partials are the shared tile
engine, `gaussian_renderer.tiles`; this module adds the autograd function: the forward composites under no_grad and
the backward replays the chunks front to back and chains every pair's closed-form partials.
"""
from __future__ import annotations

import torch

from gaussian_renderer.compiled import use_compiled
from gaussian_renderer.settings import RasterSettings
from gaussian_renderer.tiles import (NUM_GEOMETRY_ATTRIBUTES, bin_gaussians, check_inputs, composite, from_image,
                                     iterate_chunks, scatter_rows, to_image)


class _RasterizeFunction(torch.autograd.Function):
    """Forward under no_grad; the backward replays the chunks front to back and chains in closed form."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, colors, background, bins, width, height, settings):
        final_color, trans = composite(bins, means2d, conics, opacities, colors, background, settings)
        ctx.save_for_backward(means2d, conics, opacities, colors, background, final_color, trans)
        ctx.bins, ctx.settings = bins, settings
        return to_image(final_color, bins, width, height), to_image((1 - trans)[..., None], bins, width, height)[0]

    @staticmethod
    def backward(ctx, grad_image, grad_alpha):
        means2d, conics, opacities, colors, background, final_color, trans_final = ctx.saved_tensors
        bins, settings = ctx.bins, ctx.settings
        n = means2d.shape[0]
        g_color = from_image(grad_image, bins)  # [T, P, D]
        # Scalar chain per pixel: dL/dalpha_i = (g.c_i) T_i - (g.F - g.prefix_incl_i + dL/dT_final T_final)
        # / (1 - alpha_i) with F the final colour, so no [.., D] tensor per pair is needed.
        g_final = (g_color * final_color).sum(-1)  # [T, P]
        g_final = g_final - from_image(grad_alpha[None], bins)[..., 0] * trans_final  # alpha = 1 - T_final
        g_prefix = torch.zeros_like(g_final)
        grad_geom = means2d.new_zeros(n, NUM_GEOMETRY_ATTRIBUTES)
        grad_colors = torch.zeros_like(colors)
        with torch.no_grad():
            for chunk in iterate_chunks(bins, means2d, conics, opacities, settings):
                safe = chunk.ids.clamp_min(0)
                g = g_color[chunk.tiles]  # [Ta, P, D]
                gc = torch.bmm(colors[safe], g.transpose(1, 2))  # [Ta, c, P]
                incl = g_prefix[chunk.tiles][:, None, :] + torch.cumsum(chunk.weight * gc, dim=1)
                g_prefix[chunk.tiles] = incl[:, -1]
                dl_dalpha = gc * chunk.trans - (g_final[chunk.tiles][:, None, :] - incl) / (1 - chunk.alpha)
                la = torch.where(chunk.unclamped, dl_dalpha * chunk.alpha, torch.zeros_like(dl_dalpha))
                lx, ly = la * chunk.dx, la * chunk.dy
                s_x, s_y = lx.sum(-1), ly.sum(-1)  # [Ta, c]
                s_xx, s_xy, s_yy = (lx * chunk.dx).sum(-1), (lx * chunk.dy).sum(-1), (ly * chunk.dy).sum(-1)
                s_o = torch.where(chunk.unclamped, dl_dalpha * chunk.gauss, torch.zeros_like(dl_dalpha)).sum(-1)
                q = conics[safe]  # [Ta, c, 3]
                per_gauss = torch.stack([q[..., 0] * s_x + q[..., 1] * s_y, q[..., 1] * s_x + q[..., 2] * s_y,
                                         -0.5 * s_xx, -s_xy, -0.5 * s_yy, s_o], dim=-1)  # [Ta, c, 6]
                grad_geom += scatter_rows(per_gauss, chunk.ids, n)
                grad_colors += scatter_rows(torch.bmm(chunk.weight, g), chunk.ids, n)
        grad_bg = (g_color * trans_final[..., None]).sum((0, 1))
        return (grad_geom[:, 0:2], grad_geom[:, 2:5], grad_geom[:, 5], grad_colors, grad_bg,
                None, None, None, None)


def rasterize(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, colors: torch.Tensor,
              depths: torch.Tensor, radii: torch.Tensor, width: int, height: int, background: torch.Tensor,
              settings: RasterSettings | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Alpha-composite projected Gaussians front to back (differentiable; fast path).

    Gradients flow to means2d, conics, opacities, colors and background (not to depths or radii).

    Args:
        means2d: screen centres in pixels (pixel centres at +0.5). [N, 2]
        conics: inverse 2D covariances (a, b, c) = [[a, b], [b, c]]. [N, 3]
        opacities: activated opacities. [N]
        colors: per-Gaussian colours. [N, D]
        depths: camera-space depth, for sorting. [N]
        radii: 3-sigma radius in pixels, 0 = culled. [N]
        background: colour behind everything. [D]
    Returns:
        image [D, H, W] and alpha [H, W] (1 - final transmittance).
    """
    settings = settings or RasterSettings()
    check_inputs(means2d, conics, opacities, colors, depths, radii, background)
    if use_compiled(settings.backend, means2d):
        from gaussian_renderer.compiled.ops import rasterize_compiled
        return rasterize_compiled(means2d, conics, opacities, colors, depths, radii, width, height, background,
                                  settings)
    bins = bin_gaussians(means2d, conics, opacities, radii, depths, width, height, settings)
    return _RasterizeFunction.apply(means2d, conics, opacities, colors, background, bins, width, height, settings)
