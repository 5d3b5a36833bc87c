"""Training losses and the SSIM of the 3DGS evaluation (11x11 Gaussian window, sigma 1.5)."""
from __future__ import annotations

import functools
import math

import torch
import torch.nn.functional as F

SSIM_C1 = 0.01**2
SSIM_C2 = 0.03**2


def l1_loss(img1: torch.Tensor, img2: torch.Tensor) -> torch.Tensor:
    return (img1 - img2).abs().mean()


@functools.lru_cache(maxsize=8)
def _gaussian_window_1d(size: int, sigma: float, dtype: torch.dtype, device: str) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float64) - size // 2
    g = torch.exp(-(x**2) / (2 * sigma**2))
    return (g / g.sum()).to(dtype=dtype, device=device)


def _blur(x: torch.Tensor, window: torch.Tensor) -> torch.Tensor:
    """Separable Gaussian filter with zero padding (same as the 3DGS 2D conv). x: [B, C, H, W]"""
    c, k = x.shape[1], window.numel()
    wx = window.view(1, 1, 1, k).expand(c, 1, 1, k)
    wy = window.view(1, 1, k, 1).expand(c, 1, k, 1)
    return F.conv2d(F.conv2d(x, wx, padding=(0, k // 2), groups=c), wy, padding=(k // 2, 0), groups=c)


def ssim(img1: torch.Tensor, img2: torch.Tensor, window_size: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """Mean SSIM of images [C, H, W] or [B, C, H, W] in [0, 1] (differentiable)."""
    if img1.dim() == 3:
        img1, img2 = img1[None], img2[None]
    window = _gaussian_window_1d(window_size, sigma, img1.dtype, str(img1.device))
    stacked = _blur(torch.cat([img1, img2, img1 * img1, img2 * img2, img1 * img2], dim=1), window)
    mu1, mu2, s11, s22, s12 = stacked.split(img1.shape[1], dim=1)
    mu1_sq, mu2_sq, mu12 = mu1 * mu1, mu2 * mu2, mu1 * mu2
    sigma1, sigma2, sigma12 = s11 - mu1_sq, s22 - mu2_sq, s12 - mu12
    ssim_map = ((2 * mu12 + SSIM_C1) * (2 * sigma12 + SSIM_C2)) / (
        (mu1_sq + mu2_sq + SSIM_C1) * (sigma1 + sigma2 + SSIM_C2))
    return ssim_map.mean()
