"""Compare selectors across recommend-then-train results: per selector, its mean test PSNR minus random's and minus
coverage's on each scene, the worst of each, and in how many scene-seeds it came last.

    python scripts/compare_recommend_then_train.py lego=docs/results/rtt_lego_official/results.json \\
        mic=docs/results/rtt_mic_official/results.json bonsai=docs/results/rtt_bonsai/results.json

Every selector with every seed on every scene is compared ("none" left out); random and coverage must be among them.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from experiments.recommend_train_loop import compare_table
from utils.errors import UserError, run_cli
from utils.io import read_json


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("results", nargs="+", help="SCENE=PATH to a recommend_then_train.py results.json")
    args = p.parse_args()
    results = {}
    for item in args.results:
        scene, sep, path = item.partition("=")
        if not sep or not scene or not path:
            raise UserError(f"each argument is SCENE=PATH to a results.json, got {item!r}")
        results[scene] = read_json(Path(path), what="recommend-then-train results",
                                   fix="run scripts/recommend_then_train.py to write it")
    print(compare_table(results), end="")


if __name__ == "__main__":
    run_cli(main)
