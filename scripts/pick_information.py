"""The log-det information of branched picks against the runs' own, on the models that chose them
(experiments/pick_information.py): does the Fisher's margin over another selector's picks say which ends better?

    python scripts/branch_pick.py RUNS --specs lite_gs --out output/branch_cov8          # the branches first
    python scripts/pick_information.py RUNS --specs lite_gs --out output/branch_cov8 [--stage S] [--json rows.json]
    python scripts/pick_information.py --table rows.json
"""
from __future__ import annotations

import argparse
from pathlib import Path

import torch
from tqdm import tqdm

from experiments.branch import acquisition_checkpoint
from experiments.pick_information import information_rows, information_table
from experiments.replay import saved_rows
from utils.errors import UserError, run_cli
from utils.io import write_json


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", type=Path, nargs="*", help="finished grid runs (ROOT/SETUP/SCENE/METHOD/SEED)")
    p.add_argument("--specs", nargs="+", help="the branches' specs, as given to branch_pick.py")
    p.add_argument("--out", type=Path, help="branch_pick.py's --out folder holding the branches")
    p.add_argument("--stage", type=int, help="the acquisition the branches were made at (default: the last)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    p.add_argument("--json", type=Path, help="also write every row (picks, information, PSNRs) to this file")
    p.add_argument("--table", type=Path, metavar="JSON", help="print the table of rows written with --json; no runs")
    args = p.parse_args()
    if args.table is not None:
        print(information_table(saved_rows(args.table, "information rows")))
        return
    if not args.runs or not args.specs or args.out is None:
        raise UserError("pass finished grid runs, --specs and --out (branch_pick.py's), or --table ROWS.json")
    torch.set_num_threads(args.threads)
    for run in args.runs:
        acquisition_checkpoint(run, args.stage)  # every run readable there before any Fisher pass
    rows = [row for run in tqdm(args.runs, desc="runs", unit="run")
            for row in information_rows([run], args.specs, args.out, args.stage)]
    if not rows:
        raise UserError(f"no finished branch of these runs in {args.out} for {args.specs}; run branch_pick.py first")
    if args.json is not None:
        write_json(args.json, rows)
    print(information_table(rows))


if __name__ == "__main__":
    run_cli(main)
