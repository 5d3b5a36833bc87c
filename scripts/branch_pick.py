"""Branch finished grid runs at one acquisition (default: their last) and let other selectors make that pick
(experiments/branch.py): each branch picks from the run's own model and trains on from its random state, the run's
own selector making any later picks, so the final PSNR differences are that pick's doing.

    python scripts/branch_pick.py output/paper_stages_auto/setup1/mic/auto/seed* \\
        --specs coverage cover_pool --out output/branch_mic [--stage 1] [--table-only] [--json rows.json]
    python scripts/branch_pick.py --table rows.json
"""
from __future__ import annotations

import argparse
import shlex
from pathlib import Path

import torch
from tqdm import tqdm

from experiments.branch import acquisition_checkpoint, branch_rows, branch_table, rows_from_json, run_branch
from experiments.replay import saved_rows
from utils.errors import UserError, run_cli
from utils.io import write_json


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", type=Path, nargs="*", help="finished grid runs (ROOT/SETUP/SCENE/METHOD/SEED)")
    p.add_argument("--specs", nargs="+",
                   help="selectors for the last pick, NAME[+OPTION=VALUE...] (e.g. pop_gs+gain_weight=opacity)")
    p.add_argument("--out", type=Path, help="folder of the branches (OUT/SCENE/METHOD/SPEC/SEED)")
    p.add_argument("--train_args", default="", metavar="FLAGS",
                   help='extra train.py flags for every branch, quoted (e.g. "--exclude_views 3 17"); '
                        "give them their own --out")
    p.add_argument("--stage", type=int, help="the acquisition to branch at, 0 = the first, as in selection.json "
                   "(default: the last); the run must have kept its checkpoint (train.py --keep_checkpoints 0 "
                   "keeps all)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1: two of these side by side)")
    p.add_argument("--table-only", action="store_true", help="train nothing; tabulate the finished branches")
    p.add_argument("--json", type=Path, help="also write the table's rows (every seed's PSNRs) to this file")
    p.add_argument("--table", type=Path, metavar="JSON", help="print the table of rows written with --json; no runs")
    args = p.parse_args()
    if args.table is not None:
        print(branch_table(rows_from_json(saved_rows(args.table, "branch rows"))))
        return
    if not args.runs or not args.specs or args.out is None:
        raise UserError("pass finished grid runs, --specs and --out (or --table ROWS.json)")
    torch.set_num_threads(args.threads)
    train_args = tuple(shlex.split(args.train_args))
    for run in args.runs:
        acquisition_checkpoint(run, args.stage)  # every run branchable there, before any branch trains
    if not args.table_only:
        jobs = [(run, spec) for run in args.runs for spec in args.specs]
        for run, spec in tqdm(jobs, desc="branches", unit="run"):
            run_branch(run, spec, args.out, train_args, args.stage)
    rows = branch_rows(args.runs, args.specs, args.out, train_args, args.stage)
    if args.json is not None:
        write_json(args.json, rows)
    print(branch_table(rows))


if __name__ == "__main__":
    run_cli(main)
