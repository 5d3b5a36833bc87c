"""Recommend from poses alone, then train on the picks (CLI scripts/recommend_then_train.py, docs/recommend.md): the
runs of the project's CLIs (`run`), the loop over methods and seeds on a seed-view dataset (experiments/seed_dataset.py)
(`run_recommend_then_train`) and the summary table (`summary_table`)."""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from active.schedule import first_seed_index
from experiments.jobs import THREAD_VARS
from experiments.method_spec import method_flags
from experiments.seed_dataset import SeedDataset, make_seed_dataset, training_centers
from utils import model_dir
from utils.checkpoint import RunDirectory
from utils.errors import UserError
from utils.io import read_json, write_json

ROOT = Path(__file__).resolve().parents[1]


def run(cmd: list[str], threads: int, log: Path) -> float:
    """Run one CLI of the project with `threads` threads; its output goes to `log`. Returns the wall seconds."""
    env = {**os.environ, **{v: str(threads) for v in THREAD_VARS}}
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        proc = subprocess.run([sys.executable, *cmd], cwd=ROOT, env=env, stdout=fh, stderr=subprocess.STDOUT)
    if proc.returncode != 0:
        tail = "".join(log.read_text().splitlines(keepends=True)[-5:])
        raise UserError(f"{' '.join(cmd[:2])} failed (log {log}):\n{tail}")
    return time.perf_counter() - t0


def summary_table(results: dict, methods: list[str], seeds: list[int]) -> str:
    """Per-seed test PSNR and mean +- std per method, with the picks and oracle counts."""
    s = results["settings"]
    if isinstance(s["seed_views"], dict):  # --seed_start random: one seed-view set and base model per seed
        notes = s.get("seed_data", {})
        per_seed = "; ".join(f"seed {x}: {s['seed_views'][str(x)]}, {s['base_test_psnr'][str(x)]:.2f} dB"
                             + (f", {notes[str(x)]}" if str(x) in notes else "") for x in seeds)
        base = f"Seed views drawn per seed (`--seed_start random`; base test PSNR after {s['base_iterations']} " \
               f"iterations): {per_seed}"
    else:
        base = f"Seed views {s['seed_views']} ({s['base_iterations']} iterations: base test PSNR " \
               f"{s['base_test_psnr']:.2f} dB)"
    note = s.get("seed_data") if isinstance(s.get("seed_data"), str) else ""
    lines = [f"{base}; +{s['k']} views from {s['candidates']} candidate poses, then "
             f"{s['iterations']} iterations from the base model (`--init_ply`), -r {s['resolution']}, "
             f"`{s['train_args']}`." + (f" {note}." if note else ""), "",
             "| added views from | " + " | ".join(f"seed {x}" for x in seeds) + " | mean ± std | picks (seed "
             f"{seeds[0]}) | oracles evaluated / conservative |",
             "|---|" + "---|" * len(seeds) + "---|---|---|"]
    for m in methods:
        rows = [results[f"{m}/seed{x}"] for x in seeds]
        values = [r["test_psnr"] for r in rows]
        spread = statistics.stdev(values) if len(values) > 1 else 0.0
        calls = rows[0].get("oracle_calls")
        lines.append(f"| {m} | " + " | ".join(f"{v:.2f}" for v in values)
                     + f" | {statistics.mean(values):.2f} ± {spread:.2f} | {rows[0].get('picks', '–')} | "
                     + (f"{calls['evaluated']} / {calls['conservative']}" if calls else "–") + " |")
    return "\n".join(lines) + "\n"


def recorded_runs(results: dict) -> tuple[list[str], list[int]]:
    """The methods (in the order they were run) and the seeds of a results.json's "METHOD/seedS" entries."""
    keys = [k for k in results if "/seed" in k]
    return list(dict.fromkeys(k.rsplit("/", 1)[0] for k in keys)), sorted({int(k.rsplit("seed", 1)[1]) for k in keys})


def compare_table(results: dict[str, dict], methods: list[str] | None = None) -> str:
    """Across scenes (`results`: scene name -> a results.json's content): per method, its mean test PSNR minus
    random's and minus coverage's on each scene, the worst of each, and in how many scene-seeds it is last among
    `methods` (ties count for each; default: the methods with every seed on every scene, "none" left out). Rows
    from the best worst case against coverage down."""
    recorded = {name: recorded_runs(r) for name, r in results.items()}
    seeds = {name: runs[1] for name, runs in recorded.items()}
    if methods is None:  # in the first scene's order
        per_scene = [runs[0] for runs in recorded.values()]
        methods = [m for m in per_scene[0] if m != "none" and all(m in found for found in per_scene)
                   and all(f"{m}/seed{x}" in results[n] for n in results for x in seeds[n])]
    for required in ("random", "coverage"):
        if required not in methods:
            raise UserError(f"comparing recommend-then-train results needs {required!r} on every scene and seed")
    mean = {(n, m): statistics.mean(results[n][f"{m}/seed{x}"]["test_psnr"] for x in seeds[n])
            for n in results for m in methods}
    last = {m: 0 for m in methods}
    for n in results:
        for x in seeds[n]:
            values = {m: results[n][f"{m}/seed{x}"]["test_psnr"] for m in methods}
            low = min(values.values())
            for m, v in values.items():
                last[m] += v == low
    head = [f"{n} vs random / vs coverage" for n in results]
    lines = ["| selector | " + " | ".join(head) + " | worst vs random | worst vs coverage | last in |",
             "|---|" + "---|" * (len(head) + 3)]
    total = sum(len(seeds[n]) for n in results)
    worst_vs_coverage = {m: min(mean[n, m] - mean[n, "coverage"] for n in results) for m in methods}
    for m in sorted(methods, key=lambda m: -worst_vs_coverage[m]):  # best worst case first (stable on ties)
        d_random = [mean[n, m] - mean[n, "random"] for n in results]
        d_cover = [mean[n, m] - mean[n, "coverage"] for n in results]
        cells = [f"{a:+.2f} / {b:+.2f}" for a, b in zip(d_random, d_cover)]
        lines.append(f"| {m} | " + " | ".join(cells) + f" | {min(d_random):+.2f} | {min(d_cover):+.2f} | "
                     f"{last[m]} of {total} |")
    return "\n".join(lines) + "\n"


def train_flags(args: argparse.Namespace) -> list[str]:
    """The train.py flags the seed model and every continued training share."""
    return ["-r", args.resolution, "--eval", "-q", *args.train_args.split()]


def seed_model(args: argparse.Namespace, folder: Path, start: int, select_at: int) -> tuple[SeedDataset, Path, float]:
    """The seed-view dataset in FOLDER/data (seeding from view `start`) and the model trained on it in FOLDER/base
    (reused when complete): the dataset, the base model's folder and its test PSNR."""
    seed_data = make_seed_dataset(Path(args.data), folder, args.num_seed_views, images=args.images,
                                  seed_points=args.seed_points, start=start)  # a bad --data: nothing written
    print(f"seed views {seed_data.seeds}; {len(seed_data.candidates)} candidate poses in {seed_data.candidate_poses} "
          "(their images are not in that folder)" + (f"; {seed_data.note}" if seed_data.note else ""))
    base = folder / "base"
    if not RunDirectory(base).is_complete():
        (folder / "logs").mkdir(parents=True, exist_ok=True)
        secs = run(["train.py", "-s", str(seed_data.folder), "-m", str(base), "--iterations",
                    str(args.base_iterations), "--save_iterations", str(select_at), "--overwrite",
                    *seed_data.seed_flags, *train_flags(args)], args.threads, folder / "logs" / "base.log")
        print(f"base model on {len(seed_data.seeds)} views: {secs:.0f} s")
    if not model_dir.point_cloud_ply(base, select_at).is_file():
        raise UserError(f"{base} has no point cloud at iteration {select_at} (--select_iteration); use a new -o to "
                        "train a base model that saves it")
    return seed_data, base, read_json(base / model_dir.RUN_STATUS)["test_psnr"]


# The flags that decide a run's result: every call into one results.json must agree on them (methods, seeds, threads
# and the output folder may differ). The value is what a results.json written before the flag existed ran with,
# or UNKNOWN (then such a results.json is not checked on that flag).
UNKNOWN = object()
PROTOCOL_FLAGS = {"data": UNKNOWN, "images": "images", "seed_points": UNKNOWN, "num_seed_views": UNKNOWN,
                  "seed_start": "first", "k": UNKNOWN, "resolution": UNKNOWN, "base_iterations": UNKNOWN,
                  "iterations": UNKNOWN, "select_iteration": None, "train_args": UNKNOWN}


def check_same_protocol(earlier: dict, current: dict, results_path: Path) -> None:
    """One `error:` line if the settings recorded in `results_path` (`earlier`) differ from this call's (`current`)
    on a flag of PROTOCOL_FLAGS, so that runs of two protocols never share one table."""
    for flag, before_it_existed in PROTOCOL_FLAGS.items():
        old = earlier.get(flag, before_it_existed)
        if old is not UNKNOWN and old != current.get(flag):
            raise UserError(f"{results_path} holds runs with --{flag} {old}; use a new -o for --{flag} "
                            f"{current.get(flag)}")


def run_recommend_then_train(args: argparse.Namespace) -> None:
    """The whole experiment for scripts/recommend_then_train.py's parsed flags (`args`): per seed the seed-view model
    (one for all seeds in OUT/base with --seed_start first; one per seed in OUT/seedS/base with random), then per
    method recommend.py and the continued training; writes OUT/results.json and OUT/summary.md, reusing the
    finished steps."""
    data, out = Path(args.data), Path(args.output)
    select_at = args.base_iterations if args.select_iteration is None else args.select_iteration
    if not 0 < select_at <= args.base_iterations:
        raise UserError(f"--select_iteration must lie in [1, --base_iterations = {args.base_iterations}], got "
                        f"{select_at}")
    drawn = args.seed_start == "random"
    results_path = out / "results.json"
    results = read_json(results_path, missing="none", fix="delete it to run every step again") or {}
    earlier = results.get("settings", {})
    if results:
        check_same_protocol(earlier, vars(args), results_path)
    per_seed = {k: dict(earlier.get(k, {})) if drawn and isinstance(earlier.get(k), dict) else {}
                for k in ("seed_views", "base_test_psnr", "seed_data")}  # drawn: seeds of earlier calls kept
    num_views = len(training_centers(data)) if drawn else 1  # only a drawn start needs the count
    for seed in args.seeds:
        folder = out / f"seed{seed}" if drawn else out
        start = first_seed_index(args.seed_start, seed, num_views)  # train.py's draw (without --exclude_views)
        seed_data, base, base_psnr = seed_model(args, folder, start, select_at)
        seeds, candidates = seed_data.seeds, seed_data.candidates
        (out / "logs").mkdir(parents=True, exist_ok=True)
        base_ply = model_dir.point_cloud_ply(base, args.base_iterations)
        described = {"seed_views": seeds, "base_test_psnr": base_psnr, "seed_data": seed_data.note}
        if drawn:  # one entry per seed, in dicts keyed by the seed
            for k, v in described.items():
                if v != "":  # no note
                    per_seed[k][str(seed)] = v
            described = per_seed
        results["settings"] = {**vars(args), "candidates": len(candidates),
                               **{k: v for k, v in described.items() if v not in ("", {})}}
        for method in args.methods:
            key = f"{method}/seed{seed}"
            row = results.get(key, {})
            if method != "none" and "picks" not in row:
                rec_dir = out / "recommend" / f"{method}_seed{seed}"
                secs = run(["recommend.py", "-m", str(base), "--candidates", str(seed_data.candidate_poses),
                            "-k", str(args.k), *method_flags(method), "--seed", str(seed), "--iteration",
                            str(select_at), "-o", str(rec_dir),
                            "--quiet", "--no_previews"], args.threads, out / "logs" / f"recommend_{method}_{seed}.log")
                rec = read_json(rec_dir / "recommendations.json")
                row = {"picks": [candidates[pick["candidate"]] for pick in rec["picks"]],
                       "oracle_calls": rec["oracle_calls"], "recommend_seconds": secs}
            views = seeds + row.get("picks", [])
            model = out / "continue" / f"{method}_seed{seed}"
            if "test_psnr" not in row or not RunDirectory(model).is_complete():
                row["train_seconds"] = run(
                    ["train.py", "-s", str(data), "-m", str(model), "--method", "random", "--init_views",
                     *map(str, views), "--max_views", str(len(views)), "--views_per_step", str(args.k),
                     "--iterations", str(args.iterations), "--init_ply", str(base_ply), "--seed", str(seed),
                     "--overwrite", *seed_data.full_flags, *train_flags(args)], args.threads,
                    out / "logs" / f"continue_{method}_{seed}.log")
                row["test_psnr"] = read_json(model / model_dir.RUN_STATUS)["test_psnr"]
            results[key] = row
            write_json(results_path, results)
            print(f"{key}: views {views} -> test PSNR {row['test_psnr']:.2f} dB")
    (out / "summary.md").write_text(summary_table(results, args.methods, args.seeds))
    print((out / "summary.md").read_text())
