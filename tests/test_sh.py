"""SH evaluation against the textbook real spherical harmonics (Legendre form), gradients by finite differences."""
import math

import numpy as np
import pytest
import torch

from gaussian_renderer.sh import C0, eval_sh, rgb_to_sh, sh_to_colors, sh_to_rgb


def real_sh_reference(l: int, m: int, dirs: torch.Tensor) -> torch.Tensor:
    """Y_lm with the Condon-Shortley phase from the polar angles: N P_l^|m|(cos theta) times cos/sin(|m| phi).

    P_l^m(x) = (-1)^m (1 - x^2)^(m/2) d^m/dx^m P_l(x), with P_l from numpy's Legendre basis. [N, 3] -> [N]
    """
    d = (dirs / dirs.norm(dim=1, keepdim=True)).numpy()
    cos_theta, phi = d[:, 2], np.arctan2(d[:, 1], d[:, 0])
    am = abs(m)
    legendre = np.polynomial.legendre.Legendre.basis(l).deriv(am)(cos_theta)
    p_lm = (-1) ** am * (1 - cos_theta**2) ** (am / 2) * legendre
    norm = math.sqrt((2 * l + 1) / (4 * math.pi) * math.factorial(l - am) / math.factorial(l + am))
    if m == 0:
        y = norm * p_lm
    elif m > 0:
        y = math.sqrt(2) * norm * p_lm * np.cos(am * phi)
    else:
        y = math.sqrt(2) * norm * p_lm * np.sin(am * phi)
    return torch.from_numpy(y)


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_eval_sh_matches_legendre_definition(degree):
    g = torch.Generator().manual_seed(degree)
    n = 50
    dirs = torch.randn(n, 3, generator=g, dtype=torch.float64) * 3.0  # not unit: eval_sh normalises
    coeffs = torch.randn(n, 16, 3, generator=g, dtype=torch.float64)  # all 16 bases: higher ones must be ignored
    expected = torch.zeros(n, 3, dtype=torch.float64)
    for l in range(degree + 1):
        for m in range(-l, l + 1):
            expected += real_sh_reference(l, m, dirs)[:, None] * coeffs[:, l * l + l + m]
    # float64; both sides are a few dozen flops per basis, so only rounding (~1e-15) separates them.
    torch.testing.assert_close(eval_sh(coeffs, dirs, degree), expected, rtol=1e-12, atol=1e-12)


def test_degree_one_signs_follow_3dgs():
    # Along +x, +y, +z the degree-1 bases are -C1 x, -C1 y, +C1 z (bases 3, 1, 2).
    c1 = math.sqrt(3 / (4 * math.pi))
    for axis, basis, sign in [(0, 3, -1.0), (1, 1, -1.0), (2, 2, 1.0)]:
        coeffs = torch.zeros(1, 4, 1, dtype=torch.float64)
        coeffs[0, basis, 0] = 1.0
        direction = torch.zeros(1, 3, dtype=torch.float64)
        direction[0, axis] = 2.0
        assert eval_sh(coeffs, direction, 1).item() == pytest.approx(sign * c1, rel=1e-14)


def test_eval_sh_gradcheck():
    g = torch.Generator().manual_seed(1)
    coeffs = torch.randn(4, 16, 3, generator=g, dtype=torch.float64, requires_grad=True)
    dirs = torch.randn(4, 3, generator=g, dtype=torch.float64, requires_grad=True)
    # gradcheck compares autograd with central finite differences in float64 (its default tolerances).
    assert torch.autograd.gradcheck(lambda c, d: eval_sh(c, d, 3), (coeffs, dirs))


def test_rgb_sh_round_trip_and_clamped_colour():
    rgb = torch.tensor([[0.0, 0.25, 1.0]], dtype=torch.float64)
    sh = rgb_to_sh(rgb)
    torch.testing.assert_close(sh, (rgb - 0.5) / C0)  # closed form, exact up to rounding
    torch.testing.assert_close(sh_to_rgb(sh), rgb)
    coeffs = sh[:, None, :].clone()
    coeffs[0, 0, 0] = -5.0  # C0 * -5 + 0.5 < 0: clamped to 0
    colors = sh_to_colors(coeffs, torch.zeros(1, 3, dtype=torch.float64), torch.ones(3, dtype=torch.float64), 0)
    torch.testing.assert_close(colors, torch.tensor([[0.0, 0.25, 1.0]], dtype=torch.float64))


def test_view_direction_is_mean_minus_camera_centre():
    coeffs = torch.zeros(1, 4, 3, dtype=torch.float64)
    coeffs[0, 2] = 1.0  # the z basis C1 z
    mean = torch.tensor([[0.0, 0.0, 5.0]], dtype=torch.float64)
    above = sh_to_colors(coeffs, mean, torch.tensor([0.0, 0.0, 0.0], dtype=torch.float64), 1)
    below = sh_to_colors(coeffs, mean, torch.tensor([0.0, 0.0, 10.0], dtype=torch.float64), 1)
    c1 = math.sqrt(3 / (4 * math.pi))
    torch.testing.assert_close(above, torch.full((1, 3), 0.5 + c1, dtype=torch.float64))
    torch.testing.assert_close(below, torch.full((1, 3), 0.5 - c1, dtype=torch.float64))
