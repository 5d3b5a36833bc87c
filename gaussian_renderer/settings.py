"""Rasterizer settings, grouped so that the public signatures stay small."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class RasterSettings:
    """Tile size, depth-chunk size and the compositing cut-offs (the original 3DGS values)."""

    tile_size: int = 4  # pixels per tile side (small tiles waste fewer pixel-Gaussian pairs; measured best on CPU)
    chunk_size: int = 32  # Gaussians per tile processed at once (bounds memory: tiles x tile_size^2 x chunk)
    alpha_min: float = 1.0 / 255.0  # contributions with a smaller alpha are skipped
    alpha_max: float = 0.99  # alpha is clamped here (keeps 1 - alpha away from 0)
    transmittance_min: float = 1e-4  # a pixel stops once its transmittance would fall below this
