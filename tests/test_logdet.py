"""Block log-det information: gains against dense torch.logdet, whitened == direct form, the ridge, robustness on
nearly singular blocks, errors, oracle counting; the sparse factor path (numba kernels and their torch twin) against
the dense twin `DenseBlockInformation`."""
import math

import pytest
import torch

from active.logdet import (BlockGainOracle, check_finite, BlockInformation, DenseBlockInformation, ViewFactors,
                           logdet_identity_plus)
from utils.errors import UserError


pytestmark = pytest.mark.usefixtures("single_torch_thread")  # tiny batched linear algebra (tests/conftest.py)


def random_blocks(count, n, p, seed=0, rank=None):
    """`count` random PSD block sets J^T J, [count, n, p, p] float64 (rank-deficient when `rank` < p)."""
    g = torch.Generator().manual_seed(seed)
    j = torch.randn(count, n, rank or p, p, generator=g, dtype=torch.float64)
    return j.transpose(-1, -2) @ j


def dense(blocks):
    """The block-diagonal matrix of [N, P, P] blocks. [N*P, N*P]"""
    return torch.block_diag(*blocks)


def clamped_gain_reference(a_blocks, h_blocks):
    """sum_i sum log1p(max(eig(A_i^-1/2 H_i A_i^-1/2), 0)) via a symmetric eigen square root: the clamped
    definition, computed without Cholesky."""
    evals, evecs = torch.linalg.eigh(a_blocks)
    inv_sqrt = evecs @ torch.diag_embed(evals.rsqrt()) @ evecs.transpose(-1, -2)
    w = inv_sqrt @ (0.5 * (h_blocks + h_blocks.transpose(-1, -2))) @ inv_sqrt
    return float(torch.log1p(torch.linalg.eigvalsh(w).clamp_min(0)).sum())


BACKENDS = ("compiled", "torch")


@pytest.mark.parametrize("backend", BACKENDS)
def test_gains_equal_dense_logdet_through_commits(backend):
    prior, *views = random_blocks(6, 4, 3, seed=1)
    info = BlockInformation(prior, delta_rel=1e-3, delta_abs=1e-6, backend=backend)
    a = dense(info.matrix)  # [12, 12]
    h0_logdet = float(torch.logdet(a))
    accepted = []
    for v in views[:4]:
        expected = float(torch.logdet(a + dense(v)) - torch.logdet(a))
        gain = info.gain(v)
        assert math.isclose(gain, expected, rel_tol=1e-10)  # float64, 12x12 well conditioned: ~1e-14 achieved
        info.add(v)
        a = a + dense(v)
        accepted.append(gain)
        assert torch.allclose(dense(info.matrix), a, rtol=1e-12, atol=1e-12)  # L C (L C)^T == A + H, float64
        assert math.isclose(info.logdet(), float(torch.logdet(a)), rel_tol=1e-10)
    # rho(S) = logdet(A_S) - logdet(H_0) telescopes into the sum of the accepted marginal gains.
    assert math.isclose(info.rho(), float(torch.logdet(a)) - h0_logdet, rel_tol=1e-10)
    assert math.isclose(info.rho(), sum(accepted), rel_tol=1e-10)


@pytest.mark.parametrize("backend", BACKENDS)
def test_whitened_equals_direct_form_on_ill_conditioned_blocks(backend):
    # Prior eigenvalues spread over 1e-4..1e4 (ratio 1e8) per block, views of similar spread.
    g = torch.Generator().manual_seed(5)
    q, _ = torch.linalg.qr(torch.randn(8, 5, 5, generator=g, dtype=torch.float64))
    spread = torch.logspace(-4, 4, 5, dtype=torch.float64)
    prior = q @ torch.diag_embed(spread) @ q.transpose(-1, -2)
    view = random_blocks(1, 8, 5, seed=6)[0] * 1e2
    info = BlockInformation(prior, delta_rel=0.0, delta_abs=1e-12, backend=backend)
    a = info.matrix
    direct = float((torch.logdet(a + view) - torch.logdet(a)).sum())
    # Direct form loses ~cond * eps = 1e8 * 1e-16 relative accuracy; 1e-7 leaves room for that.
    assert math.isclose(info.gain(view), direct, rel_tol=1e-7)
    assert math.isclose(info.gain(view), clamped_gain_reference(a, view), rel_tol=1e-7)


def test_ridge_is_relative_plus_absolute():
    prior = torch.diag_embed(torch.tensor([[4.0, 1.0, 0.0], [0.0, 0.0, 0.0]], dtype=torch.float64))  # [2, 3, 3]
    info = BlockInformation(prior, delta_rel=0.5, delta_abs=0.25)
    expected = torch.diag_embed(torch.tensor([[6.25, 3.25, 2.25], [0.25, 0.25, 0.25]], dtype=torch.float64))
    assert torch.equal(info.matrix, expected)  # exact: dyadic numbers


def test_identity_plus_clamps_negative_eigenvalues():
    # Blocks W = Q diag(lambda) Q^T built from a known spectrum: PSD, tiny negative, below -1, all zero. The expected
    # per-block value sum log1p(max(lambda, 0)) comes from that spectrum (no eigen-solver); for the PSD block it is
    # also the dense torch.logdet(I + W).
    g = torch.Generator().manual_seed(4)
    q, _ = torch.linalg.qr(torch.randn(4, 4, 4, generator=g, dtype=torch.float64))
    spectra = torch.tensor([[2.0, 0.5, 1e-3, 0.0], [3e-2, 1e-4, -1e-13, -2e-13], [1.5, -3.0, 0.2, -1.2],
                            [0.0, 0.0, 0.0, 0.0]], dtype=torch.float64)
    w = q @ torch.diag_embed(spectra) @ q.transpose(-1, -2)
    w = 0.5 * (w + w.transpose(-1, -2))
    terms = logdet_identity_plus(w)
    expected = torch.log1p(spectra.clamp_min(0)).sum(-1)
    torch.testing.assert_close(terms, expected, rtol=1e-10, atol=1e-14)  # float64 eigenvalues of 4x4 blocks
    assert math.isclose(float(terms[0]), float(torch.logdet(torch.eye(4, dtype=torch.float64) + w[0])), rel_tol=1e-12)
    assert bool((terms >= 0).all()) and abs(float(terms[3])) < 1e-15


@pytest.mark.parametrize("backend", BACKENDS)
def test_nearly_singular_blocks_give_finite_nonnegative_gains(backend):
    # Rank-deficient float32-accumulated blocks (J^T J with J of rank 2 in float32), as the Fisher oracle makes:
    # exact null directions plus negative eigenvalues ~ eps32 * |H|.
    g = torch.Generator().manual_seed(2)
    jac = torch.randn(3, 10, 2, 6, generator=g) * torch.logspace(-3, 3, 6)  # [views, N, rank 2, P 6], scales 1e6
    blocks32 = (jac.transpose(-1, -2) @ jac).double()  # [3, 10, 6, 6] float32 products
    assert float(torch.linalg.eigvalsh(blocks32).min()) < 0  # the problem the clamp exists for
    prior = blocks32[0]
    zero = torch.zeros_like(prior)
    for p in (prior, zero):
        info = BlockInformation(p, backend=backend)
        # Eigenvalues of W are known to ~eps64 * |W| absolutely (|W| ~ 1e14 over the zero prior): a log1p of the
        # small ones moves by up to that much, over N * P = 60 of them. The sparse path takes the PSD part of H
        # before whitening, the reference after: for noise eigenvalues the two differ by that much, no more.
        noise = 60 * 2.2e-16 * float(torch.linalg.matrix_norm(DenseBlockInformation(p).whiten(blocks32[1]),
                                                               ord=2).max())
        for view in (blocks32[1], -blocks32[2] * 1e-9, zero):  # a PSD-ish view, a tiny negative view, no view
            gain = info.gain(view)
            assert math.isfinite(gain) and gain >= 0
            assert math.isclose(gain, clamped_gain_reference(info.matrix, view), rel_tol=1e-6, abs_tol=noise)
            # ^ eigen-sqrt twin on matrices of condition up to 1/delta_rel = 1e6: ~1e-10 relative
        assert info.gain(zero) == 0.0
        gain = info.gain(blocks32[1])
        info.add(blocks32[1])  # committing a non-PSD view never fails, and adds exactly the measured gain
        assert abs(info.rho() - gain) <= 1e-9 * gain + noise


def test_errors_name_gaussian_count_and_ridge():
    prior = random_blocks(1, 6, 3, seed=3, rank=1)[0]
    with pytest.raises(UserError, match=r"of 6 Gaussians .*delta_rel=0.*delta_abs=1e-30"):
        BlockInformation(prior - 1e-3 * torch.eye(3, dtype=torch.float64), delta_rel=0.0, delta_abs=1e-30)
    with pytest.raises(UserError, match="delta_rel"):
        BlockInformation(prior, delta_rel=0.0, delta_abs=0.0)
    info = BlockInformation(prior)
    bad = prior.clone()
    bad[2, 0, 0] = float("nan")
    with pytest.raises(UserError, match="6 Gaussians contain NaN"):
        info.gain(bad)
    with pytest.raises(UserError, match="NaN"):
        info.add(bad)


def test_oracle_counts_gains_not_commits_and_streams_blocks():
    prior, *views = random_blocks(4, 3, 2, seed=8)
    calls = []

    def view_blocks(v):  # streaming mode: blocks recomputed on every request
        calls.append(v)
        return views[v]

    info = BlockInformation(prior)
    oracle = BlockGainOracle(info, view_blocks)
    a = dense(info.matrix)
    dense_gain = [float(torch.logdet(a + dense(v)) - torch.logdet(a)) for v in views]
    expected = oracle.gain(1)
    assert math.isclose(expected, dense_gain[1], rel_tol=1e-10)
    assert math.isclose(oracle.gain(2), dense_gain[2], rel_tol=1e-10) and oracle.evaluated == 2
    best = 1 if dense_gain[1] > dense_gain[2] else 2
    reference = BlockInformation(prior)
    reference.add(views[best])
    oracle.commit(best)  # the best view since the last commit: its whitened blocks are reused, not recomputed
    assert oracle.evaluated == 2 and calls == [1, 2]
    torch.testing.assert_close(info.chol, reference.chol, rtol=0, atol=0)
    oracle.commit(0)  # never evaluated: its blocks are requested
    assert calls == [1, 2, 0]
    assert oracle.gain(1) < expected  # the committed information is used: diminishing returns
    oracle.reset_counts()
    assert oracle.evaluated == 0


def partly_visible(blocks, seen, seed):
    """Zero the blocks of the Gaussians a view does not see (a random `seen` fraction kept). [N, P, P]"""
    g = torch.Generator().manual_seed(seed)
    return blocks * (torch.rand(blocks.shape[0], generator=g) < seen).double()[:, None, None]


@pytest.mark.parametrize("backend", BACKENDS)
def test_sparse_gains_and_commits_equal_dense_twin(backend):
    # 40 Gaussians, P = 14, view blocks seen by ~30 % of the Gaussians, a prior with all-zero blocks too. (Full-rank
    # views: over a zero prior block the ridge is 1e-8, and a rank-deficient dense block's roundoff in its null
    # directions, eps |H| / 1e-8, would set the agreement, not the method; the test below covers that case.)
    prior = partly_visible(random_blocks(1, 40, 14, seed=11)[0], 0.7, seed=0)
    views = [partly_visible(random_blocks(1, 40, 14, seed=20 + i)[0], 0.3, seed=i + 1) for i in range(5)]
    sparse, dense_twin = BlockInformation(prior, backend=backend), DenseBlockInformation(prior)
    a = dense(dense_twin.matrix)  # [560, 560]
    for pick in (3, 0, 4):
        for v in views:
            expected = float(torch.logdet(a + dense(v)) - torch.logdet(a))
            assert math.isclose(sparse.gain(v), dense_twin.gain(v), rel_tol=1e-9)
            assert math.isclose(sparse.gain(v), expected, rel_tol=1e-9)
        sparse.add(views[pick])
        dense_twin.add(views[pick])
        a = a + dense(views[pick])
        torch.testing.assert_close(sparse.chol, dense_twin.chol, rtol=1e-10, atol=1e-10 * float(a.abs().max()))
        torch.testing.assert_close(sparse.matrix, dense_twin.matrix, rtol=1e-10, atol=1e-9 * float(a.abs().max()))
        assert math.isclose(sparse.rho(), dense_twin.rho(), rel_tol=1e-9)
    # Blocks the committed views do not see are untouched, bit for bit.
    unseen = (torch.stack([views[i] for i in (3, 0, 4)]).abs().flatten(2).amax(-1) == 0).all(0)  # [N]
    assert bool(unseen.any())
    assert torch.equal(sparse.chol[unseen], BlockInformation(prior, backend=backend).chol[unseen])


def test_compiled_kernels_equal_torch_twin_per_block():
    prior = random_blocks(1, 300, 14, seed=31)[0]
    g = torch.Generator().manual_seed(32)
    indices = torch.sort(torch.randperm(300, generator=g)[:120]).values
    view = ViewFactors.from_factors(indices, torch.randn(120, 14, 9, generator=g, dtype=torch.float64) * 3.0, 300)
    compiled, twin = BlockInformation(prior, backend="compiled"), BlockInformation(prior, backend="torch")
    for stored in (view, view.stored_as(torch.float32)):
        torch.testing.assert_close(compiled.gain_terms(stored), twin.gain_terms(stored), rtol=1e-10, atol=0)
        # ^ the same float64 arithmetic in another order; 14 x 14 priors of condition up to ~1e5: ~1e-12 seen
    added = compiled.add(view), twin.add(view)
    for info, growth in zip((compiled, twin), added):  # a commit's terms are the log-det growth, == the gain
        assert math.isclose(growth, info.rho(), rel_tol=1e-10)
    assert math.isclose(added[0], float(BlockInformation(prior).gain(view)), rel_tol=1e-10)
    torch.testing.assert_close(compiled.chol, twin.chol, rtol=1e-10, atol=1e-10)
    # ^ entries of order 1-100 summed in another order: ~1e-11 absolute seen
    torch.testing.assert_close(compiled.matrix, twin.matrix, rtol=1e-12, atol=1e-10)


@pytest.mark.parametrize("backend", BACKENDS)
def test_view_that_sees_no_gaussian_gains_zero(backend):
    prior = random_blocks(1, 5, 4, seed=41)[0]
    info = BlockInformation(prior, backend=backend)
    chol = info.chol.clone()
    empty = ViewFactors.from_factors(torch.zeros(0, dtype=torch.long), torch.zeros(0, 4, 9, dtype=torch.float64), 5)
    assert info.gain(empty) == 0.0 and info.gain(torch.zeros(5, 4, 4, dtype=torch.float64)) == 0.0
    info.add(empty)
    info.add(torch.zeros(5, 4, 4))
    assert torch.equal(info.chol, chol) and info.rho() == 0.0


def test_view_factors_refuse_non_finite_and_scatter_to_dense():
    factors = torch.ones(2, 3, 2, dtype=torch.float64)
    factors[1, 2, 0] = float("inf")
    with pytest.raises(UserError, match="view Fisher blocks of 7 Gaussians contain NaN or inf"):
        ViewFactors.from_factors(torch.tensor([1, 4]), factors, 7)
    view = ViewFactors.from_factors(torch.tensor([1, 4]), torch.ones(2, 3, 2, dtype=torch.float64), 7)
    expected = torch.zeros(7, 3, 3, dtype=torch.float64)
    expected[[1, 4]] = 2.0  # R R^T of an all-ones 3 x 2 factor
    torch.testing.assert_close(view.dense(), expected, rtol=1e-14, atol=1e-14)  # R R^T of the trapezoidal factor
    assert view.stored_as(torch.float32).nbytes == 2 * 8 + 2 * (1 + 2 + 2) * 4  # rows of 1, 2, 2 packed entries


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_check_finite_catches_every_non_finite_and_not_an_overflowing_sum(dtype):
    """check_finite sums first: a NaN/inf anywhere must still be caught, finite values whose sum overflows must not."""
    huge = torch.full((64,), torch.finfo(dtype).max / 2, dtype=dtype)
    check_finite(huge, "view", 64)  # the sum is inf, every element finite: no error
    for bad in (float("nan"), float("inf"), -float("inf")):
        for where in (0, 63):
            values = torch.ones(64, dtype=dtype)
            values[where] = bad
            with pytest.raises(UserError, match="NaN or inf"):
                check_finite(values, "view", 64)


@pytest.mark.parametrize("backend", BACKENDS)
def test_weighted_gains_equal_weighted_dense_logdets(backend):
    """`BlockGainOracle(weights=w)`: sum_i w_i (logdet(A_i + H_i) - logdet(A_i)), each block by dense torch.logdet;
    commits are the unweighted A <- A + H."""
    prior, *views = random_blocks(5, 6, 3, seed=11)
    weights = torch.tensor([0.0, 0.1, 0.5, 1.0, 2.0, 0.9], dtype=torch.float64)
    oracle = BlockGainOracle(BlockInformation(prior, backend=backend), lambda v: views[v], weights)
    plain = BlockGainOracle(BlockInformation(prior, backend=backend), lambda v: views[v])
    a = oracle.information.matrix.clone()  # [6, 3, 3]
    for step, view in enumerate((2, 0)):
        for v in range(4):
            terms = torch.logdet(a + views[v]) - torch.logdet(a)  # [6]
            assert math.isclose(oracle.gain(v), float((weights * terms).sum()), rel_tol=1e-10)
            assert math.isclose(plain.gain(v), float(terms.sum()), rel_tol=1e-10)
        oracle.commit(view)
        plain.commit(view)
        a = a + views[view]
        torch.testing.assert_close(oracle.information.chol, plain.information.chol, rtol=0, atol=0)
