"""The compiled pivoted-Cholesky root of the attribute Gram (`logdet_kernels.gram_root_factors`) against its torch
twin (eigen-decomposition of the equilibrated Gram) and against J^T G J itself: graded units, rank-deficient and
roundoff-indefinite Grams, and the real Grams of a small model through `fisher_view_factors` on both backends."""
import pytest
import torch

from active.fisher import fisher_view_blocks, fisher_view_factors
from active.logdet import gram_root_factors, gram_root_factors_torch
from active.trapezoid import packed_width, unpack
from tests.test_view_factors import BG, SETTINGS, cameras, model

A, P = 9, 14
M = packed_width(P, A)  # 90 packed entries of a lower-trapezoidal [P, A] factor


def random_grams(n: int, rank: int, seed: int, orders: float = 8.0) -> tuple[torch.Tensor, torch.Tensor]:
    """Grams G = B B^T of the given rank, attributes scaled over `orders` orders of magnitude, and a Jacobian."""
    gen = torch.Generator().manual_seed(seed)
    units = 10.0 ** torch.linspace(-orders / 2, orders / 2, A, dtype=torch.float64)  # [A], as px, px^2, colour differ
    b = torch.randn(n, A, rank, generator=gen, dtype=torch.float64) * units[None, :, None]
    gram = b @ b.transpose(1, 2)  # [n, A, A]
    jac = torch.randn(n, A, P, generator=gen, dtype=torch.float64) / units[None, :, None]
    return gram, jac


def relative_error(r: torch.Tensor, expected: torch.Tensor) -> float:
    """max over blocks of max |R R^T - H| / max |H|."""
    h = r @ r.transpose(1, 2)
    scale = expected.flatten(1).abs().amax(1).clamp_min(1e-300)
    return float(((h - expected).flatten(1).abs().amax(1) / scale).max())


@pytest.mark.parametrize("rank", [9, 5, 1])
def test_compiled_root_equals_torch_twin_and_the_blocks(rank):
    gram, jac = random_grams(200, rank, seed=rank)
    expected = jac.transpose(1, 2) @ gram @ jac / 0.25  # sigma = 0.5: H = sigma^-2 J^T G J [n, P, P]
    compiled = gram_root_factors(gram, jac, 0.5, backend="compiled")
    twin = gram_root_factors(gram, jac, 0.5, backend="torch")
    assert compiled.shape == twin.shape == (200, M)
    compiled, twin = unpack(compiled, P, A), unpack(twin, P, A)
    assert relative_error(compiled, expected) < 1e-11
    assert relative_error(twin, expected) < 1e-9
    # columns past the rank are exactly zero in the pivoted-Cholesky root, and stay so through the LQ
    assert torch.count_nonzero(compiled[:, :, rank:]) == 0


@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_float32_factors_are_the_float64_ones_rounded_once(backend):
    # What a cache stores: the kernel writes float32 directly, which must equal computing in float64 and rounding.
    gram, jac = random_grams(100, 6, seed=3)
    wide = gram_root_factors(gram, jac, 0.5, backend=backend)
    narrow = gram_root_factors(gram, jac, 0.5, backend=backend, dtype=torch.float32)
    assert wide.dtype == torch.float64 and narrow.dtype == torch.float32
    assert torch.equal(narrow, wide.float())


def test_roundoff_negative_and_zero_attributes_are_dropped_not_amplified():
    gram, jac = random_grams(50, 3, seed=7)
    gram = gram - 1e-14 * torch.eye(A, dtype=torch.float64) * torch.diagonal(gram, dim1=1, dim2=2)[:, :, None]
    gram[:10, 4, :] = 0.0  # an attribute the pixels never moved: zero row and column
    gram[:10, :, 4] = 0.0
    expected = jac.transpose(1, 2) @ gram @ jac
    for backend in ("compiled", "torch"):
        r = unpack(gram_root_factors(gram, jac, 1.0, backend=backend), P, A)
        assert torch.isfinite(r).all()
        assert relative_error(r, expected) < 1e-9


def test_empty_view_has_no_factors():
    gram, jac = torch.zeros(0, A, A, dtype=torch.float64), torch.zeros(0, A, P, dtype=torch.float64)
    for backend in ("compiled", "torch"):
        assert gram_root_factors(gram, jac, 1.0, backend=backend).shape == (0, M)


def test_real_view_factors_equal_on_both_backends():
    """Which path: the model's Grams through `fisher_view_factors(backend=...)`, compiled rasterizer both times."""
    gaussians, cams = model(), cameras()
    for cam in cams[:3]:
        blocks = fisher_view_blocks(gaussians, cam, BG, SETTINGS, sigma=0.5)
        compiled = fisher_view_factors(gaussians, cam, BG, SETTINGS, sigma=0.5, backend="compiled")
        twin = fisher_view_factors(gaussians, cam, BG, SETTINGS, sigma=0.5, backend="torch")
        assert torch.equal(compiled.indices, twin.indices)
        scale = float(blocks.abs().max())
        torch.testing.assert_close(compiled.dense(), twin.dense(), rtol=1e-9, atol=1e-12 * scale)
        torch.testing.assert_close(compiled.dense(), blocks, rtol=1e-5, atol=1e-6 * scale)


def test_torch_twin_is_plain_eigen_clamping_on_a_well_scaled_gram():
    """The twin's equilibration does not change the PSD part of a PSD Gram: equal to J^T V max(L,0) V^T J."""
    gram, jac = random_grams(20, 9, seed=1, orders=0.0)
    evals, evecs = torch.linalg.eigh(gram)
    plain = jac.transpose(1, 2) @ (evecs * evals.clamp_min(0)[:, None, :]) @ evecs.transpose(1, 2) @ jac
    assert relative_error(gram_root_factors_torch(gram, jac, 1.0), plain) < 1e-9
