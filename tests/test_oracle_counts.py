"""Oracle accounting: every selector's closed form equals the formulas written out here (independently of the
selectors' helpers), reproduces the published table, and is exactly what the selector reports at run time; the
evaluated count comes from the oracle and never exceeds it."""
import math

import pytest
import torch

from active import build_selector, list_selectors
from active.base import SelectionContext
from active.fisher import DiagonalGainOracle
from active.gated_oracle import CoverGatedOracle
from active.logdet import BlockGainOracle, BlockInformation
from active.oracle_counts import exhaustive_count, mean_rounded_up, schedule_counts
from tests.test_logdet import random_blocks
from utils.errors import UserError

pytestmark = pytest.mark.usefixtures("single_torch_thread")  # tiny batched linear algebra (tests/conftest.py)


def exhaustive(m: int, k: int) -> int:
    """pop_gs: every remaining candidate at every pick."""
    return sum(m - j for j in range(min(k, m)))


def stochastic(m: int, k: int, eps: float) -> int:
    """lite_gs: p_j = max(1, floor((M - j) ln(1/eps) / K)), never more than the M - j left."""
    k = min(k, m)
    return sum(min(m - j, max(1, math.floor((m - j) * math.log(1 / eps) / k))) for j in range(k))


def static_subset(m: int, k: int, eps: float) -> int:
    """ssg: one subset of p = max(K, floor(M ln(1/eps) / K)) (at most M), shrinking by one per pick."""
    k = min(k, m)
    if k == 0:
        return 0
    p = min(m, max(k, math.floor(m * math.log(1 / eps) / k)))
    return sum(p - j for j in range(k))


FORMULAS = {"pop_gs": lambda m, k, eps: exhaustive(m, k), "lazy_pop": lambda m, k, eps: exhaustive(m, k),
            "novel_pop": lambda m, k, eps: exhaustive(m, k), "render_variance": lambda m, k, eps: exhaustive(m, k),
            "probe_pop": lambda m, k, eps: exhaustive(m, k), "cover_pop": lambda m, k, eps: exhaustive(m, k),
            "lite_gs": stochastic, "ssg": static_subset,
            "random": lambda m, k, eps: 0, "fisherrf": lambda m, k, eps: exhaustive(m, k),
            "coverage": lambda m, k, eps: 0, "cover": lambda m, k, eps: exhaustive(m, k),
            "cover_pool": lambda m, k, eps: exhaustive(m, k),
            "auto": lambda m, k, eps: exhaustive(m, k)}  # its worst case; a step reports its branch's count
RUN_BY_ITSELF = sorted(set(FORMULAS) - {"auto"})  # auto runs cover_pool or lite_gs (tests/test_auto_selector.py)


def selector(method: str, eps: float):
    return build_selector(method, eps=eps) if method in ("lite_gs", "ssg") else build_selector(method)


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
    assert mean_rounded_up(schedule_counts(selector(method, eps), 100, n0, k, vmax)) == expected


def test_every_selector_has_a_formula_here():
    assert set(FORMULAS) >= set(list_selectors()) - {"_test_dummy"}


@pytest.mark.parametrize("method", sorted(FORMULAS))
@pytest.mark.parametrize("eps", [0.01, 0.1, 0.3, 0.6, 0.95])
def test_closed_forms_equal_the_written_out_formulas(method, eps):
    sel = selector(method, eps)
    for m in range(0, 120, 7):
        for k in (1, 2, 3, 4, 6, 10, 130):
            assert sel.conservative_count(m, k) == FORMULAS[method](m, k, eps), (m, k)


def test_literal_sums_and_schedule():
    # Setup 1, first step: M = 98 candidates, K = 3; ln 10 / 3 * 98 = 75.2
    assert build_selector("pop_gs").conservative_count(98, 3) == 98 + 97 + 96
    assert build_selector("lazy_pop").conservative_count(98, 3) == 98 + 97 + 96  # its worst case: pop_gs's
    assert build_selector("lite_gs", eps=0.1).conservative_count(98, 3) == 75 + 74 + 73
    assert build_selector("ssg", eps=0.1).conservative_count(98, 3) == 75 + 74 + 73
    assert build_selector("random").conservative_count(98, 3) == 0
    assert schedule_counts(build_selector("pop_gs"), 100, 2, 3, 11) == [291, 282, 273]
    assert schedule_counts(build_selector("pop_gs"), 20, 3, 4, 12) == [17 + 16 + 15 + 14, 13 + 12 + 11 + 10, 9]
    assert build_selector("pop_gs").conservative_count(4, 10) == 4 + 3 + 2 + 1  # K >= M: all M chosen
    with pytest.raises(UserError, match="eps"):
        build_selector("lite_gs", eps=1.0)


def test_the_shared_count_helpers_on_literals():
    assert exhaustive_count(98, 3) == 98 + 97 + 96
    assert exhaustive_count(3, 5) == 3 + 2 + 1 and exhaustive_count(0, 3) == 0 and exhaustive_count(7, 0) == 0
    assert mean_rounded_up([291, 282, 273]) == 282 and mean_rounded_up([1, 2]) == 2 and mean_rounded_up([]) == 0


def test_lite_gs_count_does_not_grow_with_k():
    for m in range(20, 300):
        lite = [stochastic(m, k, 0.1) for k in (3, 4, 6)]
        assert lite[0] >= lite[1] >= lite[2]
        pop = [exhaustive(m, k) for k in (3, 4, 6)]
        assert pop[0] < pop[1] < pop[2]
    for eps in (0.1, 0.3, 0.6):  # without the max(1, .) floor the count is at most M ln(1/eps) whatever K
        for m in range(30, 300, 7):
            for k in (3, 4, 6):
                assert stochastic(m, k, eps) <= m * math.log(1 / eps)


@pytest.mark.parametrize("method", RUN_BY_ITSELF)
@pytest.mark.parametrize("k", [3, 4, 6])
@pytest.mark.parametrize("eps", [0.1, 0.3, 0.6])
def test_selector_reports_the_formula_and_the_oracle_counts_evaluations(method, k, eps):
    m = 40
    blocks = random_blocks(m + 1, 3, 2, seed=k)
    if selector(method, eps).oracle_kind == "diagonal":  # the blocks' diagonals, two columns named "means"
        diagonals = torch.diagonal(blocks, dim1=-2, dim2=-1)  # [m + 1, 3, 2]
        oracle = DiagonalGainOracle(diagonals[0], lambda v: diagonals[v + 1], {"means": slice(0, 2)})
        sel_object = build_selector(method, fisherrf_params="means")
    else:
        oracle = BlockGainOracle(BlockInformation(blocks[0]), lambda v: blocks[v + 1])
        sel_object = selector(method, eps)
    if sel_object.oracle_kind == "logdet_cover":  # the gate: another log-det oracle stands in for COVER's
        gate_blocks = random_blocks(m + 1, 3, 2, seed=k + 100)
        oracle = CoverGatedOracle(oracle, BlockGainOracle(BlockInformation(gate_blocks[0]), lambda v: gate_blocks[v + 1]))
    centers = torch.randn(m, 3, generator=torch.Generator().manual_seed(k))
    ctx = SelectionContext(list(range(m)), oracle, torch.Generator().manual_seed(0), 0, camera_centers=centers)
    sel = sel_object.select(ctx, k)
    assert sel.conservative == FORMULAS[method](m, k, eps)
    assert oracle.evaluated <= sel.conservative
    if method in ("pop_gs", "fisherrf", "cover", "render_variance"):
        assert oracle.evaluated == sel.conservative
    assert len(set(sel.ids)) == len(sel.ids) == k
