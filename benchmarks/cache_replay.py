"""Replay one selection's Fisher requests through other cache policies: how many Fisher passes LRU, the priority
cache and the clairvoyant furthest-next-use policy (Belady's MIN) recompute under the same budget.

    python benchmarks/cache_replay.py --model MODEL --ms 100 300 --ks 3 6 --selectors lazy_pop lite_gs:0.1 --verify
    python benchmarks/cache_replay.py --report docs/results/cost_study/cache_replay.json

Why a replay: the views a selector requests do not depend on the cache (a hit and a recomputation give the same
float32 factors), only which requests recompute. So one run per (model, M, selector, K) with an unlimited cache
records its requests and hints (`FisherViewBlocks.requests`), and each policy is replayed on that log with the
budget of `cost_study.py`: a quarter of the bytes the whole pool's factors take (from lazy_pop's first pick, which
computes every candidate; it runs first for each M). Policies:

* lru: evict the least recently requested view (`FisherViewBlocks`, eviction "lru");
* priority: evict the lowest hinted upper bound, unhinted views first, LRU order among equals (eviction "priority");
* min: evict the view whose next request lies furthest ahead, or that is never requested again. With views of equal
  size no policy misses less (Belady 1966); the pool's views differ in size (their visible Gaussians), where MIN is the
  usual clairvoyant reference, not a proven bound.

In every policy the view just requested stays. `--verify` also runs the real cache with the quarter budget under
"priority" and "lru" and checks that the replays count the same Fisher passes. Writes a JSON (rows: Fisher passes
and recomputations per policy, the ratios to LRU) and prints the table; `--report` prints a saved JSON's table.
"""
from __future__ import annotations

import argparse
import math
import time
from collections import OrderedDict
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

from active import build_selector
from active.acquisition import run_selection
from active.base import Selection, SelectionContext, Selector
from active.fisher import eviction_victim
from benchmarks.cost_study import UNLIMITED_MB, load_source, selector_setting
from recommender.pipeline import candidate_cameras, make_pool
from utils.errors import UserError, run_cli
from utils.io import read_json, write_json
from utils.provenance import environment_record

RESULTS_DIR = Path(__file__).parent / "results"
POLICIES = ("lru", "priority", "min")
Request = tuple  # ("get", view, bytes) | ("hint", view, bound)


def next_requests(requests: list[Request]) -> list[float]:
    """For each entry of `requests`: the position of the next "get" of the same view after it (inf if none; only
    meaningful at "get" entries)."""
    upcoming: dict[int, int] = {}
    out = [math.inf] * len(requests)
    for i in range(len(requests) - 1, -1, -1):
        kind, view, _ = requests[i]
        if kind == "get":
            out[i] = upcoming.get(view, math.inf)
            upcoming[view] = i
    return out


def requested_bytes(requests: list[Request]) -> dict[int, int]:
    """Each requested view's factor bytes. -> {view: bytes}"""
    return {view: size for kind, view, size in requests if kind == "get"}


def replay(requests: list[Request], budget_bytes: int, policy: str) -> int:
    """The Fisher passes (cache misses) of `requests` under `policy` with a cache of `budget_bytes`."""
    return len(replay_misses(requests, budget_bytes, policy))


def replay_misses(requests: list[Request], budget_bytes: int, policy: str) -> list[int]:
    """The view of each Fisher pass (cache miss) of `requests` under `policy` with a cache of `budget_bytes`, in
    order, mirroring `FisherViewBlocks.__call__`: a miss adds the view, then views are evicted while more than one is
    held and the bytes exceed the budget; a view larger than the budget alone turns the cache off (streaming) for the
    rest. Which views are recomputed, not only how many, sets a policy's time: views differ in size and pass time."""
    if policy not in POLICIES:
        raise ValueError(f"policy must be one of {POLICIES}, got {policy!r}")
    following = next_requests(requests) if policy == "min" else []
    cache: OrderedDict[int, int] = OrderedDict()  # view -> bytes, least recently requested first
    next_use: dict[int, float] = {}  # cached view -> position of its next request (min)
    hints: dict[int, float] = {}
    held, streaming = 0, False
    misses: list[int] = []
    for i, (kind, view, value) in enumerate(requests):
        if kind == "hint":
            hints[view] = value
            continue
        if policy == "min":
            next_use[view] = following[i]
        if view in cache:
            cache.move_to_end(view)
            continue
        misses.append(view)
        if streaming:
            continue
        if value > budget_bytes:
            streaming = True
            cache.clear()
            continue
        cache[view] = value
        held += value
        while len(cache) > 1 and held > budget_bytes:
            held -= cache.pop(victim(cache, view, policy, hints, next_use))
    return misses


def victim(cache: OrderedDict[int, int], keep: int, policy: str, hints: dict[int, float],
           next_use: dict[int, float]) -> int:
    """The cached view `policy` evicts (never `keep`): "lru" and "priority" as `FisherViewBlocks` does
    (`active.fisher.eviction_victim`), "min" the one requested furthest ahead (the least recently requested among
    equals)."""
    if policy != "min":
        return eviction_victim(cache, keep, policy, hints)
    return max((v for v in cache if v != keep), key=lambda v: next_use[v])


class _RecordingSelector(Selector):
    """`selector` with its Fisher cache's request log switched on (and, for --verify, a budget and eviction set)
    before the first candidate is computed."""

    def __init__(self, selector: Selector, cache_bytes: int | None = None, eviction: str = "priority"):
        self.selector, self.cache_bytes, self.eviction = selector, cache_bytes, eviction
        self.name, self.uses_oracle, self.oracle_kind = selector.name, selector.uses_oracle, selector.oracle_kind
        self.requests: list[Request] = []
        self.fisher_passes, self.fisher_seconds = 0, 0.0
        self.pass_seconds: dict[int, float] = {}  # view -> seconds of its (last) Fisher pass

    def conservative_count(self, m: int, k: int) -> int:
        return self.selector.conservative_count(m, k)

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        blocks = ctx.oracle.blocks
        blocks.requests, blocks.eviction = self.requests, self.eviction
        compute = blocks.compute

        def timed_compute(view_id: int, *args: Any) -> Any:  # this benchmark's instrument: one pass's seconds
            t0 = time.perf_counter()
            out = compute(view_id, *args)
            self.pass_seconds[view_id] = time.perf_counter() - t0
            return out

        blocks.compute = timed_compute
        if self.cache_bytes is not None:
            blocks.cache_bytes = self.cache_bytes
        selection = self.selector.select(ctx, k)
        self.fisher_passes, self.fisher_seconds = blocks.fisher_passes, blocks.fisher_seconds
        return selection


def run_rows(source: dict, ms: list[int], ks: list[int], settings: list[tuple[str, float | None]], verify: bool,
             candidates: str, seed: int) -> tuple[list[dict], dict]:
    """Record and replay every (M, setting, K) on `source` (`benchmarks.cost_study.load_source`'s); lazy_pop is run
    first for each M (it sizes the budget)."""
    model = load_source(source)
    fisher = replace(model.fisher, fisher_mode="cached", fisher_cache_mb=UNLIMITED_MB)
    rows = []
    for m in ms:
        pool = make_pool(model, candidate_cameras(f"{candidates}:{m}", model), width=model.captured[0].width)

        def select(selector: Selector, k: int) -> list[int]:
            return run_selection(selector, model.gaussians, pool.cameras, pool.train_ids, pool.candidate_ids, k,
                                 model.background, model.settings, seed=seed, fisher=fisher).selection.ids

        sizing = _RecordingSelector(build_selector("lazy_pop"))
        select(sizing, 1)
        sizes = requested_bytes(sizing.requests)
        if len(sizes) != len(pool.candidate_ids):
            raise RuntimeError(f"lazy_pop's first pick requested {len(sizes)} of {len(pool.candidate_ids)} views")
        budget = sum(sizes.values()) // 4
        for name, eps in settings:
            for k in ks:
                selector = build_selector(name, **({} if eps is None else {"eps": eps}))
                recorder = _RecordingSelector(selector)
                t0 = time.perf_counter()
                picks = select(recorder, k)
                view_bytes = requested_bytes(recorder.requests)
                distinct = len(view_bytes)
                misses = {policy: replay_misses(recorder.requests, budget, policy) for policy in POLICIES}
                passes = {policy: len(misses[policy]) for policy in POLICIES}
                row = {"M": m, "K": k, "selector": name, "eps": eps, "picks": picks, "budget_mb": budget / 2**20,
                       "pool_mb": sum(sizes.values()) / 2**20, "requests": sum(r[0] == "get" for r in recorder.requests),
                       "distinct_views": distinct, "unlimited_passes": recorder.fisher_passes,
                       "record_s": time.perf_counter() - t0,
                       **{f"{p}_passes": passes[p] for p in POLICIES},
                       **{f"{p}_recomputes": passes[p] - distinct for p in POLICIES},
                       # the bytes and, from the unlimited run's pass of each view, the seconds of each policy's
                       # passes: what its recomputations cost, not only how many
                       **{f"{p}_pass_mb": sum(view_bytes[v] for v in misses[p]) / 2**20 for p in POLICIES},
                       "unlimited_pass_s": sum(recorder.pass_seconds.values()),
                       **{f"{p}_pass_s": sum(recorder.pass_seconds[v] for v in misses[p]) for p in POLICIES}}
                if recorder.fisher_passes != distinct:
                    raise RuntimeError(f"{name} M={m} K={k}: the unlimited cache recomputed a view")
                if verify:
                    for policy in ("priority", "lru"):
                        real = _RecordingSelector(selector, budget, policy)
                        if select(real, k) != picks:
                            raise RuntimeError(f"{name} M={m} K={k}: the {policy} cache changed the picks")
                        row[f"{policy}_measured"] = real.fisher_passes
                        row[f"{policy}_measured_s"] = real.fisher_seconds  # its Fisher seconds, the prior's included
                rows.append(row)
                print(format_row(row), flush=True)
    return rows, {"gaussians": model.gaussians.num_gaussians, "image": f"{pool.cameras[0].width}x{pool.cameras[0].height}"}


def ratio(a: int, b: int) -> str:
    return f"{a / b:.2f}" if b else "-"


HEADER = ("| M | K | selector | requests | views | LRU recomputes | priority | MIN | priority / LRU | MIN / LRU | "
          "replay = measured | MB per pass, LRU / priority | pass s, LRU / priority |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def format_row(row: dict[str, Any]) -> str:
    """One markdown row: recomputations per policy and the ratios to LRU's."""
    name = row["selector"] if row["eps"] is None else f"{row['selector']} ε={row['eps']:g}"
    lru, pri, opt = (row[f"{p}_recomputes"] for p in POLICIES)
    if "lru_measured" in row:
        check = "yes" if (row["lru_measured"], row["priority_measured"]) == (row["lru_passes"], row["priority_passes"]) \
            else f"no ({row['lru_measured']}, {row['priority_measured']})"
    else:
        check = "not run"
    per_pass = (f"{row['lru_pass_mb'] / row['lru_passes']:.1f} / {row['priority_pass_mb'] / row['priority_passes']:.1f}"
                if "lru_pass_mb" in row else "-")
    seconds = f"{row['lru_pass_s']:.1f} / {row['priority_pass_s']:.1f}" if "lru_pass_s" in row else "-"
    return (f"| {row['M']} | {row['K']} | {name} | {row['requests']:,} | {row['distinct_views']} | {lru:,} | {pri:,} | "
            f"{opt:,} | {ratio(pri, lru)} | {ratio(opt, lru)} | {check} | {per_pass} | {seconds} |")


def report(path: Path) -> None:
    """Print the table of a saved JSON."""
    doc = read_json(path, fix="rerun benchmarks/cache_replay.py")
    env = doc["environment"]
    print(f"{path}: {doc['model']}, {doc['gaussians']:,} Gaussians at {doc['image']}, {doc['candidates']} candidates, "
          f"a quarter-pool budget; {env['started'][:10]}, code {env['code']}")
    print(HEADER)
    for row in doc["rows"]:
        print(format_row(row))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", help="a train.py model directory (the prior: its training views)")
    parser.add_argument("--garden", help="instead of --model: the garden's SfM initialisation at WxH (648x420), as in "
                        "cost_study.py")
    parser.add_argument("--ms", type=int, nargs="+", default=[100, 300], help="pool sizes")
    parser.add_argument("--ks", type=int, nargs="+", default=[3, 6])
    parser.add_argument("--selectors", nargs="+", default=["lazy_pop", "lite_gs:0.1"],
                        help="NAME or NAME:EPS (pop_gs, lazy_pop, lite_gs, ssg)")
    parser.add_argument("--candidates", default="hemisphere", choices=("hemisphere", "orbit"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--verify", action="store_true", help="also run the real priority and LRU caches and compare")
    parser.add_argument("--json", type=Path, default=None, help="output JSON (default: results/cache_replay_DATE.json)")
    parser.add_argument("--report", type=Path, default=None, help="only print the table of a saved JSON")
    args = parser.parse_args()
    if args.report:
        report(args.report)
        return
    if args.garden:
        source, name = {"garden": args.garden}, f"garden {args.garden}"
    elif not args.model or not Path(args.model).is_dir():
        raise UserError(f"--model {args.model}: no such model directory (train one with train.py), or --garden WxH")
    else:
        source, name = {"model": str(Path(args.model).resolve())}, Path(args.model).resolve().name
    if min(args.ms) < max(args.ks) or min(args.ks) < 1:
        raise UserError("--ks must lie in 1..min(--ms)")
    settings = [selector_setting(text) for text in args.selectors]
    torch.set_num_threads(args.threads)
    env = environment_record(device="cpu")
    print(HEADER)
    rows, model = run_rows(source, args.ms, args.ks, settings, args.verify, args.candidates, args.seed)
    out = args.json or RESULTS_DIR / f"cache_replay_{time.strftime('%Y%m%d_%H%M%S')}.json"
    write_json(out, {"environment": env, "model": name, **model,
                     "candidates": args.candidates, "threads": args.threads, "rows": rows})
    print(f"wrote {out}")


if __name__ == "__main__":
    run_cli(main)
