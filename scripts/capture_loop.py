"""A closed capture loop on the built-in scene, the one scene that can be photographed from any pose.

Start from 3 views (the same for every seed, or turned by a seed-drawn azimuth with --seed_start random); each
round trains a model on the views captured so far (train.py, from scratch), recommends K of N generated hemisphere
poses (recommender, no images), "captures" them by rendering the built-in ground truth there, and repeats until the
view budget. Test PSNR (the built-in test split) is recorded after every
training, so each method gives a PSNR-vs-views curve.

    python scripts/capture_loop.py --methods lite_gs pop_gs coverage random --seeds 0 1 2 -o output/capture_loop
    python scripts/capture_loop.py --elevation 10,75 ...      # candidates over the test views' elevations only
    python scripts/capture_loop.py --plot output/capture_loop --png docs/results/capture_loop/psnr_vs_views.png

Each (method, seed) writes OUT/METHOD/seedS/loop.json when it finishes: per round the views, test PSNR and the seconds
spent training and recommending; run again, the command keeps the loops finished with the same flags; OUT/summary.md
tables the test PSNR per method and view count (mean +- std over seeds).
"""
from __future__ import annotations

import argparse

from experiments.closed_capture_loop import SEED_STARTS, run_capture_loop
from utils.errors import run_cli


def elevation_range(text: str) -> tuple[float, float]:
    """"LO,HI" in degrees, -89 <= LO < HI <= 89."""
    try:
        lo, hi = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--elevation takes LO,HI in degrees (e.g. 10,75), got {text!r}") from None
    if not -89.0 <= lo < hi <= 89.0:
        raise argparse.ArgumentTypeError(f"--elevation needs -89 <= LO < HI <= 89 degrees, got {text!r}")
    return lo, hi


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--methods", nargs="+", default=["lite_gs", "pop_gs", "coverage", "random"])
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    p.add_argument("-o", "--output", default="output/capture_loop")
    p.add_argument("--resolution", type=int, default=32, help="image side in pixels")
    p.add_argument("--num_test", type=int, default=8)
    p.add_argument("--budget", type=int, default=9, help="views at the end")
    p.add_argument("-k", type=int, default=2, help="views recommended per round")
    p.add_argument("--candidates", type=int, default=30, help="generated hemisphere poses per round")
    p.add_argument("--elevation", type=elevation_range, default=(0.0, 80.0),
                   help="the candidates' elevation range LO,HI in degrees (default 0,80; the test views lie at 10-75)")
    p.add_argument("--seed_start", choices=SEED_STARTS, default="first",
                   help="start views: the same 3 for every seed (first), or those 3 turned about the up axis by an "
                        "azimuth drawn with the seed (random)")
    p.add_argument("--iters_per_view", type=int, default=60, help="training iterations per captured view")
    p.add_argument("--max_gaussians", type=int, default=4000)
    p.add_argument("--num_random_points", type=int, default=10_000,
                   help="train.py's random initial points (default 10,000: every loop in docs/recommend.md ran with it)")
    p.add_argument("--overwrite", action="store_true",
                   help="run every loop again (default: a loop finished with the same flags is kept, so an "
                        "interrupted run resumes; one of other flags is an error)")
    p.add_argument("--plot", help="only rewrite the summary.md and draw the curve of an output folder")
    p.add_argument("--png", default=None, help="the plot (default: psnr_vs_views.png in the output or --plot folder)")
    args = p.parse_args()
    run_capture_loop(args)


if __name__ == "__main__":
    run_cli(main)
