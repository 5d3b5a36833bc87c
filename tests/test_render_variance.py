"""render_variance: the Woodbury variance terms against explicit inverses, the selector's picks against a written-out
dense greedy on tr(T A_S^-1), rho, counts, a case where it and pop_gs disagree, and the oracle built on a real model
(its target = the candidates' summed blocks, computed independently)."""
import pytest
import torch

from active import build_selector
from active.acquisition import run_selection
from active.base import SelectionContext
from active.fisher import FisherOracle, build_oracle
from active.logdet import BlockGainOracle, ViewFactors
from active.variance_oracle import RenderVarianceInformation, variance_terms_dense
from arguments import FisherSettings
from tests.test_fisher_cache import spiral_cameras
from tests.test_selectors import problem
from tests.test_view_factors import BG, SETTINGS, model

pytestmark = pytest.mark.usefixtures("single_torch_thread")  # tiny batched linear algebra (tests/conftest.py)

M = 10


def dense_variance(blocks, chosen):
    """sum_i tr(T_i inv(A_i)) with A = ridged prior + the chosen views, T = every candidate's blocks summed."""
    info = RenderVarianceInformation(blocks[0], blocks[1:].sum(0))
    a = info.prior_matrix + sum((blocks[v + 1] for v in chosen), torch.zeros_like(blocks[0]))
    return float(torch.diagonal(info.target @ torch.linalg.inv(a), dim1=-2, dim2=-1).sum())


def written_out_greedy(blocks, k):
    """Plain greedy on the dense variance, ties to the lowest id."""
    chosen = []
    for _ in range(k):
        rest = [v for v in range(M) if v not in chosen]
        values = [dense_variance(blocks, chosen + [v]) for v in rest]
        chosen.append(rest[min(range(len(rest)), key=lambda j: (values[j], j))])
    return chosen


def oracle_for(blocks):
    info = RenderVarianceInformation(blocks[0], blocks[1:].sum(0))
    return BlockGainOracle(info, lambda v: blocks[v + 1])


@pytest.mark.parametrize("seed", range(4))
def test_terms_equal_explicit_inverses_before_and_after_commits(seed):
    blocks = problem(m=M, n=5, p=3, seed=seed)
    oracle = oracle_for(blocks)
    info, committed = oracle.information, torch.zeros_like(blocks[0])
    for step in range(3):
        a = info.prior_matrix + committed
        for v in range(M):
            view = ViewFactors.from_blocks(blocks[v + 1])
            fast = torch.zeros(5, dtype=torch.float64)
            fast[view.indices] = info.gain_terms(view)
            dense = variance_terms_dense(a, info.target, view.dense())
            torch.testing.assert_close(fast, dense, rtol=1e-8, atol=1e-10)
        removed = info.add(blocks[step + 1])
        assert removed == pytest.approx(float(variance_terms_dense(a, info.target, blocks[step + 1]).sum()), rel=1e-8)
        committed = committed + blocks[step + 1]
    assert info.rho() == pytest.approx(dense_variance(blocks, []) - dense_variance(blocks, [0, 1, 2]), rel=1e-8)


@pytest.mark.parametrize("seed", range(5))
def test_picks_equal_the_written_out_greedy_and_counts_are_exhaustive(seed):
    blocks = problem(m=M, n=4, p=2, seed=20 + seed)
    oracle = oracle_for(blocks)
    ctx = SelectionContext(list(range(M)), oracle, torch.Generator().manual_seed(0), stage=0)
    sel = build_selector("render_variance").select(ctx, 4)
    assert sel.ids == written_out_greedy(blocks, 4)
    assert oracle.evaluated == sel.conservative == sum(M - j for j in range(4))
    gains = [dense_variance(blocks, sel.ids[:j]) - dense_variance(blocks, sel.ids[:j + 1]) for j in range(4)]
    assert sel.gains == pytest.approx(gains, rel=1e-7)


def test_a_gaussian_that_moves_no_pixel_of_the_pool_counts_for_nothing():
    """Two Gaussians, two candidates: view 0 informs Gaussian 0 a lot, view 1 Gaussian 1 a little. With the target
    seeing only Gaussian 1 (Gaussian 0 moves no pixel of the pool), the variance picks view 1, the log-det view 0."""
    p = 2
    eye = torch.eye(p, dtype=torch.float64)
    prior = torch.stack([eye, eye])  # [2, P, P]
    views = [torch.stack([100.0 * eye, 0 * eye]), torch.stack([0 * eye, 1.0 * eye])]
    target = torch.stack([0 * eye, eye])
    variance = BlockGainOracle(RenderVarianceInformation(prior, target), lambda v: views[v])
    assert variance.gain(0) == 0.0 and variance.gain(1) > 0.0
    logdet = build_selector("pop_gs")
    from active.logdet import BlockInformation
    ctx = SelectionContext([0, 1], BlockGainOracle(BlockInformation(prior), lambda v: views[v]),
                           torch.Generator(), stage=0)
    assert logdet.select(ctx, 1).ids == [0]
    ctx = SelectionContext([0, 1], variance, torch.Generator(), stage=0)
    assert build_selector("render_variance").select(ctx, 1).ids == [1]


def test_on_a_real_model_the_target_is_the_candidates_blocks_and_gains_match_the_dense_twin():
    gaussians, cams = model(n=120), spiral_cameras(12)
    train = [0, 6]
    candidates = [v for v in range(len(cams)) if v not in train]
    oracle = build_oracle("render_variance", gaussians, cams, train, BG, SETTINGS, fisher=FisherSettings())
    reference = FisherOracle.build(gaussians, cams, train, BG, SETTINGS, fisher=FisherSettings())
    target = sum(reference.blocks(v).dense() for v in candidates)
    torch.testing.assert_close(oracle.information.target, target, rtol=1e-10, atol=1e-12)
    a = oracle.information.prior_matrix
    for v in candidates[:4]:
        dense = variance_terms_dense(a, target, reference.blocks(v).dense()).sum()
        assert oracle.gain(v) == pytest.approx(float(dense), rel=1e-6)
    step = run_selection(build_selector("render_variance"), gaussians, cams, train, candidates, 3, BG, SETTINGS)
    assert len(set(step.selection.ids)) == 3 and step.evaluated == step.selection.conservative == 10 + 9 + 8
    assert step.fisher_views_computed == len(candidates)  # every candidate once, for the target
