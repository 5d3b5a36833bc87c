"""Selection cost study (issue 42): what pop_gs, lazy_pop, lite_gs and ssg cost over pools of M generated candidates
and K picks, with an unlimited Fisher cache and with a budget that holds a quarter of the pool (priority and LRU
eviction): evaluated oracles, Fisher passes, wall time, peak memory and rho(S) / rho(greedy).

    python benchmarks/cost_study.py --preset quick --model LEGO_200PX_MODEL
    python benchmarks/cost_study.py --preset full --model LEGO_200PX_MODEL --garden 648x420
    python benchmarks/cost_study.py --report benchmarks/results/cost_study_DATE.json [--out_dir docs/results/cost_study]

Models: `--model DIR` (train.py model directories; the prior is the recorded training views) and `--garden WxH` (the
garden SfM initialisation of `scene.garden`; the prior is its 3 cameras). Candidates: M poses of
`recommender.candidates` (`--candidates hemisphere` or `orbit`) around the prior's views, at the prior's image size.

Each configuration (model, M, selector setting, cache) runs in its own process, one after the other, so its peak
resident memory is its own: run the study alone on an idle machine. pop_gs and lazy_pop run once, with the largest
K: their first K picks do not depend on K (plain and lazy greedy over the whole pool), so the counts, times and peak
memory after pick K are those of a run with that K. lite_gs and ssg draw subsets whose size depends on K: one run per
K. Wall seconds = the prior's Fisher passes + the selection (`run_selection`, what train.py and recommend.py call),
after a warm-up off the clock. rho(S) = logdet(A_S) - logdet(A_0) from the oracle's own information after the picks,
the same objective for every selector; greedy = pop_gs (lazy_pop where pop_gs did not finish: the same picks). The
quarter budget is a quarter of the bytes the whole pool took in the unlimited cache of the same model and M; pop_gs
gives the cache no hints, so its LRU rows are its priority run's. A configuration past --timeout_s, or with less than --reserve_mb of memory left, stops at its next oracle and reports
its counts so far (status "timeout" / "memory").

Writes benchmarks/results/cost_study_DATE.json (rewritten after every configuration) and beside it the report: a
markdown file (.md: the targets of issue 42, the regime where lite_gs's wall time is <= 0.5x the faster exact
method, the lite_gs / exact ratios and every row) and a plot (.png). `--report JSON` rebuilds both from a saved JSON.
`--resume --json JSON` continues an interrupted or partial study (the full preset takes 15-16 h on 2 cores: run it in
pieces): the configurations whose rows JSON holds are kept, the others run and are added; each row carries its own
date, machine and code commit.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import torch

from active import build_selector
from active.acquisition import run_selection
from active.base import Selection, SelectionContext, Selector
from arguments import FisherSettings
from recommender.pipeline import LoadedModel, candidate_cameras, load_model, make_pool
from scene.garden import GARDEN, load_garden
from utils.errors import UserError, run_cli
from utils.io import atomic_write, write_json
from utils.provenance import environment_record
from utils.system_memory import available_memory_bytes

RESULTS_DIR = Path(__file__).parent / "results"
EXACT = ("pop_gs", "lazy_pop")  # greedy over the whole pool: pick j does not depend on K (one run, the largest K)
GREEDY = "pop_gs"  # the reference of rho(S) / rho(greedy) and of the shared picks
UNLIMITED_MB = 1 << 30  # a cache budget no pool reaches (1 PiB)
CACHES = {"unlimited": "priority", "quarter": "priority", "quarter_lru": "lru"}  # cache -> eviction, unlimited first
NO_HINTS = ("pop_gs",)  # gives the cache no priority hints: its priority eviction is LRU (active/fisher.py)
GRACE_S = 300  # beyond --timeout_s: model loading, the warm-up and the last oracle before a child is killed
RATIO = 0.5  # the regime asked for: lite_gs's wall time <= RATIO x the faster exact method's


@dataclass(frozen=True)
class Preset:
    """A grid: pool sizes, K values, (selector, eps) settings, caches, the time limit of one configuration."""

    ms: tuple[int, ...]
    ks: tuple[int, ...]
    settings: tuple[tuple[str, float | None], ...]
    caches: tuple[str, ...]
    timeout_s: float


PRESETS = {
    "full": Preset((100, 300, 1000), (1, 3, 6, 12, 20), (("pop_gs", None), ("lazy_pop", None), ("lite_gs", 0.1),
                                                          ("lite_gs", 0.3), ("ssg", 0.1)), tuple(CACHES), 600),
    "quick": Preset((100, 300), (3, 6), (("pop_gs", None), ("lazy_pop", None), ("lite_gs", 0.1)), tuple(CACHES), 600),
    "smoke": Preset((8,), (1, 3), (("pop_gs", None), ("lazy_pop", None), ("lite_gs", 0.3)), tuple(CACHES), 120),
}


def label(selector: str, eps: float | None) -> str:
    """The setting's name in tables: "pop_gs", "lite_gs eps=0.1"."""
    return selector if eps is None else f"{selector} eps={eps:g}"


def peak_rss_mb() -> float:
    """This process's peak resident memory so far, MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


class Stop(Exception):
    """A configuration stopped before its last pick; `status` is "timeout" or "memory"."""

    def __init__(self, status: str, note: str):
        super().__init__(note)
        self.status = status


class TracedOracle:
    """The selector's oracle, recording after every commit what the run has cost so far (`trace`, one entry per
    pick) and stopping the run at its next oracle past `deadline` or below `reserve_bytes` of free memory; every
    other attribute (counts, the cache's priority hints) is the oracle's own."""

    def __init__(self, oracle: Any, t0: float, deadline: float, reserve_bytes: int):
        self._oracle, self._t0, self._deadline, self._reserve = oracle, t0, deadline, reserve_bytes
        self._off_clock = 0.0  # seconds spent recording (rho), not counted as wall time
        self._gains: dict[int, float] = {}
        self.trace: list[dict] = []

    def gain(self, view_id: int) -> float:
        if time.perf_counter() > self._deadline:
            raise Stop("timeout", f"stopped after {time.perf_counter() - self._t0:.0f} s (--timeout_s)")
        if available_memory_bytes() < self._reserve:
            raise Stop("memory", f"stopped with {available_memory_bytes() / 2**20:.0f} MB of memory left "
                                 f"(--reserve_mb), {self._oracle.blocks.cached_bytes / 2**20:.0f} MB cached")
        self._gains[view_id] = value = self._oracle.gain(view_id)
        return value

    def commit(self, view_id: int) -> None:
        self._oracle.commit(view_id)
        self.trace.append({"view": view_id, "gain": self._gains[view_id], **self.snapshot()})

    def snapshot(self) -> dict:
        """The run's cost so far: wall and Fisher seconds (prior included), oracle and Fisher pass counts, rho(S) of
        the committed views, cached bytes, peak RSS."""
        now = time.perf_counter()
        o = self._oracle
        state = {"wall_s": now - self._t0 - self._off_clock, "fisher_s": o.fisher_seconds, "evaluated": o.evaluated,
                 "fisher_passes": o.fisher_passes, "views_computed": o.views_computed, "rho": o.information.rho(),
                 "cached_bytes": o.blocks.cached_bytes, "peak_rss_mb": peak_rss_mb()}
        self._off_clock += time.perf_counter() - now
        return state

    def __getattr__(self, name: str) -> Any:
        return getattr(self._oracle, name)


class TracedSelector(Selector):
    """`selector` run on a `TracedOracle`; sets the Fisher cache's budget (None: as built) and eviction policy before
    the first candidate is computed (the prior's views never enter the cache)."""

    def __init__(self, selector: Selector, cache_bytes: int | None, eviction: str, timeout_s: float,
                 reserve_bytes: int):
        self.selector, self.cache_bytes, self.eviction = selector, cache_bytes, eviction
        self.timeout_s, self.reserve_bytes = timeout_s, reserve_bytes
        self.name, self.uses_oracle, self.oracle_kind = selector.name, selector.uses_oracle, selector.oracle_kind
        self.t0 = time.perf_counter()  # the clock's start: reset by the caller just before run_selection
        self.oracle: TracedOracle | None = None

    def conservative_count(self, m: int, k: int) -> int:
        return self.selector.conservative_count(m, k)

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        blocks = ctx.oracle.blocks
        if self.cache_bytes is not None:
            blocks.cache_bytes = self.cache_bytes
        blocks.eviction = self.eviction
        self.oracle = TracedOracle(ctx.oracle, self.t0, self.t0 + self.timeout_s, self.reserve_bytes)
        return self.selector.select(replace(ctx, oracle=self.oracle), k)


def load_source(source: dict) -> LoadedModel:
    """A model directory ({"model": DIR}) or the garden ({"garden": "WxH"}) as recommend.py's `LoadedModel`."""
    if "garden" in source:
        gaussians, cameras, background, settings = load_garden(source["garden"])
        return LoadedModel(GARDEN, "ply", gaussians, cameras, background, settings, FisherSettings())
    return load_model(source["model"])


def run_config(spec: dict) -> dict:
    """One configuration in this process: the pool, a warm-up, then the traced selection of `spec["k_run"]` views."""
    torch.set_num_threads(spec["threads"])
    model = load_source(spec["source"])
    pool = make_pool(model, candidate_cameras(f"{spec['candidates']}:{spec['M']}", model),
                     width=model.captured[0].width)
    fisher = replace(model.fisher, fisher_mode="cached", fisher_cache_mb=UNLIMITED_MB)

    def select(selector: Selector, train_ids: list[int], candidate_ids: list[int], k: int) -> None:
        run_selection(selector, model.gaussians, pool.cameras, train_ids, candidate_ids, k, model.background,
                      model.settings, seed=spec["seed"], fisher=fisher)

    select(build_selector("pop_gs"), pool.train_ids[:1], pool.candidate_ids[:1], 1)  # loads the kernels (numba)
    options = {} if spec["eps"] is None else {"eps": spec["eps"]}
    traced = TracedSelector(build_selector(spec["selector"], **options), spec["cache_bytes"],
                            CACHES[spec["cache"]], spec["timeout_s"], spec["reserve_mb"] << 20)
    status, note = "ok", ""
    traced.t0 = time.perf_counter()
    try:
        select(traced, pool.train_ids, pool.candidate_ids, spec["k_run"])
    except Stop as stop:
        status, note = stop.status, str(stop)
    camera = pool.cameras[pool.candidate_ids[0]]
    return {"config": spec, "status": status, "note": note, "gaussians": model.gaussians.num_gaussians,
            "image": f"{camera.width}x{camera.height}", "prior_views": len(pool.train_ids),
            "trace": traced.oracle.trace, "final": traced.oracle.snapshot()}


def run_child(spec: dict) -> dict:
    """`run_config(spec)` in a fresh process (its own peak memory); a failed or killed child gives a result with
    that status and no counts."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "result.json"
        cmd = [sys.executable, str(Path(__file__).resolve()), "--run_config", json.dumps(spec), "--json", str(out)]
        try:
            done = subprocess.run(cmd, capture_output=True, text=True, timeout=spec["timeout_s"] + GRACE_S)
        except subprocess.TimeoutExpired:
            return {"config": spec, "status": "killed", "note": f"no result after {spec['timeout_s'] + GRACE_S:.0f} s"}
        if done.returncode != 0 or not out.is_file():
            tail = (done.stderr.strip().splitlines() or ["no output"])[-1]
            return {"config": spec, "status": "failed", "note": f"exit status {done.returncode}: {tail}"}
        return json.loads(out.read_text())


def pool_bytes(result: dict) -> int | None:
    """The bytes of the whole pool's cached factors, from an unlimited-cache run: what the cache held after the
    first pick when every candidate was computed by then (pop_gs, lazy_pop), else extrapolated from the views
    computed before the run stopped; None without any."""
    m, trace, final = result["config"]["M"], result.get("trace") or [], result.get("final")
    if trace and trace[0]["views_computed"] == m:
        return trace[0]["cached_bytes"]
    if final and final["views_computed"]:
        return round(final["cached_bytes"] * m / final["views_computed"])
    return None


def result_rows(result: dict, ks: list[int], model: str, env: dict) -> list[dict]:
    """One row per K of a configuration's result: the trace after pick K, or the state where it stopped."""
    spec = result["config"]
    trace, final = result.get("trace") or [], result.get("final")
    selector = build_selector(spec["selector"], **({} if spec["eps"] is None else {"eps": spec["eps"]}))
    rows = []
    for k in ks:
        state = trace[k - 1] if len(trace) >= k else final
        ok = len(trace) >= k
        row = {"machine": env["machine"], "cpu": env["cpu"], "date": env["started"], "code": env["code"],
               "threads": spec["threads"], "model": model, "gaussians": result.get("gaussians"),
               "image": result.get("image"), "prior_views": result.get("prior_views"), "M": spec["M"], "K": k,
               "selector": spec["selector"], "eps": spec["eps"], "setting": label(spec["selector"], spec["eps"]),
               "cache": spec["cache"], "eviction": CACHES[spec["cache"]],
               "cache_mb": None if spec["cache_bytes"] is None else spec["cache_bytes"] / 2**20,
               "status": "ok" if ok else result["status"], "note": "" if ok else result["note"],
               "conservative": selector.conservative_count(spec["M"], k), "picks": [t["view"] for t in trace[:k]]}
        if state is not None:
            row.update({key: state[key] for key in ("evaluated", "fisher_passes", "views_computed", "fisher_s",
                                                    "wall_s", "peak_rss_mb", "rho")})
            row["recomputes"] = state["fisher_passes"] - state["views_computed"]
        rows.append(row)
    return rows


def sources(args: argparse.Namespace) -> list[tuple[dict, str]]:
    """(source spec, model name) of every --model and --garden, checked before anything runs."""
    out = []
    for path in args.model or []:
        if not Path(path).is_dir():
            raise UserError(f"--model {path}: no such model directory (train one with train.py)")
        out.append(({"model": str(Path(path).resolve())}, Path(path).resolve().name))
    for size in args.garden or []:
        if not GARDEN.is_file():
            raise UserError(f"--garden: {GARDEN} not found (../shared/data/gsplat_garden)")
        width, _, height = size.partition("x")
        if not (width.isdigit() and height.isdigit()):
            raise UserError(f"--garden {size}: give WxH, e.g. 648x420")
        out.append(({"garden": size}, "garden"))
    if not out:
        raise UserError("give at least one model: --model DIR (a train.py model directory) or --garden WxH")
    return out


def selector_setting(text: str) -> tuple[str, float | None]:
    """"NAME" or "NAME:EPS" (lite_gs, ssg) as a preset's (selector, eps) setting."""
    name, _, eps = text.partition(":")
    known = {s for preset in PRESETS.values() for s, _ in preset.settings}
    if name not in known:
        raise UserError(f"--selectors: unknown selector {name!r}; the study runs {', '.join(sorted(known))}")
    if (name in EXACT) == bool(eps):
        raise UserError(f"--selectors {text}: " + ("pop_gs and lazy_pop take no eps" if eps else
                                                   f"{name} needs an eps, e.g. {name}:0.1"))
    try:
        value = float(eps) if eps else None
    except ValueError:
        raise UserError(f"--selectors {text}: eps must be a number in (0, 1)") from None
    if value is not None and not 0.0 < value < 1.0:
        raise UserError(f"--selectors {text}: eps must lie in (0, 1)")
    return name, value


def narrowed(preset: Preset, selectors: list[str] | None, caches: list[str] | None) -> Preset:
    """`preset` with only the given selector settings and caches (None: all of the preset's)."""
    if selectors:
        preset = replace(preset, settings=tuple(selector_setting(text) for text in selectors))
    if caches:
        if "unlimited" not in caches:  # the quarter budgets are sized by the unlimited run
            raise UserError("--caches: the quarter budgets are a quarter of the unlimited run's pool; include unlimited")
        preset = replace(preset, caches=tuple(c for c in CACHES if c in caches))
    return preset


def plan(args: argparse.Namespace, preset: Preset, ms: list[int], ks: list[int]) -> list[tuple[dict, str, list[int]]]:
    """(child spec without its cache budget, model name, the Ks its rows report) of every configuration, in run
    order: per model and M the unlimited cache first (pop_gs first: it sizes the quarter budget)."""
    out = []
    for source, name in sources(args):
        for m in ms:
            for cache in preset.caches:
                for selector, eps in preset.settings:
                    for k_run in ([max(ks)] if selector in EXACT else ks):
                        spec = {"source": source, "candidates": args.candidates, "M": m, "k_run": k_run,
                                "selector": selector, "eps": eps, "cache": cache, "cache_bytes": None,
                                "threads": args.threads, "seed": args.seed, "timeout_s": args.timeout_s,
                                "reserve_mb": args.reserve_mb}
                        out.append((spec, name, [k for k in ks if k <= k_run] if selector in EXACT else [k_run]))
    return out


def earlier_results(path: Path, timeout_s: float) -> tuple[list[dict], dict[str, int]]:
    """The rows and pool sizes of an earlier run's JSON, for --resume (same per-configuration limit required)."""
    if not path.is_file():
        raise UserError(f"--resume: {path} not found; give the --json of the run to continue")
    doc = json.loads(path.read_text())
    if doc.get("timeout_s") != timeout_s:
        raise UserError(f"--resume: {path} ran with --timeout_s {doc.get('timeout_s')}, not {timeout_s}; give the same")
    return doc["rows"], doc.get("pool_bytes", {})


def has_rows(rows: list[dict], spec: dict, name: str, ks: list[int]) -> bool:
    """Whether `rows` hold the rows of this configuration for every K in `ks` (whatever their status)."""
    setting = label(spec["selector"], spec["eps"])
    done = {r["K"] for r in rows if (r["model"], r["M"], r["setting"], r["cache"]) == (name, spec["M"], setting,
                                                                                       spec["cache"])}
    return set(ks) <= done


def study(args: argparse.Namespace) -> Path:
    """Run the grid, one child process per configuration; returns the JSON written."""
    preset = narrowed(PRESETS[args.preset], args.selectors, args.caches)
    ms, ks = sorted(args.ms or preset.ms), sorted(args.ks or preset.ks)
    if max(ks) > min(ms):
        raise UserError(f"K = {max(ks)} exceeds the smallest pool M = {min(ms)}")
    args.timeout_s = args.timeout_s or preset.timeout_s
    configs = plan(args, preset, ms, ks)
    env = environment_record(device="cpu")
    out = args.json or RESULTS_DIR / f"cost_study_{time.strftime('%Y%m%d_%H%M%S')}.json"
    doc = {"environment": env, "preset": args.preset, "command": " ".join(sys.argv), "ms": ms, "ks": ks,
           "timeout_s": args.timeout_s, "rows": [], "pool_bytes": {}}
    if args.resume:
        doc["rows"], doc["pool_bytes"] = earlier_results(out, args.timeout_s)
    sizes = doc["pool_bytes"]  # "source|M" -> the pool's cached bytes in the unlimited run
    print(f"{len(configs)} configurations, one process each, one after the other -> {out}", flush=True)
    for i, (spec, name, row_ks) in enumerate(configs, 1):
        key = f"{json.dumps(spec['source'])}|{spec['M']}"
        tag = f"[{i}/{len(configs)}] {name} M={spec['M']} {label(spec['selector'], spec['eps'])} " \
              f"K={spec['k_run']} {spec['cache']}"
        if has_rows(doc["rows"], spec, name, row_ks):
            print(f"{tag}: kept from {out.name}", flush=True)
            continue
        if spec["cache"] != "unlimited":
            if key not in sizes:
                print(f"{tag}: skipped (no unlimited-cache run sized the pool)", flush=True)
                continue
            spec["cache_bytes"] = sizes[key] // 4
        if spec["cache"] == "quarter_lru" and spec["selector"] in NO_HINTS:  # its "quarter" run, under this name
            rows = [dict(r, cache=spec["cache"], eviction="lru", note="the quarter run: no hints, priority = LRU")
                    for r in doc["rows"] if (r["model"], r["M"], r["setting"], r["cache"]) ==
                    (name, spec["M"], label(spec["selector"], spec["eps"]), "quarter")]
        else:
            result = run_child(spec)
            if spec["cache"] == "unlimited" and key not in sizes and pool_bytes(result) is not None:
                sizes[key] = pool_bytes(result)
            rows = result_rows(result, row_ks, name, env)
            last, note = rows[-1], f" ({result['note']})" if result.get("note") else ""
            print(f"{tag}: {result['status']}{note} | wall {last.get('wall_s', float('nan')):.1f} s, "
                  f"{last.get('evaluated')} evaluated, {last.get('fisher_passes')} Fisher passes, peak "
                  f"{last.get('peak_rss_mb', float('nan')):.0f} MB", flush=True)
        doc["rows"] += rows
        finalise(doc["rows"])
        write_json(out, doc)
    return out


# ---- the report: derived columns, markdown, plot ----

def _index(rows: list[dict]) -> dict[tuple, dict]:
    return {(r["model"], r["M"], r["K"], r["setting"], r["cache"]): r for r in rows}


def finalise(rows: list[dict]) -> None:
    """Adds rho_ratio = rho(S) / rho(greedy), same_picks (picks shared with greedy's) and identical (the same picks
    in the same order) to every finished row; greedy = pop_gs's finished row of the same model, M and K (any cache:
    the picks do not depend on it), else lazy_pop's."""
    greedy: dict[tuple, dict] = {}
    for setting in ("lazy_pop", GREEDY):  # pop_gs overrides
        for r in rows:
            if r["setting"] == setting and r["status"] == "ok":
                greedy[r["model"], r["M"], r["K"]] = r
    for r in rows:
        ref = greedy.get((r["model"], r["M"], r["K"]))
        done = r["status"] == "ok" and ref is not None
        r["rho_ratio"] = r["rho"] / ref["rho"] if done and ref["rho"] > 0 else None
        r["same_picks"] = len(set(r["picks"]) & set(ref["picks"])) if done else None
        r["identical"] = r["picks"] == ref["picks"] if done else None


def lite_ratios(rows: list[dict]) -> list[dict]:
    """Per finished lite_gs row: its wall time over the faster exact method's (pop_gs, lazy_pop) at the same model,
    M, K and cache. Where no exact run finished, their stopped wall time gives a bound (`bound`: the ratio is at
    most this)."""
    index, out = _index(rows), []
    for r in rows:
        if r["selector"] != "lite_gs" or r["status"] != "ok":
            continue
        exact = [e for e in (index.get((r["model"], r["M"], r["K"], s, r["cache"])) for s in EXACT)
                 if e is not None and e.get("wall_s")]
        done = [e for e in exact if e["status"] == "ok"]
        if not exact:
            continue
        best = min(done or exact, key=lambda e: e["wall_s"])
        out.append({"row": r, "exact": best, "ratio": r["wall_s"] / best["wall_s"], "bound": not done})
    return out


def _fmt(value: Any, digits: int = 1) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:,.{digits}f}"
    return f"{value:,}" if isinstance(value, int) else str(value)


def _case(r: dict) -> str:
    return f"{r['model']} {r['image']}, M = {r['M']}, K = {r['K']}, {r['cache']} cache"


def regime_lines(rows: list[dict]) -> list[str]:
    """Where lite_gs's wall time is <= RATIO x the faster exact method's: those configurations, or "none" with the
    closest one and what the two did."""
    ratios = lite_ratios(rows)
    if not ratios:
        return ["No lite_gs row with a finished exact row beside it: no regime can be stated."]
    hits = [q for q in ratios if q["ratio"] <= RATIO]
    if hits:
        lines = [f"lite_gs's wall time is <= {RATIO}x the faster exact method's in {len(hits)} of {len(ratios)} "
                 "configurations:", ""]
        lines += [f"- {_case(q['row'])}, {q['row']['setting']}: {q['ratio']:.2f}x ({q['exact']['setting']} "
                  f"{q['exact']['wall_s']:.1f} s{' when stopped' if q['bound'] else ''}, lite_gs "
                  f"{q['row']['wall_s']:.1f} s)" for q in hits]
        return lines
    q = min(ratios, key=lambda q: q["ratio"])
    r, e = q["row"], q["exact"]
    return [f"In none of the {len(ratios)} configurations is lite_gs's wall time <= {RATIO}x the faster exact "
            f"method's. Closest: {_case(r)}, {r['setting']} at {q['ratio']:.2f}x of {e['setting']} "
            f"({r['wall_s']:.1f} s against {e['wall_s']:.1f} s; {r['evaluated']:,} against {e['evaluated']:,} "
            f"evaluated oracles, {r['fisher_passes']:,} against {e['fisher_passes']:,} Fisher passes, Fisher "
            f"{r['fisher_s']:.1f} against {e['fisher_s']:.1f} s)."]


def _with_greedy(rows: list[dict], setting: str) -> list[tuple[dict, dict]]:
    """(row, pop_gs's row of the same model, M, K and cache) for every finished row of `setting` where pop_gs
    finished too."""
    index = _index(rows)
    pairs = [(r, index.get((r["model"], r["M"], r["K"], GREEDY, r["cache"]))) for r in rows
             if r["setting"] == setting and r["status"] == "ok"]
    return [(r, p) for r, p in pairs if p is not None and p["status"] == "ok"]


def _picks_line(rows: list[dict]) -> str:
    pairs = _with_greedy(rows, "lazy_pop")
    differ = [lazy for lazy, pop in pairs if lazy["picks"] != pop["picks"]]
    verdict = ("**not met**: " + "; ".join(_case(r) for r in differ) if differ else "**met**" if pairs else
               "nothing to compare")
    return (f"- lazy_pop's picks equal pop_gs's in {len(pairs) - len(differ)} of {len(pairs)} configurations where "
            f"both finished: {verdict}.")


def _oracle_lines(rows: list[dict]) -> list[str]:
    """Evaluated oracles over pop_gs's at M = 100 (else the smallest M), K >= 3, per setting (target <= 0.6x)."""
    m = 100 if any(r["M"] == 100 for r in rows) else min(r["M"] for r in rows)
    lines = []
    for setting in dict.fromkeys(r["setting"] for r in rows if r["setting"] != GREEDY):
        fractions = [r["evaluated"] / p["evaluated"] for r, p in _with_greedy(rows, setting)
                     if r["M"] == m and r["K"] >= 3]
        if fractions:
            lines.append(f"- {setting}: evaluated oracles / pop_gs's at M = {m}, K >= 3 at most {max(fractions):.2f}x "
                         f"over {len(fractions)} configurations (target <= 0.6x: "
                         f"**{'met' if max(fractions) <= 0.6 else 'not met'}**).")
    return lines


def _cache_lines(rows: list[dict]) -> list[str]:
    """Fisher recomputations under the quarter-pool budget, priority over LRU eviction (target <= 0.5x)."""
    index = _index(rows)
    pairs = [(r, index.get((r["model"], r["M"], r["K"], r["setting"], "quarter_lru"))) for r in rows
             if r["cache"] == "quarter" and r["selector"] not in NO_HINTS and r["status"] == "ok"]
    pairs = [(r, lru) for r, lru in pairs if lru is not None and lru["status"] == "ok"]
    if not pairs:
        return []
    fractions = [r["recomputes"] / lru["recomputes"] for r, lru in pairs if lru["recomputes"]]
    verdict = (f"at most {max(fractions):.2f}x over {len(fractions)} configurations where LRU recomputed (target "
               f"<= 0.5x: **{'met' if max(fractions) <= 0.5 else 'not met'}**)" if fractions else
               "LRU recomputed nothing")
    return [f"- quarter-pool budget, Fisher recomputations priority / LRU: {verdict}; "
            f"{sum(r['recomputes'] for r, _ in pairs):,} against {sum(lru['recomputes'] for _, lru in pairs):,} "
            "in all."]


def _largest_lines(rows: list[dict], timeout_s: float) -> list[str]:
    """Every setting and cache of the largest case (the largest M, then the most Gaussians; K = 6 or the largest K):
    its status, wall time and where it went."""
    largest = max(rows, key=lambda r: (r["M"], r.get("gaussians") or 0))
    k = 6 if any(r["K"] == 6 for r in rows) else max(r["K"] for r in rows)
    lines = [f"- the largest case, {largest['model']} {largest['image']}, M = {largest['M']}, K = {k} (limit "
             f"{timeout_s:.0f} s per configuration):"]
    for r in rows:
        if (r["model"], r["M"], r["K"]) != (largest["model"], largest["M"], k):
            continue
        cost = (f", {r['wall_s']:.0f} s wall (Fisher passes {r['fisher_s']:.0f} s, the rest "
                f"{r['wall_s'] - r['fisher_s']:.0f} s), {r['fisher_passes']:,} Fisher passes, {r['evaluated']:,} "
                f"evaluated, peak {r['peak_rss_mb']:,.0f} MB" if r.get("wall_s") is not None else "")
        note = f" ({r['note']})" if r["note"] else ""
        lines.append(f"  - {r['setting']}, {r['cache']}: {r['status']}{cost}{note}")
    return lines


def target_lines(rows: list[dict], timeout_s: float) -> list[str]:
    """The targets of issue 42, each with what the rows say."""
    return [_picks_line(rows), *_oracle_lines(rows), *_cache_lines(rows), *_largest_lines(rows, timeout_s)]


ROW_COLUMNS = (("model", "model"), ("image", "image"), ("gaussians", "N"), ("M", "M"), ("K", "K"),
               ("setting", "selector"), ("cache", "cache"), ("evaluated", "evaluated"),
               ("conservative", "conservative"), ("fisher_passes", "Fisher passes"), ("recomputes", "recomputed"),
               ("fisher_s", "Fisher s"), ("wall_s", "wall s"), ("peak_rss_mb", "peak RSS MB"),
               ("rho_ratio", "ρ/ρ greedy"), ("same_picks", "picks as greedy"), ("status", "status"))


def markdown(doc: dict) -> str:
    """The report of a study's JSON: set-up, targets, regime, the lite_gs / exact ratio table and every row."""
    rows, env = doc["rows"], doc["environment"]
    finalise(rows)
    out = [f"# Selection cost study ({doc['preset']} preset)", "",
           f"{env['started']}, code {env['code']}, {env['machine']}, {env['cpu']} ({env['cpus']} CPUs), "
           f"{rows[0]['threads'] if rows else '?'} threads; one process per configuration, one after the other; "
           f"limit {doc['timeout_s']:.0f} s each. Command: `{doc['command']}`", "", "## Targets", ""]
    out += target_lines(rows, doc["timeout_s"]) + ["", f"## Where lite_gs takes <= {RATIO}x the faster exact method",
                                                   ""]
    out += regime_lines(rows) + ["", "## lite_gs wall time / the faster exact method's (pop_gs, lazy_pop)", ""]
    ks = sorted({r["K"] for r in rows})
    out += ["| model | M | cache | setting | " + " | ".join(f"K = {k}" for k in ks) + " |",
            "|---|---|---|---|" + "---|" * len(ks)]
    ratios = {(q["row"]["model"], q["row"]["M"], q["row"]["cache"], q["row"]["setting"], q["row"]["K"]):
              f"{'≤ ' if q['bound'] else ''}{q['ratio']:.2f}" for q in lite_ratios(rows)}
    for group in dict.fromkeys(key[:4] for key in ratios):
        out.append("| " + " | ".join(map(str, group)) + " | " +
                   " | ".join(ratios.get((*group, k), "–") for k in ks) + " |")
    out += ["", "## Every configuration", "", "| " + " | ".join(h for _, h in ROW_COLUMNS) + " |",
            "|" + "---|" * len(ROW_COLUMNS)]
    for r in rows:
        cells = [_fmt(r.get(key), 2 if key == "rho_ratio" else 1) for key, _ in ROW_COLUMNS]
        if r.get("same_picks") is not None:
            cells[-2] = f"{r['same_picks']}/{r['K']}"
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


CACHE_STYLES = (("unlimited", "-o"), ("quarter", "--s"), ("quarter_lru", ":^"))  # plot line styles per cache


def _ratio_lines(ratios: list[dict], model: str, over_m: bool) -> list[tuple[list, str, str]]:
    """The lite_gs ratio curves of one model as (points, style, label): over M, one per (setting, K) with the
    unlimited cache; over K, one per (setting, cache)."""
    mine = [q["row"] | {"ratio": q["ratio"]} for q in ratios if q["row"]["model"] == model]
    if over_m:
        mine = [r for r in mine if r["cache"] == "unlimited"]
    x_key, group_key = ("M", "K") if over_m else ("K", "cache")
    lines = []
    for setting, group in dict.fromkeys((r["setting"], r[group_key]) for r in mine):
        points = sorted((r[x_key], r["ratio"]) for r in mine if (r["setting"], r[group_key]) == (setting, group))
        style = "-o" if over_m else dict(CACHE_STYLES)[group]
        lines.append((points, style, f"{setting}, K = {group}" if over_m else f"{setting}, {group}"))
    return lines


def plot(rows: list[dict], path: Path) -> None:
    """Per model: wall time per setting and cache, and lite_gs's wall time over the faster exact method's, against M
    (at K = 6, or the largest K) when the rows span several pools, else against K (one pool: a K sweep)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = list(dict.fromkeys(r["model"] for r in rows))
    over_m = len({r["M"] for r in rows}) > 1
    x_key, fixed_key = ("M", "K") if over_m else ("K", "M")
    fixed = (6 if any(r["K"] == 6 for r in rows) else max(r["K"] for r in rows)) if over_m else rows[0]["M"]
    fig, axes = plt.subplots(len(models), 2, figsize=(12, 4.2 * len(models)), squeeze=False)
    ratios = lite_ratios(rows)
    settings = list(dict.fromkeys(r["setting"] for r in rows))
    xlabel = "M candidates" if over_m else "K views per step"
    for (left, right), model in zip(axes, models):
        for colour, setting in enumerate(settings):
            for cache, style in CACHE_STYLES:
                points = sorted((r[x_key], r["wall_s"]) for r in rows if (r["model"], r["setting"], r["cache"],
                                                                            r[fixed_key], r["status"]) ==
                                (model, setting, cache, fixed, "ok"))
                if points:
                    left.plot(*zip(*points), style, color=f"C{colour}", label=f"{setting}, {cache}")
        left.set(xscale="log", yscale="log", xlabel=xlabel, ylabel="wall s (Fisher + selection)",
                 title=f"{model}: {fixed_key} = {fixed} (solid: unlimited cache, dashed: quarter, dotted: quarter LRU)")
        if left.lines:
            left.legend(fontsize=7)
        for points, style, label_text in _ratio_lines(ratios, model, over_m):
            right.plot(*zip(*points), style, label=label_text)
        right.axhline(RATIO, color="k", linestyle=":", label=f"{RATIO}x")
        right.set(xscale="log", xlabel=xlabel, ylabel="lite_gs wall / faster exact wall",
                  title=f"{model}: " + ("unlimited cache" if over_m else f"M = {fixed}, every cache"))
        right.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(json_path: Path, out_dir: Path | None = None) -> tuple[Path, Path]:
    """The markdown report and the plot of a study's JSON, beside it or in `out_dir`; returns their paths."""
    doc = json.loads(json_path.read_text())
    if not doc.get("rows"):
        raise UserError(f"{json_path}: no rows to report")
    stem = (out_dir or json_path.parent) / json_path.stem
    stem.parent.mkdir(parents=True, exist_ok=True)
    text = markdown(doc)
    md, png = stem.with_suffix(".md"), stem.with_suffix(".png")
    atomic_write(md, text)
    plot(doc["rows"], png)
    return md, png


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--preset", choices=tuple(PRESETS), default="quick")
    parser.add_argument("--model", nargs="+", help="train.py model directories")
    parser.add_argument("--garden", nargs="+", help="garden SfM initialisation at these WxH sizes (648x420 ...)")
    parser.add_argument("--ms", type=int, nargs="+", help="pool sizes M (default: the preset's)")
    parser.add_argument("--ks", type=int, nargs="+", help="K values (default: the preset's)")
    parser.add_argument("--selectors", nargs="+", help="only these settings, NAME or NAME:EPS (default: the "
                                                        "preset's), e.g. lazy_pop lite_gs:0.1")
    parser.add_argument("--caches", nargs="+", choices=tuple(CACHES), help="only these caches (default: all three)")
    parser.add_argument("--candidates", choices=("hemisphere", "orbit"), default="hemisphere",
                        help="generated poses around the prior's views (recommender.candidates)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0, help="lite_gs / ssg subsets (run_selection's seeding)")
    parser.add_argument("--timeout_s", type=float, default=None, help="per configuration (default: the preset's)")
    parser.add_argument("--reserve_mb", type=int, default=1024, help="stop a configuration with less memory left")
    parser.add_argument("--json", type=Path, default=None, help="results (default benchmarks/results/...)")
    parser.add_argument("--resume", action="store_true", help="continue the --json of an earlier run: keep its "
                                                               "rows, run only the configurations it lacks")
    parser.add_argument("--report", type=Path, default=None, help="only rebuild the report of a results JSON")
    parser.add_argument("--out_dir", type=Path, default=None, help="where --report writes (default: beside JSON)")
    parser.add_argument("--run_config", default=None, help=argparse.SUPPRESS)  # a child: one configuration
    args = parser.parse_args()
    if args.run_config:
        write_json(args.json, run_config(json.loads(args.run_config)))
        return
    if args.report:
        if not args.report.is_file():
            raise UserError(f"--report {args.report}: no such file")
        path = args.report
    else:
        path = study(args)
    md, png = write_report(path, args.out_dir if args.report else None)
    print(md.read_text())
    print(f"wrote {md} and {png}")


if __name__ == "__main__":
    run_cli(main)
