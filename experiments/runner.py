"""Run a grid of jobs with submitit (local processes, Slurm arrays) or inline, track them, summarize at the end.

Layout under OUT/<setup>: the runs (<scene>/<tag>/seed<S>), logs/<scene>/<tag>/seed<S>.log (one per job),
grid.json (the flags the runs were made with), grid_status.json (every job's state, command, log, error line),
.submitit/ (submitit's pickles and worker logs), summary.md / summary.csv / plots (experiments/summary.py), with
--report report.html (reports.write_grid_report).
The pieces: `grid_config` (the validated command line, each run's job), `flags` (never mix runs made with other
flags), `progress` (`Tracker`), `launchers` (inline, local, Slurm), `summary`.
"""
from __future__ import annotations

import logging
from pathlib import Path

from experiments.flags import RECORD, check_flags
from experiments.grid_config import GridConfig, job_spec
from experiments.jobs import is_finished, lock_held, train_command
from experiments.launchers import run_inline, run_submitit, sbatch_text
from experiments.progress import Tracker
from experiments.summary import check_readable, find_runs, write_outputs
from utils.errors import UserError
from utils.io import write_json
from utils.model_dir import RUN_STATUS, SELECTION

log = logging.getLogger(__name__)


def run_grid(cfg: GridConfig) -> int:
    """Run (or resume) every job of the grid, then summarize; returns the number of failed jobs."""
    specs = [job_spec(cfg, run) for run in cfg.runs]
    check_flags(cfg, specs)
    todo = [s for s in specs if not is_finished(Path(s.model_dir), s.uncertainty)]
    # Jobs an earlier (killed) runner's workers still hold go first: they take a slot while they wait for them.
    todo.sort(key=lambda s: not lock_held(s))
    if cfg.dry_run:
        for spec in specs:
            state = "done" if spec not in todo else ("running elsewhere" if lock_held(spec) else "to run")
            log.info(f"{spec.key}: {state}: {train_command(spec)}")
        log.info(f"{len(specs)} job(s), {len(todo)} to run, {cfg.threads} thread(s) each (dry run: nothing started)")
        if cfg.launcher == "slurm" and todo:
            path = cfg.setup_dir / "slurm_dry_run" / "array.sbatch"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(sbatch_text(cfg, len(todo)))
            log.info(f"wrote {path} (not submitted)")
        return 0
    cfg.setup_dir.mkdir(parents=True, exist_ok=True)
    write_json(cfg.setup_dir / RECORD, cfg.record())
    tracker = Tracker(cfg, specs)
    tracker.write()
    log.info(f"{cfg.setup}: {len(specs)} job(s), {len(specs) - len(todo)} already finished, {len(todo)} to run "
             f"({cfg.launcher}, {cfg.max_parallel} at a time, {cfg.threads} thread(s) each); "
             f"status: {tracker.path}")
    if todo:
        (run_inline if cfg.launcher == "inline" else run_submitit)(cfg, todo, tracker)
    failed = tracker.count("failed")
    has_runs = any(next(cfg.setup_dir.rglob(marker), None) for marker in (SELECTION, RUN_STATUS))
    summary_ok = summarize(cfg.setup_dir) if has_runs else True
    if cfg.report and has_runs:
        summary_ok = write_report(cfg.setup_dir) and summary_ok
    if failed:
        log.info(f"{failed} job(s) failed (see the log paths above and {tracker.path}); rerun the same command "
                 "to resume them")
    return failed + (0 if summary_ok else 1)


def write_report(setup_dir: Path) -> bool:
    """The grid report of OUT/<setup> and its runs' reports (reports.write_grid_report), logged; False when it
    fails (with its `error:` line)."""
    from reports import write_grid_report  # plotly: only with --report

    try:
        log.info(f"wrote {write_grid_report(setup_dir)}")
    except UserError as exc:
        log.info(f"report: error: {exc}")
        return False
    return True


def summarize(setup_dir: Path) -> bool:
    """The summary of OUT/<setup> (tables and plots next to the runs, experiments/summary.py), logged; False when
    it fails (with its `error:` line)."""
    try:
        runs = find_runs([str(setup_dir)])
        written = write_outputs(runs, setup_dir)
        log.info(written[0].read_text().rstrip())
        log.info("wrote " + ", ".join(str(p) for p in written))
        check_readable(runs)
    except UserError as exc:
        log.info(f"summary: error: {exc}")
        return False
    return True
