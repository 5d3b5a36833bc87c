"""SSIM and PSNR against slow, explicit twins."""
import math

import torch

from utils.image import psnr
from utils.losses import ssim


def ssim_slow(img1, img2, size=11, sigma=1.5):
    """Per-pixel window sums with zero padding, float64, written out."""
    c, h, w = img1.shape
    x = torch.arange(size, dtype=torch.float64) - size // 2
    g1 = torch.exp(-x**2 / (2 * sigma**2))
    g1 = g1 / g1.sum()
    win = g1[:, None] * g1[None, :]
    pad = size // 2
    a = torch.nn.functional.pad(img1.double(), (pad, pad, pad, pad))
    b = torch.nn.functional.pad(img2.double(), (pad, pad, pad, pad))
    total = 0.0
    for ch in range(c):
        for i in range(h):
            for j in range(w):
                pa, pb = a[ch, i:i + size, j:j + size], b[ch, i:i + size, j:j + size]
                mu1, mu2 = (win * pa).sum(), (win * pb).sum()
                s1 = (win * pa * pa).sum() - mu1**2
                s2 = (win * pb * pb).sum() - mu2**2
                s12 = (win * pa * pb).sum() - mu1 * mu2
                total += ((2 * mu1 * mu2 + 1e-4) * (2 * s12 + 9e-4)) / ((mu1**2 + mu2**2 + 1e-4) * (s1 + s2 + 9e-4))
    return total / (c * h * w)


def test_ssim_matches_slow_twin():
    g = torch.Generator().manual_seed(0)
    a = torch.rand(3, 13, 17, generator=g, dtype=torch.float64)
    b = (a + 0.1 * torch.randn(3, 13, 17, generator=g, dtype=torch.float64)).clamp(0, 1)
    # float64: separable vs direct window sums differ by rounding only.
    assert abs(float(ssim(a, b)) - float(ssim_slow(a, b))) < 1e-10


def test_ssim_identity_and_gradient():
    a = torch.rand(3, 20, 20, requires_grad=True)
    assert abs(ssim(a.detach(), a.detach()).item() - 1.0) < 1e-5  # float32 rounding
    ssim(a, torch.rand(3, 20, 20)).backward()
    assert torch.isfinite(a.grad).all() and a.grad.abs().sum() > 0


def test_psnr_known_value():
    a = torch.zeros(3, 4, 4)
    b = torch.full((3, 4, 4), 0.1)
    assert abs(float(psnr(a, b)) - 20.0) < 1e-4  # MSE 0.01 -> 20 dB
