"""Selection cost: Fisher blocks vs a training step, one oracle, and the oracle selectors over K and their options.

    python benchmarks/bench_selection.py                      # the quickstart model, every oracle selector
    python benchmarks/bench_selection.py --model output/quickstart --mode cached --compare_dense
    python benchmarks/bench_selection.py --model output/quickstart --mode streaming --ks 3 --methods NAME [NAME ...]
    python benchmarks/bench_selection.py --model output/quickstart --memory_table --ks 3 --methods NAME
    python benchmarks/bench_selection.py --report benchmarks/results/selection_streaming_<date>.json

Uses a trained model directory (default: the quickstart's) and its dataset; the seed views are chosen by
farthest-point sampling (2 of the pool, so M = 98 candidates on the built-in scene). Modes:
  cached     every candidate's blocks are computed once (timed apart) and a gain is a batched log-det update;
  streaming  nothing is kept: every oracle recomputes that view's blocks (the memory-lean mode).
Every selector that calls the oracle runs (or those of --methods), once per combination of the --sweep values of the
options it declares (default eps = 0.1 0.3 0.6); ratios are taken to the row with the most evaluated oracles at the
same K (exhaustive greedy when it runs). Peak resident memory of the process is printed at the end.
Each selector gets the oracle its `oracle_kind` declares. The log-det, COVER-gated log-det and diagonal kinds share
this script's view factors (sparse, `active.logdet`) or diagonals, so the cache build is timed apart; every other kind
(cover's geometric score, render_variance, probe_pop's probes, the opacity weighting, FisherRF's reference diagonal)
gets its own oracle from `active.fisher.build_oracle`, marked `own` in the oracle column, and its select time
includes its Fisher passes. `--compare_dense` also runs every log-det selector on the dense twin (`DenseBlockInformation`
over [N, P, P] blocks: the implementation before the sparse factors; its blocks are the same float32 factors
scattered to dense on every call, a few % of a dense gain) and prints both times and whether the picks agree. `benchmarks/selection_cost.py` times old vs new per candidate (Fisher pass, gain, commit, end to end).
`--memory_table` runs the first of --methods (first K of --ks) in both modes, each in its own process, for a growing number of candidates (--pool_sizes, the last = all) and prints
the peak resident memory of each: cached grows with M, streaming stays flat.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import json
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import torch

from active import SelectionContext, build_selector, list_selectors, selector_options
from active.fisher import (FACTOR_STORAGE, DiagonalGainOracle, build_oracle, fisher_view_blocks,
                           fisher_view_diagonals, fisher_view_factors, parameter_columns)
from active.cover_oracle import CoverageOracle
from active.gated_oracle import CoverGatedOracle
from active.logdet import BlockGainOracle, BlockInformation, DenseBlockInformation
from active.schedule import farthest_point_views
from arguments import FisherSettings
from gaussian_renderer import render
from gaussian_renderer.fisher_partials import RAW_PARAMETER_GROUPS
from scene.trained import load_trained
from utils.losses import photometric_loss
from utils.errors import UserError, run_cli
from utils.io import read_json


RESULTS_DIR = Path(__file__).parent / "results"
SHARED_ORACLE_KINDS = ("logdet", "logdet_cover", "diagonal")  # served by this script's cached factors / diagonals


def median_time(fn, items) -> float:
    times = []
    for item in items:
        t0 = time.perf_counter()
        fn(item)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def fisher_split(gaussians: GaussianModel, cameras: list, bg: torch.Tensor, settings: RasterSettings) -> None:
    """Print the median time of the two parts of a view's Fisher blocks: the attribute Gram and the projection
    Jacobian."""
    from gaussian_renderer import attribute_gram, project_gaussians, projection_jacobian
    from gaussian_renderer.sh import sh_to_colors
    params = {k: v.detach() for k, v in gaussians.params.items()}

    @torch.no_grad()
    def gram(cam):
        proj = project_gaussians(gaussians.means, gaussians.unit_quats, gaussians.scales, cam.viewmat,
                                 cam.intrinsics, cam.width, cam.height)
        colors = sh_to_colors(gaussians.sh_coeffs, gaussians.means, cam.camera_center, gaussians.active_sh_degree)
        attribute_gram(proj.means2d, proj.conics, gaussians.opacities, colors, proj.depths, proj.radii, cam.width,
                       cam.height, bg, settings)

    def jacobian(backend):
        return lambda cam: projection_jacobian(params["means"], params["quats"], params["log_scales"],
                                               params["logit_opacities"], gaussians.sh_coeffs.detach(),
                                               gaussians.active_sh_degree, cam.viewmat, cam.intrinsics, cam.width,
                                               cam.height, backend=backend)
    print(f"Fisher blocks split ({gaussians.num_gaussians} Gaussians): attribute_gram "
          f"{1e3 * median_time(gram, cameras):.1f} ms | projection_jacobian torch "
          f"{1e3 * median_time(jacobian('torch'), cameras):.1f} ms, compiled "
          f"{1e3 * median_time(jacobian('compiled'), cameras):.1f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", default="output/quickstart", help="trained model directory")
    parser.add_argument("--mode", choices=("cached", "streaming"), default="cached")
    parser.add_argument("--ks", type=int, nargs="+", default=[3, 4, 6])
    parser.add_argument("--sweep", nargs="+", default=["eps=0.1,0.3,0.6"],
                        help="NAME=V1,V2,...: values of a selector option to run (for the selectors that declare it)")
    parser.add_argument("--num_init_views", type=int, default=2)
    oracle_selectors = [name for name in list_selectors()  # auto delegates to cover_pool or lite_gs, both listed
                        if (s := build_selector(name)).uses_oracle and not s.delegates]
    parser.add_argument("--methods", nargs="+", choices=oracle_selectors, default=oracle_selectors)
    parser.add_argument("--num_candidates", type=int, default=0,
                        help="use only the first N candidates (0 = all); for peak-memory scaling")
    parser.add_argument("--memory_table", action="store_true",
                        help="peak memory of the first of --methods, cached vs streaming, over --pool_sizes (one process each)")
    parser.add_argument("--pool_sizes", type=int, nargs="+", default=[24, 48, 0], help="0 = all candidates")
    parser.add_argument("--json", type=Path, default=None, help="where to write the results (default: results/)")
    parser.add_argument("--report", type=Path, default=None, help="only print the table of a results JSON")
    parser.add_argument("--cost_only", action="store_true",
                        help="stop after the step / Fisher timing, with the Gram vs projection-Jacobian split")
    parser.add_argument("--raster_backend", choices=("auto", "compiled", "torch"), default=None,
                        help="rasterizer backend (default: the model's cfg_args)")
    parser.add_argument("--compare_dense", action="store_true",
                        help="also run the log-det selectors on the dense twin (the pre-sparse implementation)")
    args = parser.parse_args()
    if args.report:
        report(args.report)
        return
    if args.memory_table:
        memory_table(args)
        return

    model_path = Path(args.model)
    if not model_path.is_dir():
        raise UserError(f"no model directory {model_path}: run scripts/quickstart.sh first, or pass --model DIR")
    trained = load_trained(model_path, device="cpu")
    gaussians, cams, bg, settings = trained.gaussians, trained.scene.train_cameras, trained.background, trained.settings
    if args.raster_backend:
        settings = replace(settings, backend=args.raster_backend)
    seeds = farthest_point_views(torch.stack([c.camera_center for c in cams]), args.num_init_views)
    candidates = [v for v in range(len(cams)) if v not in seeds]
    if args.num_candidates > 0:
        candidates = candidates[:args.num_candidates]

    def train_step(v):
        out = render(cams[v], gaussians, bg, settings)
        loss = photometric_loss(out.image, cams[v].image)
        loss.backward()

    def blocks(v):
        return fisher_view_blocks(gaussians, cams[v], bg, settings)

    def factors(v):
        return fisher_view_factors(gaussians, cams[v], bg, settings, dtype=FACTOR_STORAGE)

    def diagonals(v):
        return fisher_view_diagonals(gaussians, cams[v], bg, settings)

    sample = candidates[:: max(1, len(candidates) // 6)][:6]
    train_step(sample[0])
    t_step = median_time(train_step, sample)
    t_fisher = median_time(blocks, sample)
    t_factors = median_time(factors, sample)
    prior = sum(blocks(v) for v in seeds)
    info = BlockInformation(prior)
    some_factors = factors(candidates[0])
    t_gain = median_time(lambda _: info.gain(some_factors), range(5))
    dense_info, some_blocks = DenseBlockInformation(prior), some_factors.dense()
    t_dense_gain = median_time(lambda _: dense_info.gain(some_blocks), range(3))
    print(f"model {model_path}: {gaussians.num_gaussians} Gaussians, {cams[0].width}x{cams[0].height}, "
          f"M = {len(candidates)} candidates, torch {torch.__version__}, {torch.get_num_threads()} threads")
    print(f"one training step (fwd+bwd+loss): {1e3 * t_step:.1f} ms | one view's Fisher blocks: "
          f"{1e3 * t_fisher:.1f} ms ({t_fisher / t_step:.2f}x a step), as visible factors {1e3 * t_factors:.1f} ms | "
          f"one gain on cached factors: {1e3 * t_gain:.2f} ms (dense twin {1e3 * t_dense_gain:.1f} ms, "
          f"{t_dense_gain / t_gain:.1f}x), {some_factors.indices.numel()} of {gaussians.num_gaussians} Gaussians seen")
    if args.cost_only:
        fisher_split(gaussians, [cams[v] for v in sample], bg, settings)
        return

    cache, t_cache, cache_mb = {}, 0.0, 0.0
    diag_cache = {}
    configs = [(method, options) for method in args.methods for options in option_grid(method, args.sweep)]
    kinds = {build_selector(method, **options).oracle_kind for method, options in configs}
    if args.mode == "cached":
        t0 = time.perf_counter()
        if kinds & {"logdet", "logdet_cover"}:
            cache = {v: factors(v) for v in candidates}
        if "diagonal" in kinds:
            diag_cache = {v: diagonals(v) for v in candidates}
        t_cache = time.perf_counter() - t0
        cache_mb = sum(f.nbytes for f in cache.values()) / 2**20
        print(f"cache: {len(candidates)} views, {cache_mb:.0f} MB of float32 visible factors "
              f"(dense float64 blocks would be {len(candidates) * prior.numel() * 8 / 2**20:.0f} MB), "
              f"built in {t_cache:.1f} s")
    prior_diag = sum(diagonals(v) for v in seeds) if "diagonal" in kinds else None
    columns = parameter_columns(gaussians, RAW_PARAMETER_GROUPS)

    rows = []
    for k in args.ks:
        for method, options in configs:
            kind = build_selector(method, **options).oracle_kind
            if kind not in SHARED_ORACLE_KINDS:
                variants = ["own"]
            else:
                variants = ["sparse", "dense"] if args.compare_dense and kind == "logdet" else ["sparse"]
            for variant in variants:
                computed = set()

                def provider(v, variant=variant, kind=kind):
                    computed.add(v)
                    if kind == "diagonal":
                        return diag_cache[v] if diag_cache else diagonals(v)
                    if variant == "dense":
                        return cache[v].dense() if cache else factors(v).dense()  # scattered per call
                    return cache[v] if cache else factors(v)

                if variant == "own":
                    oracle = build_oracle(kind, gaussians, cams, list(seeds), bg, settings,
                                          fisher=FisherSettings(fisher_mode=args.mode))
                elif kind == "diagonal":
                    oracle = DiagonalGainOracle(prior_diag, provider, columns)
                elif variant == "dense":
                    oracle = DenseGainOracle(DenseBlockInformation(prior), provider)
                else:
                    oracle = BlockGainOracle(BlockInformation(prior), provider)
                if kind == "logdet_cover":  # cover_pop: the log-det oracle gated by COVER's score
                    oracle = CoverGatedOracle(oracle, CoverageOracle.for_model(gaussians, cams, list(seeds)))
                ctx = SelectionContext(candidates, oracle, torch.Generator().manual_seed(0), 0,
                                       camera_centers=torch.stack([c.camera_center for c in cams]),
                                       train_ids=tuple(seeds))
                t0 = time.perf_counter()
                sel = build_selector(method, **options).select(ctx, k)
                rows.append({"K": k, "method": method, "options": options, "oracle": variant,
                             "conservative": sel.conservative, "evaluated": oracle.evaluated,
                             "views_computed": oracle.views_computed if variant == "own" else len(computed),
                             "select_s": time.perf_counter() - t0,
                             "ids": sel.ids, "gains": sel.gains})
    print(f"\n{args.mode} mode{' (cache build excluded, see above)' if cache else ''}")
    print_rows(rows)
    if args.compare_dense:
        compare_dense(rows)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\npeak resident memory of this process: {peak_mb:.0f} MB")
    out = args.json or RESULTS_DIR / f"selection_{args.mode}_{time.strftime('%Y%m%d_%H%M%S')}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"machine": platform.platform(), "torch": torch.__version__, "mode": args.mode,
                               "gaussians": gaussians.num_gaussians, "candidates": len(candidates),
                               "cache_mb": cache_mb, "train_step_s": t_step,
                               "fisher_view_s": t_fisher, "fisher_factors_s": t_factors, "gain_s": t_gain,
                               "dense_gain_s": t_dense_gain, "cache_build_s": t_cache,
                               "peak_rss_mb": peak_mb, "rows": rows}, indent=2))
    print(f"wrote {out}")


class DenseGainOracle(BlockGainOracle):
    """The oracle before the sparse factors, over the dense twin: every gain whitens all N blocks [N, P, P]; a commit
    reuses the whitened blocks of the best gain since the last commit."""

    def _score(self, view_id: int) -> tuple[float, torch.Tensor]:
        return self.information.gain_and_whitened(self.view_blocks(view_id))

    def _add_scored(self, reusable: torch.Tensor) -> None:
        self.information.add_whitened(reusable)


def compare_dense(rows: list[dict]) -> None:
    """Per log-det row: selection seconds sparse vs dense twin, their ratio, and whether the picks agree (with the
    relative gap of the first differing pick's gains when they do not)."""
    print(f"\n{'K':>2} {'method':8} {'options':>9} {'dense s':>8} {'sparse s':>8} {'ratio':>6}  picks")
    for dense in (r for r in rows if r["oracle"] == "dense"):
        sparse = next(r for r in rows if r["oracle"] == "sparse" and r["K"] == dense["K"]
                      and r["method"] == dense["method"] and r["options"] == dense["options"])
        same = sparse["ids"] == dense["ids"]
        note = "same" if same else f"differ: sparse {sparse['ids']} vs dense {dense['ids']}"
        gap = max(abs(a - b) / max(abs(b), 1e-300) for a, b in zip(sparse["gains"], dense["gains"])) if same else None
        options = " ".join(f"{n}={v:g}" for n, v in dense["options"].items())
        print(f"{dense['K']:2d} {dense['method']:8} {options:>9} {dense['select_s']:8.2f} {sparse['select_s']:8.2f} "
              f"{dense['select_s'] / sparse['select_s']:6.2f}  {note}"
              + (f" (max relative gain difference {gap:.1e})" if gap is not None else ""))


def option_grid(method: str, sweep: list[str]) -> list[dict]:
    """Every combination of the --sweep values of the options `method` declares ([{}] when it declares none)."""
    grid: list[dict] = [{}]
    for item in sweep:
        name, _, values = item.partition("=")
        if name in selector_options(method):
            grid = [{**g, name: float(v)} for g in grid for v in values.split(",")]
    return grid


def print_rows(rows: list[dict]) -> None:
    """The selection table: counts, wall time, both ratios to the row with the most evaluated oracles at the same K
    (exhaustive greedy when it ran) and the time per evaluated oracle; then the time per evaluated oracle summed
    over all rows of each method (per-view Fisher cost varies, so single cells scatter around the oracle ratio;
    the totals show whether overhead eats the savings)."""
    print(f"{'K':>2} {'method':8} {'oracle':6} {'options':>9} {'conserv.':>8} {'evaluated':>9} {'views':>5} "
          f"{'select s':>9} "
          f"{'time/max':>8} {'evals/max':>9} {'s/eval':>7}")
    for r in rows:
        ref = max((p for p in rows if p["K"] == r["K"] and p.get("oracle") == r.get("oracle")),
                  key=lambda p: p["evaluated"])
        ratios = f"{r['select_s'] / ref['select_s']:8.3f} {r['evaluated'] / max(1, ref['evaluated']):9.3f}"
        options = " ".join(f"{n}={v:g}" for n, v in r.get("options", {}).items())
        print(f"{r['K']:2d} {r['method']:8} {r.get('oracle', 'dense'):6} {options:>9} {r['conservative']:8d} "
              f"{r['evaluated']:9d} {r['views_computed']:5d} {r['select_s']:9.2f} {ratios} "
              f"{r['select_s'] / max(1, r['evaluated']):7.3f}")
    for method, oracle in dict.fromkeys((r["method"], r.get("oracle", "dense")) for r in rows):
        mine = [r for r in rows if r["method"] == method and r.get("oracle", "dense") == oracle]
        seconds, evals = sum(r["select_s"] for r in mine), sum(r["evaluated"] for r in mine)
        print(f"{method} ({oracle}): {evals} evaluated oracles in {seconds:.1f} s over {len(mine)} rows = "
              f"{seconds / max(1, evals):.4f} s per evaluated oracle")


def report(path: Path) -> None:
    """Print the table of a results JSON written earlier by this script."""
    res = read_json(path, fix="rerun the benchmark that wrote it")
    print(f"{path}: {res['mode']} mode, {res['gaussians']} Gaussians, {res.get('candidates', '?')} candidates, "
          f"one step {1e3 * res['train_step_s']:.1f} ms, one view's Fisher blocks {1e3 * res['fisher_view_s']:.1f} ms "
          f"({res['fisher_view_s'] / res['train_step_s']:.2f}x), one gain {1e3 * res['gain_s']:.1f} ms, "
          f"peak RSS {res['peak_rss_mb']:.0f} MB")
    print_rows(res["rows"])


def memory_table(args: argparse.Namespace) -> None:
    """Peak RSS of the first of --methods in cached and streaming mode over growing pools, one child process per cell."""
    k, method = args.ks[0], args.methods[0]
    RESULTS_DIR.mkdir(exist_ok=True)
    stamp = time.strftime("%Y%m%d_%H%M%S")
    print(f"{method}, K = {k}: peak resident memory of one process per cell")
    print(f"{'M':>4} {'mode':9} {'cache MB':>8} {'peak RSS MB':>11} {'select s':>9}")
    table = []
    for pool in args.pool_sizes:
        for mode in ("cached", "streaming"):
            out = RESULTS_DIR / f"memory_{stamp}_{mode}_{pool}.json"
            cmd = [sys.executable, __file__, "--model", str(args.model), "--mode", mode, "--ks", str(k),
                   "--methods", method, "--num_init_views", str(args.num_init_views),
                   "--num_candidates", str(pool), "--json", str(out)]
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
            res = read_json(out)
            row = {"M": res["candidates"], "mode": mode, "cache_mb": res["cache_mb"], "peak_rss_mb": res["peak_rss_mb"],
                   "select_s": res["rows"][0]["select_s"]}
            table.append(row)
            print(f"{row['M']:4d} {mode:9} {row['cache_mb']:8.0f} {row['peak_rss_mb']:11.0f} {row['select_s']:9.1f}",
                  flush=True)
    summary = RESULTS_DIR / f"memory_{stamp}.json"
    summary.write_text(json.dumps({"machine": platform.platform(), "model": str(args.model), "K": k,
                                   "method": method, "rows": table},
                                  indent=2))
    print(f"wrote {summary}")


if __name__ == "__main__":
    run_cli(main)
