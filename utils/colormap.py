"""Colour-mapped scalar images on a log scale, and their colour bar (matplotlib, Agg backend)."""
from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

CMAP = "inferno"


def log_range(maps: list[np.ndarray]) -> tuple[float, float]:
    """(lo, hi) of log10 over the positive values of all `maps` (a shared scale); (0, 1) when none is positive."""
    positive = np.concatenate([m[m > 0].ravel() for m in maps]) if maps else np.zeros(0)
    if positive.size == 0:
        return 0.0, 1.0
    lo, hi = float(np.log10(positive.min())), float(np.log10(positive.max()))
    return lo, hi if hi > lo else lo + 1.0


def colorize_log(values: np.ndarray, lo: float, hi: float) -> torch.Tensor:
    """log10(values) mapped from [lo, hi] onto the colour map; values <= 0 get the lowest colour. [H, W] -> [3, H, W]"""
    logs = np.log10(np.where(values > 0, values, 10.0 ** lo))
    t = np.clip((logs - lo) / (hi - lo), 0.0, 1.0)
    rgb = matplotlib.colormaps[CMAP](t)[..., :3]  # [H, W, 3]
    return torch.from_numpy(rgb.astype(np.float32)).permute(2, 0, 1)


def save_colorbar(path: str | os.PathLike, lo: float, hi: float, label: str) -> None:
    """A vertical colour bar for `colorize_log`'s scale, ticks at powers of ten."""
    fig, ax = plt.subplots(figsize=(1.3, 3.0), dpi=100)
    norm = matplotlib.colors.LogNorm(vmin=10.0 ** lo, vmax=10.0 ** hi)
    fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=CMAP), cax=ax, label=label)
    ax.tick_params(labelsize=7)
    fig.subplots_adjust(left=0.05, right=0.35, top=0.95, bottom=0.05)
    os.makedirs(os.path.dirname(os.path.abspath(path)) or ".", exist_ok=True)
    fig.savefig(path)
    plt.close(fig)

