"""Aggregate experiment runs into paper-style tables (summary.md, summary.csv) and plots (PNG).

    python scripts/summarize.py output/experiments/setup1 [more roots...] [--out DIR]

A run is a model directory holding selection.json, run_status.json or cfg_args. Its setup and scene come from the
layout the experiment scripts write (OUT/<setup>/<scene>/<tag>/seed<S>); its method, K, selector options (e.g. eps)
and seed from selection.json (or cfg_args before the first acquisition step). A run without results.json is listed
as incomplete. Nothing here knows selector names: a method's setting is its name, K and the options its
selection.json records. The library is `experiments/summary.py` (scripts/grid.py calls it after a grid).
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from experiments.summary import check_readable, find_runs, write_outputs
from utils.errors import run_cli


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("roots", nargs="+", help="experiment output roots (searched recursively)")
    parser.add_argument("--out", default=None, help="where to write summary.md/csv and plots (default: first root)")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR, format="warning: %(message)s")
    runs = find_runs(args.roots)
    written = write_outputs(runs, Path(args.out or args.roots[0]))
    print(written[0].read_text())
    print("wrote " + ", ".join(str(p) for p in written))
    check_readable(runs)


if __name__ == "__main__":
    run_cli(main)
