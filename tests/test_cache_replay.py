"""benchmarks/cache_replay.py: the furthest-next-use replay (MIN) misses no more than a brute-force optimum on
equal-sized views; the LRU and priority replays count what the real `FisherViewBlocks` cache counts on a tiny model."""
import functools
import json
import random

import pytest

from benchmarks.cache_replay import POLICIES, replay, replay_misses
from tests.conftest import run_cli


def optimal_misses(gets: list[int], capacity: int) -> int:
    """Fewest misses of the page sequence `gets` with `capacity` equal-sized slots, by trying every eviction."""

    @functools.lru_cache(maxsize=None)
    def best(i: int, held: frozenset) -> int:
        if i == len(gets):
            return 0
        view = gets[i]
        if view in held:
            return best(i + 1, held)
        if len(held) < capacity:
            return 1 + best(i + 1, held | {view})
        return 1 + min(best(i + 1, (held - {out}) | {view}) for out in held)

    return best(0, frozenset())


def as_requests(gets: list[int], size: int = 10) -> list[tuple]:
    return [("get", view, size) for view in gets]


def test_min_beats_lru_on_a_hand_example():
    trace = as_requests([1, 2, 3, 1])  # room for two views: LRU drops 1 for 3, MIN drops 2 (never asked again)
    assert replay(trace, 20, "lru") == 4
    assert replay(trace, 20, "min") == 3


def test_priority_evicts_the_lowest_hint_first():
    trace = [("hint", 1, 5.0), ("hint", 2, 1.0), *as_requests([1, 2]), ("hint", 3, 9.0), *as_requests([3, 1, 2])]
    assert replay(trace, 20, "priority") == 4  # 3 evicts 2 (hint 1.0): 1 hits, 2 misses
    assert replay(trace, 20, "lru") == 5  # 3 evicts 1, then 1 evicts 2


@pytest.mark.parametrize("seed", range(20))
def test_min_is_optimal_for_equal_sizes(seed):
    rng = random.Random(seed)
    gets = [rng.randrange(5) for _ in range(14)]
    capacity = rng.choice([1, 2, 3])
    optimum = optimal_misses(gets, capacity)
    requests = as_requests(gets)
    assert replay(requests, 10 * capacity, "min") == optimum
    assert replay(requests, 10 * capacity, "lru") >= optimum


def test_a_view_larger_than_the_budget_streams_the_rest():
    assert replay(as_requests([1, 1, 2, 2]) + [("get", 3, 99)] + as_requests([1, 1]), 20, "lru") == 5


def test_misses_name_the_views_recomputed():
    """Views of unequal size: the priority cache keeps the large hinted view and recomputes the small one, LRU the
    large one too; which views a policy recomputes sets its cost, not only how many."""
    trace = [("hint", 1, 9.0), ("hint", 2, 1.0), ("get", 1, 30), ("get", 2, 5), ("get", 3, 10),
             ("get", 1, 30), ("get", 2, 5)]
    assert replay_misses(trace, 40, "priority") == [1, 2, 3, 2]  # 3 evicts 2 (hint 1.0); 1 hits
    assert replay_misses(trace, 40, "lru") == [1, 2, 3, 1, 2]  # 3 evicts 1, 1 evicts 2, 2 evicts 3


def test_replay_counts_what_the_real_cache_counts(tiny_model, tmp_path):
    out = tmp_path / "replay.json"
    r = run_cli("benchmarks/cache_replay.py", "--model", str(tiny_model), "--ms", "8", "--ks", "1", "3", "--selectors",
                "lazy_pop", "lite_gs:0.3", "--threads", "1", "--verify", "--json", str(out), timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = json.loads(out.read_text())["rows"]
    assert len(rows) == 4
    for row in rows:
        assert (row["lru_measured"], row["priority_measured"]) == (row["lru_passes"], row["priority_passes"]), row
        assert row["lru_measured_s"] > 0 and row["priority_measured_s"] > 0, row
        assert row["unlimited_passes"] == row["distinct_views"]
        assert row["min_passes"] <= min(row[f"{p}_passes"] for p in POLICIES), row
        if row["selector"] == "lazy_pop":  # it computes every candidate at least once: the pool's bytes at least
            assert all(row[f"{p}_pass_mb"] >= row["pool_mb"] * (1 - 1e-12) for p in POLICIES), row
        # each distinct view's pass is timed once; a policy's passes include each distinct view at least once
        assert 0 < row["unlimited_pass_s"] <= min(row[f"{p}_pass_s"] for p in POLICIES) * (1 + 1e-12), row
    assert any(row["lru_recomputes"] > 0 for row in rows)  # the quarter budget made the cache recompute
    r = run_cli("benchmarks/cache_replay.py", "--report", str(out))
    assert r.returncode == 0 and "| 8 | 3 | lazy_pop |" in r.stdout, r.stderr
