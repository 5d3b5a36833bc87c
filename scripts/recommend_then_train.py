"""Recommend the next views from poses alone, then train on them: recommend.py against random and coverage picks.

On a Blender dataset (default: lego): train a model on S seed views (farthest-point sampling, as train.py seeds), in a
folder that holds only those S training images and the test images; rank the other training views by their *poses*
(a transforms file whose images are not in that folder, so no candidate image can be read) with recommend.py for each
method and seed; then continue training the S-view model (`train.py --init_ply`) on the S + K views, the same
iterations for every method, and record the test PSNR. Method "none" continues on the S views alone (the reference).

    python scripts/recommend_then_train.py --data ../shared/data/lego --methods lite_gs coverage random none \
        --seeds 0 1 2 -o output/recommend_then_train

Writes OUT/results.json (per method and seed: picks as dataset view ids, oracle counts, seconds, test PSNR) and
OUT/summary.md (per-seed table, mean +- std). Finished steps are reused when the script is run again.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from experiments.recommend_then_train import make_seed_dataset, method_args, run, summary_table
from utils import model_dir
from utils.checkpoint import RunDirectory
from utils.errors import UserError, run_cli
from utils.io import write_json


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default="../shared/data/lego", help="Blender dataset (transforms_train/test.json)")
    p.add_argument("-o", "--output", default="output/recommend_then_train")
    p.add_argument("--methods", nargs="+", default=["lite_gs", "coverage", "random", "none"],
                   help="recommend.py selectors, NAME or NAME+OPTION=VALUE (e.g. pop_gs+gain_weight=opacity), and "
                        "'none' (no new views)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--num_seed_views", type=int, default=5)
    p.add_argument("-k", type=int, default=4)
    p.add_argument("-r", "--resolution", default="8")
    p.add_argument("--base_iterations", type=int, default=1000, help="training of the seed-view model")
    p.add_argument("--iterations", type=int, default=1200, help="training continued on the seed + K views")
    p.add_argument("--train_args", default="--num_random_points 3000 --densify_from_iter 100 "
                                            "--densification_interval 50 --max_gaussians 20000",
                   help="extra train.py flags of both trainings, one string (--train_args=\"...\"; default: 3,000 "
                        "initial points, densification from iteration 100 as short runs need, at most 20k Gaussians)")
    p.add_argument("--threads", type=int, default=2)
    args = p.parse_args()
    data, out = Path(args.data), Path(args.output)
    if not (data / "transforms_train.json").is_file() or not (data / "transforms_test.json").is_file():
        raise UserError(f"{data} is not a Blender dataset with transforms_train.json and transforms_test.json")
    out.mkdir(parents=True, exist_ok=True)
    (out / "logs").mkdir(exist_ok=True)
    seeds, candidates = make_seed_dataset(data, out, args.num_seed_views)
    print(f"seed views {seeds}; {len(candidates)} candidate poses in {out / 'data' / 'candidates.json'} "
          "(their images are not in that folder)")
    common = ["-r", args.resolution, "--eval", "-w", "-q", *args.train_args.split()]
    base = out / "base"
    if not RunDirectory(base).is_complete():
        secs = run(["train.py", "-s", str(out / "data"), "-m", str(base), "--iterations", str(args.base_iterations),
                    "--overwrite", *common], args.threads, out / "logs" / "base.log")
        print(f"base model on {len(seeds)} views: {secs:.0f} s")
    base_status = json.loads((base / model_dir.RUN_STATUS).read_text())
    base_ply = model_dir.point_cloud_ply(base, args.base_iterations)
    results_path = out / "results.json"
    results = json.loads(results_path.read_text()) if results_path.is_file() else {}
    results["settings"] = {**vars(args), "seed_views": seeds, "candidates": len(candidates),
                           "base_test_psnr": base_status["test_psnr"]}
    for method in args.methods:
        for seed in args.seeds:
            key = f"{method}/seed{seed}"
            row = results.get(key, {})
            if method != "none" and "picks" not in row:
                rec_dir = out / "recommend" / f"{method}_seed{seed}"
                secs = run(["recommend.py", "-m", str(base), "--candidates", str(out / "data" / "candidates.json"),
                            "-k", str(args.k), *method_args(method), "--seed", str(seed), "-o", str(rec_dir),
                            "--quiet", "--no_previews"], args.threads, out / "logs" / f"recommend_{method}_{seed}.log")
                rec = json.loads((rec_dir / "recommendations.json").read_text())
                row = {"picks": [candidates[pick["candidate"]] for pick in rec["picks"]],
                       "oracle_calls": rec["oracle_calls"], "recommend_seconds": secs}
            views = seeds + row.get("picks", [])
            model = out / "continue" / f"{method}_seed{seed}"
            if "test_psnr" not in row or not RunDirectory(model).is_complete():
                row["train_seconds"] = run(
                    ["train.py", "-s", str(data), "-m", str(model), "--method", "random", "--init_views",
                     *map(str, views), "--max_views", str(len(views)), "--views_per_step", str(args.k),
                     "--iterations", str(args.iterations), "--init_ply", str(base_ply), "--seed", str(seed),
                     "--overwrite", *common], args.threads, out / "logs" / f"continue_{method}_{seed}.log")
                row["test_psnr"] = json.loads((model / model_dir.RUN_STATUS).read_text())["test_psnr"]
            results[key] = row
            write_json(results_path, results)
            print(f"{key}: views {views} -> test PSNR {row['test_psnr']:.2f} dB")
    (out / "summary.md").write_text(summary_table(results, args.methods, args.seeds))
    print((out / "summary.md").read_text())


if __name__ == "__main__":
    run_cli(main)
