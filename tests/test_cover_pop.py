"""cover_pop: its picks against a written-out twin (dense log-dets, eligible sets from a set-cover gain computed in
plain Python), its two ends (gate 0 = pop_gs, gate 1 = cover's pick), the gate at every pick, counts, the real
oracle (`build_oracle("logdet_cover")`: the Fisher and COVER oracles committed together) and bad options."""
import pytest
import torch

from active import build_selector
from active.acquisition import run_selection
from active.base import SelectionContext
from active.cover_oracle import CoverageOracle
from active.fisher import FisherOracle, build_oracle
from active.gated_oracle import CoverGatedOracle
from active.logdet import BlockGainOracle, BlockInformation
from active.selectors.cover_pop import gated_candidates
from arguments import FisherSettings
from tests.test_fisher_cache import spiral_cameras
from tests.test_selectors import plain_greedy, problem, rho_dense
from tests.test_view_factors import BG, SETTINGS, model
from utils.errors import UserError

pytestmark = pytest.mark.usefixtures("single_torch_thread")  # tiny batched linear algebra (tests/conftest.py)

M = 12
ITEMS = 30  # the set-cover ground set


class SetCover:
    """A submodular stand-in for COVER: gain(v | S) = the weight of v's items that no committed view holds."""

    def __init__(self, covers: list[set[int]], weights: list[float]):
        self.covers, self.weights, self.taken, self.evaluated = covers, weights, set(), 0

    def gain(self, view: int) -> float:
        self.evaluated += 1
        return sum(self.weights[i] for i in self.covers[view] - self.taken)

    def commit(self, view: int) -> None:
        self.taken |= self.covers[view]

    def reset_counts(self) -> None:
        self.evaluated = 0


def cover_sets(seed: int) -> tuple[list[set[int]], list[float]]:
    g = torch.Generator().manual_seed(seed)
    covers = [set(torch.randperm(ITEMS, generator=g)[:int(torch.randint(3, 12, (1,), generator=g))].tolist())
              for _ in range(M)]
    return covers, torch.rand(ITEMS, generator=g).tolist()


def select(method, blocks, covers, weights, k, **options):
    oracle = CoverGatedOracle(BlockGainOracle(BlockInformation(blocks[0]), lambda v: blocks[v + 1]),
                              SetCover(covers, weights))
    ctx = SelectionContext(list(range(M)), oracle, torch.Generator().manual_seed(0), stage=0)
    return build_selector(method, **options).select(ctx, k), oracle


def written_out(blocks, covers, weights, k, gate):
    """Dense greedy where pick j scores only the candidates whose set-cover gain is >= gate x the largest."""
    chosen, taken = [], set()
    for _ in range(k):
        rest = [v for v in range(M) if v not in chosen]
        gain = {v: sum(weights[i] for i in covers[v] - taken) for v in rest}
        eligible = [v for v in rest if gain[v] >= gate * max(gain.values())] if max(gain.values()) > 0 else rest
        values = rho_dense(blocks, [chosen + [v] for v in eligible])
        chosen.append(eligible[int(torch.argmax(values))])  # first maximum: the lowest id
        taken |= covers[chosen[-1]]
    return chosen


@pytest.mark.parametrize("gate", [0.3, 0.7, 0.9])
@pytest.mark.parametrize("seed", range(4))
def test_picks_equal_the_written_out_twin(gate, seed):
    blocks = problem(m=M, seed=40 + seed)
    covers, weights = cover_sets(seed)
    sel, oracle = select("cover_pop", blocks, covers, weights, 4, cover_gate=gate)
    assert sel.ids == written_out(blocks, covers, weights, 4, gate)
    assert oracle.evaluated <= sel.conservative == sum(M - j for j in range(4))
    assert oracle.cover_evaluated == sum(M - j for j in range(4))  # one COVER gain per remaining candidate per pick
    assert oracle.logdet.information.rho() == pytest.approx(float(rho_dense(blocks, [sel.ids])), rel=1e-9)


def test_the_gate_changes_the_picks_and_every_pick_passes_it():
    changed = 0
    for seed in range(6):
        blocks = problem(m=M, seed=60 + seed)
        covers, weights = cover_sets(seed)
        sel, _ = select("cover_pop", blocks, covers, weights, 4, cover_gate=0.7)
        changed += sel.ids != plain_greedy(blocks, 4)[0]
        reference = SetCover(covers, weights)
        for j, pick in enumerate(sel.ids):
            rest = {v: reference.gain(v) for v in range(M) if v not in sel.ids[:j]}
            assert rest[pick] >= 0.7 * max(rest.values())
            reference.commit(pick)
    assert changed  # the problems discriminate: ungated greedy picks views the gate refuses


@pytest.mark.parametrize("seed", range(3))
def test_gate_zero_is_pop_gs_and_one_is_covers_pick(seed):
    blocks = problem(m=M, seed=80 + seed)
    covers, weights = cover_sets(seed)
    zero = select("cover_pop", blocks, covers, weights, 5, cover_gate=0.0)[0].ids
    assert zero == plain_greedy(blocks, 5)[0]
    one = select("cover_pop", blocks, covers, weights, 5, cover_gate=1.0)[0].ids
    reference, greedy = SetCover(covers, weights), []
    for _ in range(5):
        gains = {v: reference.gain(v) for v in range(M) if v not in greedy}
        greedy.append(max(gains, key=lambda v: gains[v]))  # no exact ties in random weights
        reference.commit(greedy[-1])
    assert one == greedy


def test_gated_candidates_keep_all_when_nothing_gains():
    assert gated_candidates({3: 0.0, 1: 0.0}, 0.7) == [1, 3]
    assert gated_candidates({3: 1.0, 1: 0.69, 2: 0.7}, 0.7) == [2, 3]


def test_the_real_oracle_is_the_fisher_and_cover_committed_together():
    gaussians, cams = model(n=120), spiral_cameras(12)
    train = [0, 6]
    candidates = [v for v in range(len(cams)) if v not in train]
    gated = build_oracle("logdet_cover", gaussians, cams, train, BG, SETTINGS)
    fisher = FisherOracle.build(gaussians, cams, train, BG, SETTINGS, fisher=FisherSettings())
    cover = CoverageOracle.for_model(gaussians, cams, train)
    for view in (candidates[0], candidates[4]):
        assert gated.gain(view) == pytest.approx(fisher.gain(view), rel=1e-12)
        assert gated.cover_gain(view) == pytest.approx(cover.gain(view), rel=1e-12)
        gated.commit(view), fisher.commit(view), cover.commit(view)
    assert gated.gain(candidates[2]) == pytest.approx(fisher.gain(candidates[2]), rel=1e-12)
    assert gated.cover_gain(candidates[2]) == pytest.approx(cover.gain(candidates[2]), rel=1e-12)
    assert gated.evaluated == 3 and gated.cover_evaluated == 3
    step = run_selection(build_selector("cover_pop"), gaussians, cams, train, candidates, 3, BG, SETTINGS)
    assert step.evaluated <= step.selection.conservative == 10 + 9 + 8 and step.fisher_views_computed > 0


@pytest.mark.parametrize("gate", [-0.1, 1.5])
def test_gate_outside_0_1_is_one_clear_error(gate):
    with pytest.raises(UserError, match=r"--cover_gate must lie in \[0, 1\]"):
        build_selector("cover_pop", cover_gate=gate)
