"""The Fisher cache that knows the selector: eviction by the selector's priority hints (a lazy greedy's upper
bounds) or LRU, picks unchanged by the policy, and the Fisher passes saved on a small real model with a budget of a
quarter of the pool; lazy_pop against pop_gs on the same model."""
import logging
import math

import pytest
import torch

from active import build_selector
from active.acquisition import run_selection
from active.base import SelectionContext
from active.fisher import FisherOracle, FisherViewBlocks
from arguments import FisherSettings
from scene.cameras import Camera
from tests.scenes import intrinsics_for, look_at_viewmat
from tests.test_view_factors import BG, SETTINGS, H, W, model

pytestmark = pytest.mark.usefixtures("single_torch_thread")  # tiny batched linear algebra (tests/conftest.py)


def fake_blocks(eviction="priority", views=8, room=3):
    """A FisherViewBlocks whose views are 80-byte diagonals, with room for `room` of them; records computes."""
    blocks = FisherViewBlocks(None, [None] * views, BG, SETTINGS, FisherSettings(), diagonal=True, eviction=eviction)
    blocks.cache_bytes = room * 80
    blocks.computed = []
    blocks.compute = lambda v, *dtype: (blocks.computed.append(v), torch.full((10,), float(v), dtype=torch.float64))[1]
    return blocks


def test_priority_eviction_drops_the_lowest_hint_never_the_view_just_added():
    blocks = fake_blocks()
    for v in (0, 1, 2):
        blocks(v)
    blocks.set_priority(0, 5.0), blocks.set_priority(1, 1.0), blocks.set_priority(2, 3.0)
    blocks(3)  # not hinted yet: it is the view asked for (a lazy greedy's heap top), kept
    assert list(blocks._cache) == [0, 2, 3]
    blocks.set_priority(3, 0.5)
    blocks(4)  # the lowest hint now is view 3's
    assert list(blocks._cache) == [0, 2, 4]
    blocks.set_priority(4, 9.0), blocks.set_priority(0, -math.inf)  # view 0 was chosen
    blocks(0)  # a hit: nothing computed, nothing evicted
    blocks(5)
    assert list(blocks._cache) == [2, 4, 5] and blocks._cached_bytes == 3 * 80
    assert blocks.computed == [0, 1, 2, 3, 4, 5] and blocks.fisher_passes == 6 and blocks.views_computed == 6
    blocks(1)  # evicted before: computed again, a second pass of a view already seen
    assert blocks.fisher_passes == 7 and blocks.views_computed == 6


def test_without_hints_or_with_lru_eviction_the_least_recently_used_goes():
    for eviction, hinted in (("priority", False), ("lru", True)):
        blocks = fake_blocks(eviction)
        for v in (0, 1, 2):
            blocks(v)
            if hinted:
                blocks.set_priority(v, 10.0 - v)
        blocks(0)  # used again: view 1 is now the least recently used
        blocks(3)
        assert list(blocks._cache) == [2, 0, 3], eviction
    with pytest.raises(ValueError, match="eviction"):
        fake_blocks("fifo")


def spiral_cameras(count=34):
    """Three turns of a rising spiral around the model: views overlap in many ways."""
    k = intrinsics_for(W, H, 40.0, dtype=torch.float32)
    out = []
    for i in range(count):
        a = 6 * math.pi * i / count
        view = look_at_viewmat((2.2 * math.cos(a), 2.2 * math.sin(a), -1.0 + 2.4 * i / count), dtype=torch.float32)
        out.append(Camera(i, f"v{i}", view, *k.tolist(), W, H))
    return out


@pytest.fixture(scope="module")
def scene():
    """200 Gaussians, 34 cameras of 24 x 24 px, 2 training views, 32 candidates, and the pool's cached bytes."""
    gaussians, cams = model(n=200), spiral_cameras()
    train = [0, 17]
    candidates = [v for v in range(len(cams)) if v not in train]
    probe = FisherOracle.build(gaussians, cams, train, BG, SETTINGS, fisher=FisherSettings(fisher_cache_mb=1 << 14))
    return gaussians, cams, train, candidates, sum(probe.blocks(v).nbytes for v in candidates)


def acquire(scene, method, k, eviction, budget, monkeypatch, options=None):
    """One acquisition step through `run_selection` (the selector sees the oracle through its recorder) with a cache
    budget of `budget` bytes; returns (selection, oracle)."""
    gaussians, cams, train, candidates, _ = scene
    built = []

    def build(*args, **kwargs):
        built.append(FisherOracle.build(*args[1:], **kwargs))  # args[0]: the kind, "logdet"
        built[-1].blocks.eviction = eviction
        return built[-1]

    monkeypatch.setattr("active.acquisition.build_oracle", build)
    monkeypatch.setattr("active.fisher.cache_budget", lambda cache_mb: budget)
    step = run_selection(build_selector(method, **(options or {})), gaussians, cams, train, candidates, k, BG, SETTINGS,
                        fisher=FisherSettings())
    assert step.evaluated == built[0].evaluated
    return step.selection, built[0]


@pytest.mark.parametrize("k", [3, 6])
def test_quarter_budget_priority_eviction_saves_fisher_passes_and_changes_no_pick(scene, monkeypatch, caplog, k):
    quarter = scene[4] // 4
    passes = {}
    for method, options in (("lazy_pop", {}), ("lite_gs", {"eps": 0.1}), ("pop_gs", {})):
        picks = {}
        for eviction, budget in (("priority", quarter), ("lru", quarter), ("priority", 1 << 40)):
            caplog.clear()
            with caplog.at_level(logging.WARNING):
                sel, oracle = acquire(scene, method, k, eviction, budget, monkeypatch, options)
            picks[eviction, budget] = sel.ids, sel.gains
            passes[method, eviction, budget] = oracle.fisher_passes
            assert not oracle.blocks.streaming and oracle.blocks._cached_bytes <= budget
            assert oracle.fisher_passes <= oracle.evaluated  # never more than streaming: one pass per oracle
            if method != "lite_gs":  # the first pick evaluates every candidate
                assert oracle.views_computed == len(scene[3])
            if budget == quarter:  # one line: the cache holds part of the pool
                lines = [r.getMessage() for r in caplog.records if "caching part of them" in r.getMessage()]
                assert len(lines) == 1 and "--fisher_cache_mb" in lines[0], caplog.text
            else:  # the whole pool fits: every view computed once
                assert oracle.fisher_passes == oracle.views_computed and "caching part" not in caplog.text
        assert len(set(map(repr, picks.values()))) == 1, (method, picks)  # the policy changes no pick or gain
    for method in ("lazy_pop", "lite_gs"):  # the hints keep the views lazy greedy asks for again
        assert passes[method, "priority", quarter] < passes[method, "lru", quarter], passes
    assert passes["pop_gs", "priority", quarter] == passes["pop_gs", "lru", quarter]  # no hints: LRU


@pytest.mark.parametrize("k", [3, 6])
def test_lazy_pop_makes_pop_gs_picks_on_a_real_model_with_fewer_oracles(scene, k):
    gaussians, cams, train, candidates, _ = scene
    out = {}
    for method in ("pop_gs", "lazy_pop"):
        oracle = FisherOracle.build(gaussians, cams, train, BG, SETTINGS,
                                    fisher=FisherSettings(fisher_cache_mb=1 << 14))
        sel = build_selector(method).select(SelectionContext(candidates, oracle, torch.Generator().manual_seed(0), 0),
                                            k)
        out[method] = sel, oracle.evaluated
    (pop, pop_evaluated), (lazy, lazy_evaluated) = out["pop_gs"], out["lazy_pop"]
    assert lazy.ids == pop.ids and lazy.gains == pop.gains
    assert lazy.conservative == pop.conservative == pop_evaluated == sum(32 - j for j in range(k))
    assert lazy_evaluated < pop_evaluated
