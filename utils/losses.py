"""Training losses and the image metrics of the 3DGS evaluation (L1, SSIM with an 11x11 Gaussian window, PSNR).

SSIM follows the graphdeco 3DGS definition: a Gaussian window of size 11 and sigma 1.5 (the outer product of the
normalised 1D window), zero padding of 5, per-channel filtering, C1 = 0.01^2, C2 = 0.03^2 (images in [0, 1]) and the
mean over the whole SSIM map. The 2D filter is applied as two 1D passes, which gives the same numbers (the 2D
window is separable and zero padding commutes with the split) at 2x11 instead of 121 multiplies per pixel.
"""
from __future__ import annotations

import functools

import torch
import torch.nn.functional as F

SSIM_WINDOW_SIZE = 11
SSIM_SIGMA = 1.5
SSIM_C1 = 0.01**2
SSIM_C2 = 0.03**2


def l1_loss(img1: torch.Tensor, img2: torch.Tensor) -> torch.Tensor:
    """Mean absolute difference over all elements of two same-shaped images. Scalar tensor."""
    assert img1.shape == img2.shape, f"shapes differ: {tuple(img1.shape)} vs {tuple(img2.shape)}"
    return (img1 - img2).abs().mean()


def psnr(img1: torch.Tensor, img2: torch.Tensor) -> torch.Tensor:
    """PSNR in dB of images in [0, 1], from the MSE over each whole image (all pixels and channels).

    Identical images give +inf (MSE 0), as the formula says.

    Args:
        img1, img2: Images. [3, H, W] or [B, 3, H, W]
    Returns:
        Scalar tensor for [3, H, W] inputs, per-image PSNRs [B] for batches.
    """
    assert img1.shape == img2.shape, f"shapes differ: {tuple(img1.shape)} vs {tuple(img2.shape)}"
    assert img1.dim() in (3, 4), f"expected [3, H, W] or [B, 3, H, W], got {tuple(img1.shape)}"
    diff = (img1 - img2) ** 2
    mse = diff.mean() if diff.dim() == 3 else diff.flatten(1).mean(dim=1)  # [] or [B]
    return 10.0 * torch.log10(1.0 / mse)


@functools.lru_cache(maxsize=8)
def _gaussian_window_1d(size: int, sigma: float, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """Normalised 1D Gaussian centred on index size // 2. [size]"""
    x = torch.arange(size, dtype=torch.float64) - size // 2
    g = torch.exp(-(x**2) / (2 * sigma**2))
    return (g / g.sum()).to(dtype=dtype, device=device)


def _blur(x: torch.Tensor, window: torch.Tensor) -> torch.Tensor:
    """Per-channel separable Gaussian filter with zero padding, same size out. x: [B, C, H, W], window: [k]"""
    c, k = x.shape[1], window.numel()
    wx = window.view(1, 1, 1, k).expand(c, 1, 1, k)  # [C, 1, 1, k]
    wy = window.view(1, 1, k, 1).expand(c, 1, k, 1)  # [C, 1, k, 1]
    return F.conv2d(F.conv2d(x, wx, padding=(0, k // 2), groups=c), wy, padding=(k // 2, 0), groups=c)


def ssim(img1: torch.Tensor, img2: torch.Tensor) -> torch.Tensor:
    """Mean SSIM of two images in [0, 1] as in the 3DGS evaluation (differentiable).

    Args:
        img1, img2: Images. [C, H, W] or [B, C, H, W]
    Returns:
        Scalar tensor: the mean of the SSIM map over batch, channels and pixels.
    """
    return ssim_map(img1, img2).mean()


def ssim_map(img1: torch.Tensor, img2: torch.Tensor) -> torch.Tensor:
    """The per-pixel SSIM map behind `ssim` (zero padding at the border). [C, H, W] or [B, C, H, W] -> [B, C, H, W]"""
    assert img1.shape == img2.shape, f"shapes differ: {tuple(img1.shape)} vs {tuple(img2.shape)}"
    assert img1.dim() in (3, 4), f"expected [C, H, W] or [B, C, H, W], got {tuple(img1.shape)}"
    if img1.dim() == 3:
        img1, img2 = img1[None], img2[None]
    window = _gaussian_window_1d(SSIM_WINDOW_SIZE, SSIM_SIGMA, img1.dtype, img1.device)
    # One filtering pass over the five moment images. [B, 5C, H, W]
    moments = _blur(torch.cat([img1, img2, img1 * img1, img2 * img2, img1 * img2], dim=1), window)
    mu1, mu2, e11, e22, e12 = moments.split(img1.shape[1], dim=1)
    mu1_sq, mu2_sq, mu12 = mu1 * mu1, mu2 * mu2, mu1 * mu2
    sigma1_sq, sigma2_sq, sigma12 = e11 - mu1_sq, e22 - mu2_sq, e12 - mu12
    return ((2 * mu12 + SSIM_C1) * (2 * sigma12 + SSIM_C2)) / (
        (mu1_sq + mu2_sq + SSIM_C1) * (sigma1_sq + sigma2_sq + SSIM_C2))


LAMBDA_DSSIM = 0.2  # the 3DGS training loss: (1 - 0.2) L1 + 0.2 D-SSIM (the default of train.py --lambda_dssim)


def photometric_loss(image: torch.Tensor, gt: torch.Tensor, lambda_dssim: float = LAMBDA_DSSIM) -> torch.Tensor:
    """The 3DGS training loss (1 - lambda) L1 + lambda (1 - SSIM) of a rendered image against its target.

    Args:
        image, gt: Images in [0, 1]. [3, H, W]
    Returns:
        Scalar tensor (differentiable in both images).
    """
    return (1.0 - lambda_dssim) * l1_loss(image, gt) + lambda_dssim * (1.0 - ssim(image, gt))
