"""Recommend the next views from poses alone, then train on them: recommend.py against random and coverage picks.

On a Blender dataset (default: lego) or a COLMAP one (convert.py's output; test split: train.py --eval's): train a
model on S seed views (farthest-point sampling, as train.py seeds), in a folder that holds only those S training images
and the test images (on COLMAP, with the SfM points that a seed view observes); rank the other training views by
their *poses* (a pose file whose images are not in that folder, so no candidate image can be read) with recommend.py
for each method and seed; then continue training the S-view model (`train.py --init_ply`) on the S + K views, the same
iterations for every method, and record the test PSNR. Method "none" continues on the S views alone (the reference).
With --seed_start random each seed draws its own first seed view, so it has its own seed views and base model.

    python scripts/recommend_then_train.py --data ../shared/data/lego --methods lite_gs coverage random none \
        --seeds 0 1 2 -o output/recommend_then_train

Writes OUT/results.json (per method and seed: picks as dataset view ids, oracle counts, seconds, test PSNR) and
OUT/summary.md (per-seed table, mean +- std). Finished steps are reused when the script is run again.
"""
from __future__ import annotations

import argparse

from active.schedule import SEED_STARTS
from experiments.recommend_train_loop import run_recommend_then_train
from experiments.seed_dataset import SEED_POINTS
from utils.errors import run_cli


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default="../shared/data/lego",
                   help="Blender dataset (transforms_train/test.json) or COLMAP one (sparse/0; test split: --eval's)")
    p.add_argument("-i", "--images", default="images", help="a COLMAP dataset's image folder (train.py's -i)")
    p.add_argument("-o", "--output", default="output/recommend_then_train")
    p.add_argument("--seed_points", choices=SEED_POINTS, default="observed",
                   help="COLMAP: the seed model starts from the SfM points a seed view observes (a real capture), or "
                        "from all of them (a diagnosis: Gaussians also where only candidates looked)")
    p.add_argument("--methods", nargs="+", default=["lite_gs", "coverage", "random", "none"],
                   help="recommend.py selectors, NAME or NAME+OPTION=VALUE (e.g. pop_gs+gain_weight=opacity), "
                        "and 'none' (no new views)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--num_seed_views", type=int, default=5)
    p.add_argument("--seed_start", choices=SEED_STARTS, default="first",
                   help="farthest-point seeding from training view 0, one seed model for every seed (first), or from a "
                        "view drawn with each seed, one seed model per seed in OUT/seedS (random; a deterministic "
                        "selector's seeds are then different view sets, not training noise around one)")
    p.add_argument("-k", type=int, default=4)
    p.add_argument("-r", "--resolution", default="8")
    p.add_argument("--base_iterations", type=int, default=1000, help="training of the seed-view model")
    p.add_argument("--iterations", type=int, default=1200, help="training continued on the seed + K views")
    p.add_argument("--select_iteration", type=int, default=None,
                   help="recommend on the seed-view model as saved at this iteration (< --base_iterations; a "
                        "diagnosis: picks of a less trained model), the training still continuing from the last "
                        "(default: the last)")
    p.add_argument("--train_args", default="--num_random_points 3000 --densify_from_iter 100 "
                                            "--densification_interval 50 --max_gaussians 20000",
                   help="extra train.py flags of both trainings, one string (--train_args=\"...\"; default: 3,000 "
                        "initial points, densification from iteration 100 as short runs need, at most 20k Gaussians)")
    p.add_argument("--threads", type=int, default=2)
    args = p.parse_args()
    run_recommend_then_train(args)


if __name__ == "__main__":
    run_cli(main)
