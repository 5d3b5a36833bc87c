"""One self-contained HTML report (opens offline, no network request) of a run, a grid or a recommendation.

    python report.py -m output/lego                 # output/lego/report.html
    python report.py -m output/lego -o /tmp/r.html
    python report.py --grid OUT/setup1              # OUT/setup1/report.html and every run's report.html
    python report.py --recommendation output/lego/next

See docs/reports.md for what each report shows.
"""
from __future__ import annotations

import argparse
import logging
import time
from contextlib import nullcontext
from pathlib import Path

from reports import write_grid_report, write_recommendation_report, write_run_report
from utils.dir_lock import WAYS_OUT, writer_lock
from utils.errors import run_cli
from utils.model_dir import folder_lock_file



def main(argv: list[str] | None = None) -> None:
    """Parse the command line and write the report."""
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("-m", "--model_path", help="model directory written by train.py (render.py / metrics.py)")
    what.add_argument("--grid", help="grid output folder OUT/<setup> of scripts/grid.py")
    what.add_argument("--recommendation", help="output folder of recommend.py (holds recommendations.json)")
    parser.add_argument("-o", "--out", default=None, help="report path (default: report.html in the folder)")
    parser.add_argument("--no_run_reports", action="store_true",
                        help="--grid: link to the runs' existing report.html instead of rewriting them")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    folder = args.model_path or args.grid or args.recommendation
    # report.html goes into the folder: no other writer meanwhile (recommend.py replaces its folder whole, so its
    # lock lies beside it); with -o the folder is only read
    lock = (nullcontext() if args.out is not None else
            writer_lock(folder, WAYS_OUT["report"], folder_lock_file(Path(folder)) if args.recommendation else None,
                        create=False))
    with lock:
        if args.model_path:
            path = write_run_report(args.model_path, args.out)
        elif args.grid:
            path = write_grid_report(args.grid, args.out, run_reports=not args.no_run_reports)
        else:
            path = write_recommendation_report(args.recommendation, args.out)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB in {time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    run_cli(main)
