"""`render(camera, gaussians, background)`: the 3DGS-style renderer on top of `rasterization`."""
from __future__ import annotations

import torch

from gaussian_renderer.api import RasterOutput, rasterization
from gaussian_renderer.settings import RasterSettings

RenderOutput = RasterOutput  # image [3,H,W], alpha [H,W], means2d [N,2] (grad retained), radii [N], visible, depths


def render(camera, gaussians, background: torch.Tensor, settings: RasterSettings | None = None,
           override_color: torch.Tensor | None = None) -> RenderOutput:
    """Render a Gaussian model from one camera, as graphdeco's `render` does.

    Colours come from the model's SH at its active degree (view direction = mean - camera centre), or from
    `override_color` when given. Gradients reach the model's raw parameters through its activations
    (exp scales, sigmoid opacities, the projection normalising the raw quaternions).

    Args:
        camera: has `viewmat` [4, 4] (world-to-camera, OpenCV), `intrinsics` [4], `width`, `height`
            (a `scene.cameras.Camera`).
        gaussians: has `means` [N, 3], `quats` [N, 4] (wxyz, any norm), `scales` [N, 3], `opacities` [N],
            `sh_coeffs` [N, K, 3] and `active_sh_degree` (a `scene.gaussian_model.GaussianModel`).
        background: colour behind the Gaussians. [3]
        settings: rasterizer settings (default `RasterSettings()`).
        override_color: precomputed per-Gaussian colours instead of SH. [N, 3]
    Returns:
        `RenderOutput`.
    """
    if override_color is not None:
        assert override_color.shape == (gaussians.means.shape[0], 3), \
            f"override_color must be [N,3], got {tuple(override_color.shape)}"
        colors, degree = override_color, None
    else:
        colors, degree = gaussians.sh_coeffs, gaussians.active_sh_degree
    return rasterization(gaussians.means, gaussians.quats, gaussians.scales, gaussians.opacities, colors,
                         camera.viewmat, camera.intrinsics, camera.width, camera.height, sh_degree=degree,
                         background=background, settings=settings)
