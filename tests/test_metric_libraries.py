"""The hand-written metrics against well-kept libraries: SSIM against scikit-image's structural_similarity, PSNR
against its peak_signal_noise_ratio, Spearman against scipy.stats.spearmanr; on random images and on real lego
frames (skipped without /work/shared/data/lego); AUSE variants on cases with a known answer.

SSIM settings that make scikit-image compute the 3DGS definition: gaussian_weights=True, sigma=1.5 (scipy's
truncate 3.5 gives the 11 x 11 window), use_sample_covariance=False, data_range=1.0, K1 = 0.01, K2 = 0.03 (its
defaults), channel_axis=0. The two differ only at the border: 3DGS pads with zeros and averages the whole map,
scikit-image reflects and averages the map without a 5-pixel border. Tolerances: the maps' interiors agree to 1e-10
in float64 and to 1e-3 in float32 (sigma^2 = E[x^2] - mu^2 cancels in float32 where the image is flat near 1, as
on Blender's white background, and is then divided by C2 = 9e-4); PSNR to 1e-4 dB; Spearman to 1e-12.
"""
import math
import os
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.stats import spearmanr
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from utils.errors import UserError
from utils.losses import psnr, ssim, ssim_map
from utils.uncertainty_metrics import AUSE_VARIANTS, ause, parse_ause_variants, spearman

LEGO = Path(os.environ.get("LITEGS_SHARED", Path(__file__).resolve().parents[2] / "shared")) / "data" / "lego"
BORDER = 5  # (11 - 1) // 2: scikit-image's crop


def skimage_ssim(a: torch.Tensor, b: torch.Tensor) -> tuple[float, np.ndarray]:
    """(mean, full map) from scikit-image with the 3DGS settings. [3, H, W] x2"""
    mean, full = structural_similarity(a.double().numpy(), b.double().numpy(), gaussian_weights=True, sigma=1.5,
                                       use_sample_covariance=False, data_range=1.0, channel_axis=0, full=True)
    return float(mean), full


def check_against_libraries(a: torch.Tensor, b: torch.Tensor) -> None:
    """Assert that the SSIM maps' interiors, scikit-image's mean and PSNR agree."""
    mean, full = skimage_ssim(a, b)
    inner = (slice(None), slice(BORDER, -BORDER), slice(BORDER, -BORDER))
    np.testing.assert_allclose(ssim_map(a.double(), b.double())[0].numpy()[inner], full[inner], rtol=0, atol=1e-10)
    np.testing.assert_allclose(ssim_map(a, b)[0].double().numpy()[inner], full[inner], rtol=0, atol=1e-3)
    assert mean == pytest.approx(full[inner].mean(), abs=1e-12)  # scikit-image's mean: the map without the border
    expected_psnr = peak_signal_noise_ratio(a.double().numpy(), b.double().numpy(), data_range=1.0)
    assert psnr(a, b).item() == pytest.approx(expected_psnr, abs=1e-4)


def test_ssim_and_psnr_match_scikit_image_on_random_images():
    g = torch.Generator().manual_seed(0)
    a = torch.rand(3, 40, 48, generator=g)
    b = (a + 0.1 * torch.randn(3, 40, 48, generator=g)).clamp(0, 1)
    check_against_libraries(a, b)


@pytest.mark.skipif(not (LEGO / "train" / "r_0.png").is_file(), reason=f"real lego frames not found under {LEGO}")
def test_ssim_and_psnr_match_scikit_image_on_real_lego_frames():
    from scene.frames import load_composited

    white = torch.ones(3)
    a = load_composited(LEGO / "train" / "r_0.png", (100, 100), white)  # [3, 100, 100]
    b = load_composited(LEGO / "train" / "r_1.png", (100, 100), white)  # a neighbouring view: a real "error"
    blurred = torch.nn.functional.avg_pool2d(a[None], 3, stride=1, padding=1, count_include_pad=False)[0]
    for other in (b, blurred):
        check_against_libraries(a, other)
    # The whole-map means differ by the border only (docs/deviations.md: 0.083 for these two 100 px frames).
    assert ssim(a.double(), b.double()).item() > skimage_ssim(a, b)[0]


def test_spearman_matches_scipy_with_ties():
    rng = np.random.default_rng(1)
    x = rng.integers(0, 6, size=500).astype(float)  # many ties
    y = x + rng.normal(size=500)
    for u, v in ((x, y), (y, x ** 2), (x, rng.integers(0, 3, size=500))):
        assert spearman(u, v) == pytest.approx(spearmanr(u, v).statistic, abs=1e-12)


def test_ause_variants_known_answers():
    errors = np.array([1.0, 2.0, 3.0, 4.0])
    for variant in AUSE_VARIANTS:  # the error itself as uncertainty: the oracle, AUSE 0
        assert ause(errors * 7, errors, bins=4, variant=variant) == pytest.approx(0.0, abs=1e-12)
    # Reversed order, MAE, 4 bins: after removing 0..3 pixels the MAE left is
    # oracle    10/4, 6/3, 3/2, 1      reversed  10/4, 9/3, 7/2, 4
    gap = [0.0, 3 - 2, 3.5 - 1.5, 4 - 1]
    expected = sum(0.25 * (gap[i] + gap[i + 1]) / 2 for i in range(3))
    assert ause(-errors, errors, bins=4, variant="mae") == pytest.approx(expected)
    assert ause(-errors, errors, bins=4, variant="mae_norm") == pytest.approx(expected / 2.5)  # / MAE of all
    assert ause(-errors, errors, bins=4, variant="rmse_norm") == pytest.approx(
        ause(-errors, errors, bins=4) / math.sqrt(30 / 4))
    rng = np.random.default_rng(2)
    u, e = rng.random(1000), rng.random(1000)
    for variant in AUSE_VARIANTS:  # scaling every error by 3: normalised unchanged, unnormalised x3
        factor = 1.0 if variant.endswith("_norm") else 3.0
        assert ause(u, 3 * e, variant=variant) == pytest.approx(factor * ause(u, e, variant=variant), rel=1e-10)
    assert ause(u, np.zeros(1000), variant="mae_norm") is None  # no error to normalise by


def test_unknown_ause_variant_is_one_line_listing_the_valid():
    for call in (lambda: ause(np.ones(3), np.ones(3), variant="auc"), lambda: parse_ause_variants("mae,auc"),
                 lambda: parse_ause_variants("")):
        with pytest.raises(UserError, match="valid: rmse, mae, rmse_norm, mae_norm") as err:
            call()
        assert "\n" not in str(err.value)
