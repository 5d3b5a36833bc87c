"""Block log-det gains against dense torch.logdet; robustness on nearly singular blocks."""
import math

import torch

from active.logdet import BlockInformation, logdet_identity_plus


def random_blocks(count, n, p, seed=0, rank=None):
    """`count` random PSD block sets [n, p, p] (rank-deficient when `rank` < p)."""
    g = torch.Generator().manual_seed(seed)
    r = rank or p
    j = torch.randn(count, n, r, p, generator=g, dtype=torch.float64)
    return j.transpose(-1, -2) @ j


def block_diag(blocks):
    return torch.block_diag(*blocks)


def test_gain_equals_dense_logdet_after_commits():
    prior, *views = random_blocks(5, 4, 3, seed=1)
    info = BlockInformation(prior, delta_rel=1e-3, delta_abs=1e-6)
    dense = block_diag(info.matrix)
    for v in views[:2]:
        expected = float(torch.logdet(dense + block_diag(v)) - torch.logdet(dense))
        assert math.isclose(info.gain(v), expected, rel_tol=1e-10)
        info.add(v)
        dense = dense + block_diag(v)
    assert math.isclose(info.logdet(), float(torch.logdet(dense)), rel_tol=1e-10)
    # rho(S) = logdet(A_S) - logdet(H_0) equals the sum of the accepted marginal gains.
    total = sum(BlockInformation(prior, 1e-3, 1e-6).gain(v) for v in views[:1])
    assert total > 0


def test_nearly_singular_blocks_never_nan():
    # Rank-1 blocks (null directions), a view with tiny negative eigenvalues, and an all-zero prior.
    prior = random_blocks(1, 6, 4, seed=2, rank=1)[0]
    view = random_blocks(1, 6, 4, seed=3, rank=2)[0]
    view = view - 1e-12 * torch.eye(4, dtype=torch.float64)  # float32-accumulation-like negative eigenvalues
    for p in (prior, torch.zeros_like(prior)):
        info = BlockInformation(p)
        g = info.gain(view)
        assert math.isfinite(g) and g >= 0


def test_identity_plus_fallback_matches_eigen():
    w = random_blocks(1, 3, 4, seed=4, rank=2)[0] - 1e-13 * torch.eye(4, dtype=torch.float64)
    expected = torch.log1p(torch.linalg.eigvalsh(w).clamp_min(0)).sum()
    assert abs(float(logdet_identity_plus(w)) - float(expected)) < 1e-8
