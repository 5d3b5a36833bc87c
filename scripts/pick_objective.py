"""cover_pool's objective for its greedy picks and for coverage's farthest-camera picks at a grid run's first
acquisition, over the model that chose and over the run's final model (experiments/pick_objective.py).

    python scripts/pick_objective.py output/paper_stages_6seeds/setup1/mic/cover_pool/seed* ... [--json rows.json]
    python scripts/pick_objective.py --table rows.json     # the per-scene table of saved rows

Each run's first acquisition is trained again from its logged train.py command (seconds at 100 px); a row per run
is printed as it finishes.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import torch

from experiments.pick_objective import objective_table, pick_objective
from experiments.replay import saved_rows
from utils.errors import UserError, run_cli
from utils.io import write_json


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="*", type=Path, help="finished grid run directories (ROOT/SETUP/SCENE/METHOD/SEED)")
    p.add_argument("--json", type=Path, help="also write the rows to this JSON file")
    p.add_argument("--table", type=Path, help="print the per-scene table of a rows file written by --json, run nothing")
    args = p.parse_args()
    if args.table:
        print(objective_table(saved_rows(args.table, "objective rows")))
        return
    if not args.runs:
        raise UserError("pass finished grid run directories (ROOT/SETUP/SCENE/METHOD/SEED), or --table ROWS.json")
    torch.set_num_threads(1)
    rows = []
    print("| run | captured | cover_pool picks | early | final | coverage picks | early | final |\n"
          "|---|---|---|---|---|---|---|---|")
    for run_dir in args.runs:
        row = pick_objective(run_dir)
        rows.append(row)
        g, s = row["cover_pool"], row["coverage"]
        print(f"| {row['run']} | {row['captured']} | {g['picks']} | {g['early']:.4f} | {g['final']:.4f} | "
              f"{s['picks']} | {s['early']:.4f} | {s['final']:.4f} |", flush=True)
    if args.json:
        write_json(args.json, rows)
    print()
    print(objective_table(rows))


if __name__ == "__main__":
    run_cli(main)
