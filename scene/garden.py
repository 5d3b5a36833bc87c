"""The gsplat garden test scene (`../shared/data/gsplat_garden/test_garden.npz`): its 138,766 SfM points initialised
as 3DGS does, and its 3 cameras, at a multiple of the stored 648 x 420.

    gaussians, cameras, background, settings = load_garden("648x420")

The benchmarks' large real scene (`benchmarks/selection_cost.py`, `benchmarks/cost_study.py`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from gaussian_renderer import RasterSettings
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from utils.errors import UserError

GARDEN = Path(__file__).resolve().parents[2] / "shared" / "data" / "gsplat_garden" / "test_garden.npz"


def load_garden(size: str, sh_degree: int = 3) -> tuple[GaussianModel, list[Camera], torch.Tensor, RasterSettings]:
    """The garden Gaussians (SH degree `sh_degree`, all bands active), its cameras at `size` ("WxH", a multiple of
    648x420), a black background and the default rasterizer settings."""
    if not GARDEN.is_file():
        raise UserError(f"{GARDEN} not found (../shared/data/gsplat_garden)")
    try:
        width, height = (int(v) for v in size.split("x"))
    except ValueError:
        raise UserError(f"garden size {size!r}: give WxH, e.g. 648x420") from None
    data = np.load(GARDEN)
    scale = width / int(data["width"])
    gaussians = GaussianModel.from_point_cloud(torch.from_numpy(data["means3d"]).float(),
                                               torch.from_numpy(data["colors"]).float() / 255.0, sh_degree)
    gaussians.active_sh_degree = sh_degree
    cams = []
    for i, (view, k) in enumerate(zip(data["viewmats"], data["Ks"])):
        cams.append(Camera(i, f"garden{i}", torch.from_numpy(view).float(), float(k[0, 0]) * scale,
                           float(k[1, 1]) * scale, float(k[0, 2]) * scale, float(k[1, 2]) * scale, width, height))
    return gaussians, cams, torch.zeros(3), RasterSettings()
