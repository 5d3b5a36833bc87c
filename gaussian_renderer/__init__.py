"""Pure-PyTorch differentiable Gaussian rasterizer (CPU first, runs unchanged on CUDA).

Shape letters used throughout:
    N  Gaussians                      C  cameras
    H  image height (pixels)          W  image width (pixels)
    K  SH bases, (degree + 1)^2       D  colour channels
    P  parameters per Gaussian        A  2D attributes per Gaussian (mean x, y, conic a, b, c, opacity,
    V  candidate views                   colour: 6 + D, = 9 for RGB)
    M  (pixel, Gaussian) pairs        T  tiles

Conventions: world-to-camera `viewmat [4, 4]` in the OpenCV convention (x right, y down, z forward); intrinsics
(fx, fy, cx, cy) in pixels; pixel (x, y) has its centre at (x + 0.5, y + 0.5); quaternions wxyz, normalised
inside the projection; conics (a, b, c) = [[a, b], [b, c]], the inverse 2D covariance.
"""
from gaussian_renderer.api import RasterOutput, rasterization
from gaussian_renderer.fisher_partials import (attribute_gram, pixel_attribute_partials, project_and_shade,
                                              projection_jacobian, seen_attribute_gram)
from gaussian_renderer.projection import Projection, camera_center, project_gaussians
from gaussian_renderer.rasterize import rasterize
from gaussian_renderer.renderer import RenderOutput, render
from gaussian_renderer.settings import RasterSettings
from gaussian_renderer.sh import eval_sh, sh_to_colors

__all__ = ["RasterOutput", "RasterSettings", "RenderOutput", "Projection", "attribute_gram", "camera_center", "eval_sh",
           "pixel_attribute_partials", "project_and_shade", "project_gaussians", "projection_jacobian",
           "rasterization", "rasterize",
           "render", "seen_attribute_gram", "sh_to_colors"]
