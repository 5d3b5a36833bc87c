"""How close each selector's picks lie to the seed views in a recommend-then-train result (experiments/pick_spacing.py).

    python scripts/pick_spacing.py docs/results/rtt_bonsai/results.json --data /work/data/bonsai

Prints a markdown table: per method, the nearest and the mean distance from its picks (first seed) to the nearest
seed view's camera centre, over the median of that distance among the candidates.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from experiments.pick_spacing import spacing_table
from utils.errors import run_cli


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("results", type=Path, help="recommend-then-train results.json")
    p.add_argument("--data", type=Path, required=True, help="its dataset (Blender or COLMAP)")
    args = p.parse_args()
    print(spacing_table(args.results, args.data), end="")


if __name__ == "__main__":
    run_cli(main)
