"""The run-time projection: per-step Fisher work, the arithmetic, the suggested -r, and the one-shot estimator."""
import pytest

import training.time_estimate as te
from active.schedule import plan_stages
from active.selectors.lite_gs import LiteGSConfig, LiteGSSelector
from active.selectors.pop_gs import PopGSSelector
from training.time_estimate import (RunTimeEstimator, SelectionWork, estimate_message, fisher_blocks_per_step,
                                    projected_seconds, suggest_resolution)

PLAN = plan_stages(2, 3, 11, 80, 100, 3000)  # Setup 1 on lego: stages of 200, 500, 800 iterations, 3000 in all
POP = SelectionWork(PopGSSelector().conservative_count)


def test_fisher_work_per_step():
    # Cached pop_gs: the prior's views plus every candidate once; its oracles are M + (M-1) + (M-2).
    assert fisher_blocks_per_step(PLAN, 80, POP) == [(2 + 78, 231), (5 + 75, 222), (8 + 72, 213)]
    # Streaming recomputes a candidate's blocks at each oracle.
    streaming = fisher_blocks_per_step(PLAN, 80, SelectionWork(PopGSSelector().conservative_count, streaming=True))
    assert streaming[0] == (2 + 231, 231)
    # lite_gs, eps = 0.1, M = 78, K = 3: subsets of 59, 59, 58 views, together more than the pool.
    lite = SelectionWork(LiteGSSelector(LiteGSConfig(eps=0.1)).conservative_count)
    assert fisher_blocks_per_step(PLAN, 80, lite)[0] == (2 + 78, 176)
    assert fisher_blocks_per_step(PLAN, 80, SelectionWork(None)) == [(0, 0)] * 3


def test_projection_arithmetic():
    step, fisher = 0.5, 2.0
    # 3000 iterations x 0.5 s, plus per acquisition step (80 blocks + 0.15 x oracles) x 2 s, one log-det gain
    # costing 0.15 of a view's blocks (the documented model): 1500 + 2 x (3 x 80 + 0.15 x (231 + 222 + 213)).
    assert projected_seconds(PLAN, 80, POP, 0, step, fisher) == pytest.approx(1500 + 2 * (240 + 99.9))  # 2179.8
    # Past the first acquisition (iteration 200) only two selections and 2,700 iterations remain.
    assert projected_seconds(PLAN, 80, POP, 300, step, fisher) == pytest.approx(1350 + 2 * (160 + 65.25))  # 1800.5
    assert projected_seconds(PLAN, 80, SelectionWork(None), 0, step, 99.0) == pytest.approx(1500)


def test_suggested_resolution():
    limit = 1800.0
    # 16x the limit at full 800 px: -r 2 only quarters it, -r 4 (200 px) is exactly at the limit.
    assert suggest_resolution(16 * limit, (800, 800), (800, 800), limit) == (4, 200, pytest.approx(limit))
    # Already at 200 px of 800 and 9x over: no factor gives a smaller image that fits, so a width: 200 / 3.
    value, width, seconds = suggest_resolution(9 * limit, (200, 200), (800, 800), limit)
    assert (value, width) == (66, 66) and seconds <= limit
    assert suggest_resolution(1e9, (200, 200), (800, 800), limit) is None  # not even 16 px would do


def test_message_only_over_the_limit():
    assert estimate_message(PLAN, 80, POP, 20, 0.1, 0.2, (200, 200), (800, 800)) is None  # ~10 min
    line = estimate_message(PLAN, 80, POP, 20, 1.5, 4.0, (400, 400), (800, 800))  # ~97 min; at 200 px ~24 min
    assert line.startswith("estimate:") and "-r 4 (200 px wide)" in line and "\n" not in line


def test_estimator_reports_once_after_the_measured_iterations(monkeypatch):
    clock = iter(float(t) for t in range(0, 1000, 30))  # 30 s between the two readings
    monkeypatch.setattr(te.time, "perf_counter", lambda: next(clock))
    probes = []
    est = RunTimeEstimator(PLAN, 80, POP, (800, 800), (800, 800), start_iteration=0,
                           fisher_probe=lambda: probes.append(1) or 4.0)
    lines = [est.after_iteration(i) for i in range(1, 40)]
    # Reported once, at iteration 20: 5 warm-up iterations, then 15 timed ones.
    assert [i + 1 for i, line in enumerate(lines) if line] == [20] and probes == [1]
    assert "2.00 s/it" in lines[20 - 1]  # 30 s over the 15 timed iterations
