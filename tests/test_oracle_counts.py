"""Oracle accounting: closed forms reproduce the published table; selectors count exactly that."""
import pytest
import torch

from active import build_selector
from active.base import SelectionContext
from active.logdet import BlockGainOracle, BlockInformation
from active.oracle_counts import mean_rounded_up, schedule_counts, step_count, subset_size
from tests.test_logdet import random_blocks

# (method, num_init, K, max_views, eps) -> published per-step conservative count (pool of 100 views)
PUBLISHED = [
    ("pop_gs", 2, 3, 11, 0.1, 282), ("lite_gs", 2, 3, 11, 0.1, 215),  # Setup 1
    ("pop_gs", 5, 4, 21, 0.1, 350), ("lite_gs", 5, 4, 21, 0.1, 200),  # Setup 2
    ("pop_gs", 3, 3, 15, 0.1, 275), ("lite_gs", 3, 3, 15, 0.1, 210),  # Setup 4, K = 3
    ("pop_gs", 3, 4, 15, 0.1, 366), ("lite_gs", 3, 4, 15, 0.1, 209),  # K = 4
    ("pop_gs", 3, 6, 15, 0.1, 549), ("lite_gs", 3, 6, 15, 0.1, 208),  # K = 6
    ("lite_gs", 3, 6, 15, 0.3, 108), ("lite_gs", 3, 6, 15, 0.6, 44),
]


@pytest.mark.parametrize("method, n0, k, vmax, eps, expected", PUBLISHED)
def test_published_table(method, n0, k, vmax, eps, expected):
    assert mean_rounded_up(schedule_counts(method, 100, n0, k, vmax, eps)) == expected


def test_lite_gs_count_independent_of_k():
    counts = [step_count("lite_gs", 98, k, 0.1) for k in (3, 4, 6)]
    assert max(counts) - min(counts) <= 6  # ~ M ln(1/eps), only floor effects differ
    pop = [step_count("pop_gs", 98, k) for k in (3, 4, 6)]
    assert pop[0] < pop[1] < pop[2]


class CountingOracle(BlockGainOracle):
    pass


@pytest.mark.parametrize("method", ["pop_gs", "lite_gs", "ssg"])
@pytest.mark.parametrize("k", [3, 4, 6])
@pytest.mark.parametrize("eps", [0.1, 0.3, 0.6])
def test_selector_counts_equal_closed_form(method, k, eps):
    m, n, p = 40, 3, 2
    blocks = random_blocks(m + 1, n, p, seed=k)
    oracle = BlockGainOracle(BlockInformation(blocks[0]), lambda v: blocks[v + 1])
    options = {} if method == "pop_gs" else {"eps": eps}
    ctx = SelectionContext(list(range(m)), oracle, torch.Generator().manual_seed(0), 0)
    sel = build_selector(method, **options).select(ctx, k)
    assert sel.oracle_calls.conservative == step_count(method, m, k, eps)
    assert sel.oracle_calls.evaluated == oracle.evaluated <= sel.oracle_calls.conservative
    assert len(set(sel.ids)) == k


def test_subset_size_rule():
    assert subset_size(98, 3, 0.1) == 75  # floor(98 ln 10 / 3) = floor(75.2)
    assert subset_size(5, 1, 0.01) == 5  # capped at the remaining candidates
    assert subset_size(10, 6, 0.99) == 1  # at least one
