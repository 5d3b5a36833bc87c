"""Run one setup of the paper as a grid of jobs: scenes x methods (x K x eps) x seeds, each job train -> render
test views -> metrics, on local processes, a Slurm cluster (job arrays) or inline; then summarize.

    python scripts/grid.py --setup setup1 --scenes lego --methods random pop_gs lite_gs --seeds 2 \\
        --launcher local --max_parallel 2
    python scripts/grid.py --setup setup4 --scenes ship --launcher slurm --slurm_partition gpu \\
        --gpus_per_job 1 --cpus_per_job 8 --time_min 240 --max_parallel 16 --resolution 1 --iter_scale 1 \\
        --num_points 100000 -- --sh_degree 3

Runs go to OUT/<setup>/<scene>/<method>[_k<K>][_eps<E>]/seed<S>; a rerun skips finished jobs and resumes the others
(train.py resumes from its newest stage checkpoint). Progress: one line per finished job and
OUT/<setup>/grid_status.json. Everything after `--` is appended to every train.py call. Exit status: the number
of failed jobs (0 = all finished; 2 with one `error:` line for a bad command line, before any job runs).
"""
from __future__ import annotations

import logging
import sys

from experiments.grid_args import parse
from experiments.runner import run_grid
from utils.errors import run_cli


def main() -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stdout)
    return min(run_grid(parse(sys.argv[1:], __doc__)), 100)


if __name__ == "__main__":
    run_cli(main)
