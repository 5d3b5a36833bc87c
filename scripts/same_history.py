"""Paired differences of two selectors' grid runs from the acquisition where their picks part
(experiments/same_history.py): seeds that picked the same views up to an acquisition hold the same model there,
so the differences after it are the later picks' doing.

    python scripts/same_history.py output/paper_stages_compare/setup1/mic/auto \\
        output/paper_stages_6seeds/setup1/mic/coverage [--names A B]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from experiments.same_history import history_table, same_history
from utils.errors import run_cli


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("a", type=Path, help="method folder A of a finished grid (ROOT/SETUP/SCENE/METHOD)")
    p.add_argument("b", type=Path, help="method folder B, the same scene and seeds")
    p.add_argument("--names", nargs=2, metavar=("A", "B"), help="names for the table (default: the folder names)")
    args = p.parse_args()
    names = args.names or [args.a.name, args.b.name]
    print(history_table(same_history(args.a, args.b), *names))


if __name__ == "__main__":
    run_cli(main)
