"""Rasterizer settings, grouped so that the public signatures stay small."""
from __future__ import annotations

from dataclasses import dataclass

from utils.errors import UserError

ALPHA_MIN_FLOOR = 1e-9  # smallest alpha_min: `compiled.row_kernels.exp_neg` is exact down to exp(-22)


@dataclass(frozen=True)
class RasterSettings:
    """Tile size, depth-chunk size and the compositing cut-offs (the original 3DGS values)."""

    tile_size: int = 4  # pixels per tile side (small tiles waste fewer pixel-Gaussian pairs; measured best on CPU)
    chunk_size: int = 32  # Gaussians per tile processed at once (bounds memory: tiles x tile_size^2 x chunk)
    alpha_min: float = 1.0 / 255.0  # contributions with a smaller alpha are skipped
    alpha_max: float = 0.99  # alpha is clamped here (keeps 1 - alpha away from 0)
    transmittance_min: float = 1e-4  # a pixel stops once its transmittance would fall below this
    backend: str = "auto"  # "torch", "compiled" (numba CPU kernels) or "auto" (compiled when numba imports)

    def __post_init__(self) -> None:
        if not (isinstance(self.tile_size, int) and self.tile_size >= 1):
            raise UserError(f"tile_size must be a positive integer, got {self.tile_size!r}; use e.g. --tile_size 4")
        if not (isinstance(self.chunk_size, int) and self.chunk_size >= 1):
            raise UserError(f"chunk_size must be a positive integer, got {self.chunk_size!r}; use e.g. 32")
        if not 0 < self.alpha_min < self.alpha_max < 1:
            raise UserError(f"need 0 < alpha_min < alpha_max < 1, got {self.alpha_min} and {self.alpha_max}; "
                            "use the defaults 1/255 and 0.99")
        if self.alpha_min < ALPHA_MIN_FLOOR:
            raise UserError(f"alpha_min must be at least {ALPHA_MIN_FLOOR:g} (the compiled kernels' exp covers "
                            f"exp(-22) and up), got {self.alpha_min}; use the default 1/255")
        if not 0 <= self.transmittance_min < 1:
            raise UserError(f"transmittance_min must be in [0, 1), got {self.transmittance_min}; use 1e-4")
        from gaussian_renderer.compiled import BACKENDS, NUMBA_HINT, numba_import_error
        if self.backend not in BACKENDS:
            raise UserError(f"rasterizer backend must be one of {', '.join(BACKENDS)}, got {self.backend!r}")
        if self.backend == "compiled" and numba_import_error() is not None:
            raise UserError(NUMBA_HINT)
