"""Approximation quality against brute force: how close each selector's K views come to the best K-subset.

    python benchmarks/bench_approximation.py -m output/i24/fisherrf_exact_seed0 --out benchmarks/results/approx.json

On a trained model (its recorded final training views are the prior), M candidates (--candidates, evenly spaced ids of
the rest of the pool) get their Fisher blocks once (the run's --fisher_params). For each relative ridge delta_rel
(--delta_rel, the oracle's A_0 = H_0 + (delta_rel max diag + delta_abs) I per Gaussian) and each K (--ks), every
K-subset S is scored by the same oracle the selectors use, rho(S) = logdet(A_0 + sum_S H_v) - logdet(A_0), and
OPT = max over S. Each selector (pop_gs, lite_gs at each --eps, ssg, fisherrf, coverage, random) then picks K views;
its rho(S) is looked up in that table. Reported per selector, K and delta_rel, averaged over --seeds seeds for the
stochastic ones (lite_gs, ssg, random; one run for the others):

    ratio       rho(S) / rho(OPT)
    normalised  (rho(S) - mean_random) / (rho(OPT) - mean_random), mean_random = the mean of rho over all K-subsets
                (the exact expectation of a uniformly random K-subset: 0 = no better than chance, 1 = optimal)
    oracles     gains the selector evaluated (0 for coverage and random; fisherrf: diagonal evaluations)

plus the wall time of each part. The number of subsets C(M, K) is capped (--max_subsets).
"""
from __future__ import annotations

import argparse
import itertools
import json
import statistics
import time
from pathlib import Path

import torch
from tqdm import tqdm

from active import SelectionContext, build_selector
from active.fisher import FISHER_PARAM_GROUPS, DiagonalGainOracle, fisher_view_blocks, fisher_view_diagonals, \
    parameter_columns
from active.brute_force import check_inputs, subset_rhos
from active.logdet import BlockGainOracle, BlockInformation
from arguments import ActiveConfig, FisherSettings, config_from_dict
from gaussian_renderer.fisher_partials import RAW_PARAMETER_GROUPS
from gaussian_renderer.projection import camera_centers, look_at_point
from scene.trained import load_trained, recorded_train_views
from utils.errors import UserError, run_cli

STOCHASTIC = ("lite_gs", "ssg", "random")


def selector_runs(eps: list[float]) -> list[tuple[str, str, dict]]:
    """(label, selector name, options) of every selector setting benchmarked."""
    runs = [("pop_gs", "pop_gs", {})]
    runs += [(f"lite_gs eps={e:g}", "lite_gs", {"eps": e}) for e in eps]
    runs += [("ssg", "ssg", {"eps": eps[0]}), ("fisherrf", "fisherrf", {}), ("coverage", "coverage", {}),
             ("random", "random", {})]
    return runs


def run(model: Path, candidates_count: int, ks: list[int], deltas: list[float], seeds: int, eps: list[float],
        max_subsets: int, quiet: bool = False) -> dict:
    """The whole benchmark; returns the JSON-ready report."""
    check_inputs(candidates_count, ks, deltas, max_subsets)
    t_start = time.perf_counter()
    trained = load_trained(model)
    saved = trained.record.get("active", {})
    active = config_from_dict(ActiveConfig, saved) if saved else ActiveConfig()
    fisher = FisherSettings.from_active(active)
    cameras = trained.scene.train_cameras
    train = recorded_train_views(trained.path, trained.iteration, len(cameras), active.method)
    pool = [v for v in range(len(cameras)) if v not in train]
    if candidates_count > len(pool):
        raise UserError(f"--candidates {candidates_count}: the model leaves only {len(pool)} views outside training")
    candidates = [pool[round(i * (len(pool) - 1) / max(candidates_count - 1, 1))] for i in range(candidates_count)]
    groups = FISHER_PARAM_GROUPS[fisher.fisher_params]
    g, bg, settings = trained.gaussians, trained.background, trained.settings
    t0 = time.perf_counter()
    prior = sum(fisher_view_blocks(g, cameras[v], bg, settings, fisher.sigma, groups) for v in train)
    blocks = {v: fisher_view_blocks(g, cameras[v], bg, settings, fisher.sigma, groups)
              for v in tqdm(candidates, desc="Fisher blocks", disable=quiet)}
    diag_prior = sum(fisher_view_diagonals(g, cameras[v], bg, settings, fisher.sigma) for v in train)
    diags = {v: fisher_view_diagonals(g, cameras[v], bg, settings, fisher.sigma) for v in candidates}
    fisher_seconds = time.perf_counter() - t0
    viewmats = torch.stack([c.viewmat.cpu() for c in cameras])  # [V, 4, 4]
    centers, scene_center = camera_centers(viewmats), look_at_point(viewmats)
    rows, brute_seconds, select_seconds = [], 0.0, 0.0
    for delta, k in tqdm(list(itertools.product(deltas, ks)), desc="delta_rel x K", disable=quiet):
        information = BlockInformation(prior, delta_rel=delta, delta_abs=fisher.delta_abs)
        t0 = time.perf_counter()
        rhos = subset_rhos(information, blocks, candidates, k)
        brute_seconds += time.perf_counter() - t0
        best_set = max(rhos, key=rhos.get)
        opt, mean_random = rhos[best_set], statistics.fmean(rhos.values())
        for label, name, options in selector_runs(eps):
            t0 = time.perf_counter()
            values, oracles = [], []
            for seed in range(seeds if name in STOCHASTIC else 1):
                selector = build_selector(name, **options)
                if selector.oracle_kind == "logdet":
                    oracle = BlockGainOracle(BlockInformation(prior, delta_rel=delta, delta_abs=fisher.delta_abs),
                                             blocks.__getitem__)
                else:
                    oracle = DiagonalGainOracle(diag_prior, diags.__getitem__,
                                                parameter_columns(g, RAW_PARAMETER_GROUPS))
                ctx = SelectionContext(list(candidates), oracle, torch.Generator().manual_seed(seed), 0,
                                       tuple(train), centers, scene_center)
                ids = selector.select(ctx, k).ids
                values.append(rhos[tuple(sorted(ids, key=candidates.index))])
                oracles.append(oracle.evaluated)
            select_seconds += time.perf_counter() - t0
            mean_rho = statistics.fmean(values)
            rows.append({"delta_rel": delta, "K": k, "selector": label, "runs": len(values),
                         "ratio": mean_rho / opt, "ratio_min": min(values) / opt,
                         "normalised": (mean_rho - mean_random) / (opt - mean_random),
                         "found_opt": sum(v == opt for v in values) / len(values),
                         "oracles": statistics.fmean(oracles)})
        rows.append({"delta_rel": delta, "K": k, "selector": "OPT", "runs": len(rhos), "ratio": 1.0,
                     "ratio_min": 1.0, "normalised": 1.0, "found_opt": 1.0, "oracles": len(rhos),
                     "opt_set": list(best_set), "rho_opt": opt, "rho_mean_random": mean_random})
    return {"model": str(model), "iteration": trained.iteration, "num_gaussians": g.num_gaussians,
            "fisher_params": fisher.fisher_params, "train_views": train, "candidates": candidates, "ks": ks,
            "delta_rel": deltas, "seeds": seeds, "rows": rows,
            "seconds": {"total": time.perf_counter() - t_start, "fisher": fisher_seconds, "brute_force": brute_seconds,
                        "selectors": select_seconds},
            "threads": torch.get_num_threads()}


def format_report(report: dict) -> str:
    """A markdown table: one row per delta_rel, K and selector."""
    lines = [f"model {report['model']} (iteration {report['iteration']}, {report['num_gaussians']} Gaussians, "
             f"--fisher_params {report['fisher_params']}), M = {len(report['candidates'])}, "
             f"{report['seeds']} seeds for {', '.join(STOCHASTIC)}",
             "", "| delta_rel | K | selector | ratio | min ratio | normalised | found OPT | oracles |",
             "|---|---|---|---|---|---|---|---|"]
    for r in report["rows"]:
        lines.append(f"| {r['delta_rel']:g} | {r['K']} | {r['selector']} | {r['ratio']:.4f} | {r['ratio_min']:.4f} | "
                     f"{r['normalised']:.3f} | {r['found_opt']:.2f} | {r['oracles']:.1f} |")
    s = report["seconds"]
    lines += ["", f"wall time: {s['total']:.1f} s (Fisher blocks {s['fisher']:.1f} s, brute force "
                  f"{s['brute_force']:.1f} s, selectors {s['selectors']:.1f} s), {report['threads']} thread(s)"]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-m", "--model", type=Path, required=True, help="trained model directory (train.py)")
    parser.add_argument("--candidates", type=int, default=14, help="M, candidate views brute-forced (default 14)")
    parser.add_argument("--ks", type=int, nargs="+", default=[2, 3, 4], help="K values (default 2 3 4)")
    parser.add_argument("--delta_rel", type=float, nargs="+", default=[1e-3, 1e-6, 1e-9],
                        help="relative ridges (default 1e-3 1e-6 1e-9)")
    parser.add_argument("--eps", type=float, nargs="+", default=[0.1, 0.3, 0.6], help="lite_gs eps (ssg: the first)")
    parser.add_argument("--seeds", type=int, default=20, help="seeds of the stochastic selectors (default 20)")
    parser.add_argument("--max_subsets", type=int, default=5000, help="cap on C(M, K) (default 5000)")
    parser.add_argument("--out", type=Path, default=None, help="write the JSON report here")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args()
    if args.seeds < 1:
        raise UserError(f"--seeds must be positive, got {args.seeds}")
    report = run(args.model, args.candidates, args.ks, args.delta_rel, args.seeds, args.eps, args.max_subsets,
                 args.quiet)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1))
    print(format_report(report))


if __name__ == "__main__":
    run_cli(main)
