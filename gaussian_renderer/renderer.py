"""`render(camera, gaussians, background)`: the 3DGS-style renderer on top of `rasterization`."""
from __future__ import annotations

import torch

from gaussian_renderer.api import RasterOutput, rasterization
from gaussian_renderer.settings import RasterSettings

RenderOutput = RasterOutput


def render(camera, gaussians, background: torch.Tensor, settings: RasterSettings | None = None,
           override_color: torch.Tensor | None = None) -> RenderOutput:
    """Render `gaussians` (a GaussianModel) from `camera` (a scene.cameras.Camera).

    Colours come from the model's SH at its active degree, or from `override_color` [N, 3].
    """
    colors, degree = (override_color, None) if override_color is not None else (gaussians.sh_coeffs,
                                                                                 gaussians.active_sh_degree)
    return rasterization(gaussians.means, gaussians.quats, gaussians.scales, gaussians.opacities, colors,
                         camera.viewmat, camera.intrinsics, camera.width, camera.height, sh_degree=degree,
                         background=background, settings=settings)
