"""Pure-PyTorch differentiable Gaussian rasterizer (CPU first, runs unchanged on CUDA).

Shape letters used throughout: N Gaussians, C cameras, H/W image height/width, K SH bases ((degree+1)^2),
D colour channels, P parameters per Gaussian, A 2D attributes per Gaussian (6 + D), V candidate views,
M (pixel, Gaussian) pairs, T tiles.
"""
from gaussian_renderer.api import RasterOutput, projection_jacobian, rasterization
from gaussian_renderer.projection import Projection, project_gaussians
from gaussian_renderer.rasterize import attribute_gram, pixel_attribute_partials, rasterize
from gaussian_renderer.renderer import RenderOutput, render
from gaussian_renderer.settings import RasterSettings
from gaussian_renderer.sh import eval_sh, sh_to_colors

__all__ = ["RasterOutput", "RasterSettings", "RenderOutput", "Projection", "attribute_gram", "eval_sh",
           "pixel_attribute_partials", "project_gaussians", "projection_jacobian", "rasterization", "rasterize",
           "render", "sh_to_colors"]
