"""Branch finished grid runs at their last acquisition and let other selectors make that pick
(experiments/branch.py): each branch picks from the run's own model and trains on from its random state, so the
final PSNR differences are the last pick's alone.

    python scripts/branch_pick.py output/paper_stages_auto/setup1/mic/auto/seed* \\
        --specs coverage cover_pool --out output/branch_mic [--table-only]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import torch
from tqdm import tqdm

from experiments.branch import branch_rows, branch_table, check_branchable, run_branch
from utils.errors import run_cli


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", type=Path, nargs="+", help="finished grid runs (ROOT/SETUP/SCENE/METHOD/SEED)")
    p.add_argument("--specs", nargs="+", required=True,
                   help="selectors for the last pick, NAME[+OPTION=VALUE...] (e.g. pop_gs+gain_weight=opacity)")
    p.add_argument("--out", type=Path, required=True, help="folder of the branches (OUT/SCENE/SPEC/SEED)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1: two of these side by side)")
    p.add_argument("--table-only", action="store_true", help="train nothing; print the table of the finished branches")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    for run in args.runs:
        check_branchable(run)
    if not args.table_only:
        jobs = [(run, spec) for run in args.runs for spec in args.specs]
        for run, spec in tqdm(jobs, desc="branches", unit="run"):
            run_branch(run, spec, args.out)
    source = args.runs[0].parent.name
    print(branch_table(branch_rows(args.runs, args.specs, args.out), source))


if __name__ == "__main__":
    run_cli(main)
