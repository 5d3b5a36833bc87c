"""Oracle accounting: the closed forms reproduce the published table, match literal sums, and the selectors count
exactly that."""
import math

import pytest
import torch

from active import build_selector
from active.base import SelectionContext
from active.logdet import BlockGainOracle, BlockInformation
from active.oracle_counts import conservative_count, mean_rounded_up, schedule_counts, subset_size
from tests.test_logdet import random_blocks, single_thread  # noqa: F401  (autouse fixture)
from utils.errors import UserError

# (method, seed views, K, view budget, eps, published per-step conservative count), pool of 100 views
PUBLISHED = [
    ("pop_gs", 2, 3, 11, 0.1, 282), ("lite_gs", 2, 3, 11, 0.1, 215),  # Setup 1
    ("pop_gs", 5, 4, 21, 0.1, 350), ("lite_gs", 5, 4, 21, 0.1, 200),  # Setup 2
    ("pop_gs", 3, 3, 15, 0.1, 275), ("lite_gs", 3, 3, 15, 0.1, 210),  # Setup 4, K = 3
    ("pop_gs", 3, 4, 15, 0.1, 366), ("lite_gs", 3, 4, 15, 0.1, 209),  # Setup 4, K = 4
    ("pop_gs", 3, 6, 15, 0.1, 549), ("lite_gs", 3, 6, 15, 0.1, 208),  # Setup 4, K = 6
    ("lite_gs", 3, 6, 15, 0.3, 108), ("lite_gs", 3, 6, 15, 0.6, 44),  # Setup 4, K = 6, larger eps
]


@pytest.mark.parametrize("method, n0, k, vmax, eps, expected", PUBLISHED)
def test_published_table(method, n0, k, vmax, eps, expected):
    assert mean_rounded_up(schedule_counts(method, 100, n0, k, vmax, eps)) == expected


def test_closed_forms_equal_literal_sums():
    # Setup 1, first step: M = 98 candidates, K = 3.
    assert conservative_count("pop_gs", 98, 3) == 98 + 97 + 96
    c = math.log(10.0)
    assert conservative_count("lite_gs", 98, 3, 0.1) == sum(math.floor((98 - j) * c / 3) for j in range(3))
    p = math.floor(98 * c / 3)
    assert conservative_count("ssg", 98, 3, 0.1) == p + (p - 1) + (p - 2)
    assert conservative_count("random", 98, 3) == 0
    assert schedule_counts("pop_gs", 100, 2, 3, 11) == [291, 282, 273]
    assert schedule_counts("pop_gs", 20, 3, 4, 12) == [17 + 16 + 15 + 14, 13 + 12 + 11 + 10, 9]  # remainder step
    assert conservative_count("pop_gs", 4, 10) == 4 + 3 + 2 + 1  # K >= M: all M chosen
    with pytest.raises(UserError, match="eps"):
        conservative_count("lite_gs", 98, 3, 1.0)
    with pytest.raises(ValueError, match="no closed-form"):
        conservative_count("nope", 98, 3)


def test_subset_size_rule():
    assert subset_size(98, 3, 0.1) == 75  # floor(98 ln 10 / 3) = floor(75.2)
    assert subset_size(5, 1, 0.01) == 5  # capped at the remaining candidates
    assert subset_size(10, 6, 0.99) == 1  # at least one


def test_lite_gs_count_does_not_grow_with_k():
    for m in range(20, 300):
        lite = [conservative_count("lite_gs", m, k, 0.1) for k in (3, 4, 6)]
        assert lite[0] >= lite[1] >= lite[2]
        pop = [conservative_count("pop_gs", m, k) for k in (3, 4, 6)]
        assert pop[0] < pop[1] < pop[2]
    # For every eps, without the max(1, .) floor the count is bounded by M ln(1/eps) whatever K (floors only
    # remove): sum_j floor((M - j) ln(1/eps) / K) <= K * M ln(1/eps) / K.
    for eps in (0.1, 0.3, 0.6):
        for m in range(30, 300, 7):
            for k in (3, 4, 6):
                assert conservative_count("lite_gs", m, k, eps) <= m * math.log(1 / eps)


@pytest.mark.parametrize("method", ["pop_gs", "lite_gs", "ssg", "random"])
@pytest.mark.parametrize("k", [3, 4, 6])
@pytest.mark.parametrize("eps", [0.1, 0.3, 0.6])
def test_selector_counts_equal_closed_form(method, k, eps):
    m = 40
    blocks = random_blocks(m + 1, 3, 2, seed=k)
    oracle = BlockGainOracle(BlockInformation(blocks[0]), lambda v: blocks[v + 1])
    options = {"eps": eps} if method in ("lite_gs", "ssg") else {}
    ctx = SelectionContext(list(range(m)), oracle, torch.Generator().manual_seed(0), 0)
    sel = build_selector(method, **options).select(ctx, k)
    assert sel.oracle_calls.conservative == conservative_count(method, m, k, eps)
    assert sel.oracle_calls.evaluated == oracle.evaluated <= sel.oracle_calls.conservative
    assert len(set(sel.ids)) == len(sel.ids) == k
