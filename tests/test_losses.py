"""utils.losses: SSIM against an explicit per-pixel twin, gradients, PSNR and L1 closed forms."""
from __future__ import annotations

import math

import pytest
import torch

from utils.losses import l1_loss, photometric_loss, psnr, ssim


def ssim_reference(img1: torch.Tensor, img2: torch.Tensor) -> float:
    """Mean SSIM written out: per pixel, explicit sums over the 11x11 window (zero outside the image), float64.

    img1, img2: [C, H, W]. Constants are restated here rather than imported, so a wrong constant fails the test.
    """
    size, sigma, c1, c2 = 11, 1.5, 0.01**2, 0.03**2
    half = size // 2
    g = [math.exp(-((i - half) ** 2) / (2 * sigma**2)) for i in range(size)]
    g = [v / sum(g) for v in g]
    a, b = img1.double().tolist(), img2.double().tolist()
    channels, height, width = img1.shape
    total = 0.0
    for ch in range(channels):
        for y in range(height):
            for x in range(width):
                mu1 = mu2 = e11 = e22 = e12 = 0.0
                for dy in range(-half, half + 1):
                    for dx in range(-half, half + 1):
                        yy, xx = y + dy, x + dx
                        if not (0 <= yy < height and 0 <= xx < width):
                            continue  # zero padding
                        w = g[dy + half] * g[dx + half]
                        p, q = a[ch][yy][xx], b[ch][yy][xx]
                        mu1 += w * p
                        mu2 += w * q
                        e11 += w * p * p
                        e22 += w * q * q
                        e12 += w * p * q
                s1, s2, s12 = e11 - mu1 * mu1, e22 - mu2 * mu2, e12 - mu1 * mu2
                total += ((2 * mu1 * mu2 + c1) * (2 * s12 + c2)) / ((mu1 * mu1 + mu2 * mu2 + c1) * (s1 + s2 + c2))
    return total / (channels * height * width)


def _pair(shape, seed=0, noise=0.1, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    a = torch.rand(*shape, generator=g, dtype=torch.float64)
    b = (a + noise * torch.randn(*shape, generator=g, dtype=torch.float64)).clamp(0, 1)
    return a.to(dtype), b.to(dtype)


@pytest.mark.parametrize("shape", [(3, 13, 17), (3, 6, 4), (1, 12, 12)])  # odd sizes, smaller than the window
def test_ssim_matches_reference(shape):
    a, b = _pair(shape)
    ref = ssim_reference(a, b)
    # float64: separable filtering vs explicit window sums differ by summation order only.
    assert abs(float(ssim(a, b)) - ref) < 1e-12
    # float32 inputs: the SSIM map's rounding (variances from E[x^2] - mu^2) averages out far below 1e-6.
    assert abs(float(ssim(a.float(), b.float())) - ref) < 1e-6


def test_ssim_batch_is_mean_of_images():
    a, b = _pair((2, 3, 9, 10), seed=1)
    expected = (ssim(a[0], b[0]) + ssim(a[1], b[1])) / 2
    torch.testing.assert_close(ssim(a, b), expected, rtol=0, atol=1e-14)  # float64 rounding


def test_ssim_identity_and_symmetry():
    a, b = _pair((3, 20, 20), seed=2, dtype=torch.float32)
    assert abs(ssim(a, a).item() - 1.0) < 1e-6  # float32 rounding of (x + C) / (x + C)
    assert abs(ssim(a, b).item() - ssim(b, a).item()) < 1e-6  # float32; the formula is symmetric
    assert ssim(a, b).item() < 0.99  # noise of 0.1 must lower SSIM visibly


def test_ssim_gradient_matches_finite_differences():
    a, b = _pair((2, 6, 7), seed=3)
    a.requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: ssim(x, b), (a,))  # float64, default gradcheck tolerances


def test_ssim_rejects_mismatched_shapes():
    with pytest.raises(AssertionError, match="shapes differ"):
        ssim(torch.zeros(3, 4, 4), torch.zeros(3, 4, 5))


def test_psnr_closed_forms():
    a = torch.zeros(3, 4, 4)
    assert abs(psnr(a, torch.full((3, 4, 4), 0.1)).item() - 20.0) < 1e-4  # MSE 0.01 -> 20 dB; float32 rounding
    # One pixel in one channel off by 1: MSE = 1 / 48 -> 10 log10(48).
    b = a.clone()
    b[1, 2, 3] = 1.0
    assert abs(psnr(a, b).item() - 10 * math.log10(48)) < 1e-4  # float32 rounding
    assert psnr(a, a).item() == math.inf  # MSE 0


def test_psnr_batched_is_per_image():
    a = torch.zeros(2, 3, 4, 4, dtype=torch.float64)
    b = torch.stack([torch.full((3, 4, 4), 0.1), torch.full((3, 4, 4), 0.01)]).double()
    torch.testing.assert_close(psnr(a, b), torch.tensor([20.0, 40.0], dtype=torch.float64))  # float64 defaults


def test_l1_closed_form():
    a = torch.zeros(2, 3, 3)
    b = torch.arange(18, dtype=torch.float32).reshape(2, 3, 3)
    assert l1_loss(a, b).item() == 8.5  # mean of 0..17, exact in float32


def test_photometric_loss_is_the_3dgs_mix():
    """0.8 L1 + 0.2 (1 - SSIM) by default (the 3DGS weights, written out here), lambda as given otherwise."""
    g = torch.Generator().manual_seed(3)
    a, b = torch.rand(3, 16, 12, generator=g), torch.rand(3, 16, 12, generator=g)
    l1, s = (a - b).abs().mean(), ssim(a, b)
    assert torch.allclose(photometric_loss(a, b), 0.8 * l1 + 0.2 * (1 - s))
    assert torch.allclose(photometric_loss(a, b, 0.5), 0.5 * l1 + 0.5 * (1 - s))
