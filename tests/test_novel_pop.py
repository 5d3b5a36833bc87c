"""novel_pop: its picks against a written-out twin (dense log-dets, eligible sets from plain distances), its two ends
(novelty 0 = pop_gs, novelty 1 = coverage), the novelty rule at every pick, counts and bad options."""
import math

import pytest
import torch

from active import build_selector
from active.base import SelectionContext
from active.logdet import BlockGainOracle, BlockInformation
from tests.test_selectors import plain_greedy, problem, rho_dense
from utils.errors import UserError

pytestmark = pytest.mark.usefixtures("single_torch_thread")  # tiny batched linear algebra (tests/conftest.py)

M = 12
TRAIN = (M, M + 1)  # two training views beside the M candidates 0..M-1


def centers(seed):
    """Camera centres of the M candidates and the two training views. [M + 2, 3]"""
    return torch.randn(M + 2, 3, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


def select(method, blocks, points, k, **options):
    oracle = BlockGainOracle(BlockInformation(blocks[0]), lambda v: blocks[v + 1])
    ctx = SelectionContext(list(range(M)), oracle, torch.Generator().manual_seed(0), stage=0, train_ids=TRAIN,
                           camera_centers=points, scene_center=torch.zeros(3, dtype=torch.float64))
    return build_selector(method, **options).select(ctx, k), oracle


def written_out(blocks, points, k, novelty):
    """Dense greedy where pick j scores only the candidates at least `novelty` x the largest nearest-view distance
    from the training views and earlier picks (math.dist loops), ties to the lowest id."""
    chosen = []
    for _ in range(k):
        taken = list(TRAIN) + chosen
        rest = [v for v in range(M) if v not in chosen]
        nearest = {v: min(math.dist(points[v].tolist(), points[c].tolist()) for c in taken) for v in rest}
        eligible = [v for v in rest if nearest[v] >= novelty * max(nearest.values())]
        values = rho_dense(blocks, [chosen + [v] for v in eligible])
        chosen.append(eligible[int(torch.argmax(values))])  # first maximum: the lowest id
    return chosen


@pytest.mark.parametrize("novelty", [0.3, 0.5, 0.8])
@pytest.mark.parametrize("seed", range(4))
def test_picks_equal_the_written_out_twin(novelty, seed):
    blocks, points = problem(m=M, seed=40 + seed), centers(seed)
    sel, oracle = select("novel_pop", blocks, points, 4, novelty=novelty)
    assert sel.ids == written_out(blocks, points, 4, novelty)
    assert oracle.evaluated <= sel.conservative == sum(M - j for j in range(4))
    assert oracle.information.rho() == pytest.approx(float(rho_dense(blocks, [sel.ids])), rel=1e-9)


def test_the_gate_changes_the_picks_and_every_pick_is_novel():
    changed = 0
    for seed in range(6):
        blocks, points = problem(m=M, seed=60 + seed), centers(seed)
        sel, _ = select("novel_pop", blocks, points, 4, novelty=0.7)
        changed += sel.ids != plain_greedy(blocks, 4)[0]
        taken = list(TRAIN)
        for pick in sel.ids:
            rest = [v for v in range(M) if v not in taken]
            nearest = {v: min(float((points[v] - points[c]).norm()) for c in taken) for v in rest}
            assert nearest[pick] >= 0.7 * max(nearest.values())
            taken.append(pick)
    assert changed  # the problems discriminate: ungated greedy picks views the gate refuses


@pytest.mark.parametrize("seed", range(3))
def test_novelty_zero_is_pop_gs_and_one_is_coverage(seed):
    blocks, points = problem(m=M, seed=80 + seed), centers(seed)
    assert select("novel_pop", blocks, points, 5, novelty=0.0)[0].ids == select("pop_gs", blocks, points, 5)[0].ids
    for space in ("centers", "directions"):
        one = select("novel_pop", blocks, points, 5, novelty=1.0, coverage_space=space)[0].ids
        assert one == select("coverage", blocks, points, 5, coverage_space=space)[0].ids


@pytest.mark.parametrize("novelty", [-0.1, 1.5])
def test_novelty_outside_0_1_is_one_clear_error(novelty):
    with pytest.raises(UserError, match=r"--novelty must lie in \[0, 1\]"):
        build_selector("novel_pop", novelty=novelty)
    with pytest.raises(UserError, match="--coverage_space must be one of"):
        build_selector("novel_pop", coverage_space="sphere")
