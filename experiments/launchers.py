"""Where a grid's jobs run: inline (this process), submitit local processes (P at a time) or a Slurm array."""
from __future__ import annotations

import logging
import os
import shlex
import sys
import time
from typing import Any

from experiments.grid_config import ROOT, GridConfig
from experiments.jobs import GridJob, JobSpec, error_line
from experiments.progress import Tracker
from utils.errors import UserError

log = logging.getLogger(__name__)


def slurm_parameters(cfg: GridConfig, n: int) -> dict[str, Any]:
    """submitit SlurmExecutor parameters of the grid's array (n tasks, at most --max_parallel at once)."""
    params: dict[str, Any] = {
        "job_name": f"litegs_{cfg.setup}", "time": cfg.slurm.time_min, "cpus_per_task": cfg.slurm.cpus_per_job,
        "array_parallelism": min(cfg.max_parallel, n),
        "setup": [f"export PYTHONPATH={shlex.quote(str(ROOT))}${{PYTHONPATH:+:$PYTHONPATH}}"]}
    if cfg.slurm.partition:
        params["partition"] = cfg.slurm.partition
    if cfg.slurm.gpus_per_job:
        params["gpus_per_node"] = cfg.slurm.gpus_per_job
    return params


def sbatch_text(cfg: GridConfig, n: int) -> str:
    """The sbatch file submitit would submit for an array of n jobs (what --dry_run writes)."""
    from submitit.slurm.slurm import _make_sbatch_string  # the text SlurmExecutor writes
    folder = cfg.setup_dir / ".submitit" / "%j"
    command = " ".join([shlex.quote(sys.executable), "-u -m submitit.core._submit", shlex.quote(str(folder))])
    return _make_sbatch_string(command=command, folder=folder, map_count=n, **slurm_parameters(cfg, n))


def _outcome(job: Any, spec: JobSpec) -> dict[str, Any]:
    """A finished submitit job's result, or a failure with the worker's last error line."""
    try:
        return job.result()
    except Exception as exc:  # the worker died or raised: report its last line, not a runner traceback
        return {"state": "failed", "error": f"worker: {error_line(str(exc))} (worker log: {job.paths.stderr})",
                "seconds": None}


def run_inline(cfg: GridConfig, todo: list[JobSpec], tracker: Tracker) -> None:
    for spec in todo:
        tracker.start(spec.key)
        tracker.finish(spec.key, GridJob(spec)())


def run_submitit(cfg: GridConfig, todo: list[JobSpec], tracker: Tracker) -> None:
    import submitit
    folder = cfg.setup_dir / ".submitit" / "%j"
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    if cfg.launcher == "slurm":
        try:
            executor = submitit.SlurmExecutor(folder=folder, max_num_timeout=10)
        except RuntimeError as exc:  # no srun on this machine
            raise UserError(f"cannot use Slurm here ({exc}); use --dry_run to write the sbatch file, or "
                            "--launcher local") from None
        executor.update_parameters(**slurm_parameters(cfg, len(todo)))
        jobs = executor.submit_array([GridJob(spec) for spec in todo])
        for spec, job in zip(todo, jobs):
            tracker.start(spec.key, str(job.paths.stderr))
        log.info(f"submitted {len(jobs)} job(s) as Slurm array {jobs[0].job_id.split('_')[0]}")
        running = dict(zip((s.key for s in todo), zip(todo, jobs)))
        _wait(running, tracker, poll_s=30.0)
        return
    executor = submitit.LocalExecutor(folder=folder, max_num_timeout=10)
    executor.update_parameters(timeout_min=cfg.slurm.time_min)
    queue = list(todo)
    running: dict[str, tuple[JobSpec, Any]] = {}
    while queue or running:
        while queue and len(running) < cfg.max_parallel:
            spec = queue.pop(0)
            job = executor.submit(GridJob(spec))
            running[spec.key] = (spec, job)
            tracker.start(spec.key, str(job.paths.stderr))
        _wait(running, tracker, poll_s=0.5, until_one=True)


def _wait(running: dict[str, tuple[JobSpec, Any]], tracker: Tracker, poll_s: float, until_one: bool = False) -> None:
    """Collect finished jobs from `running` (all of them, or at least one when `until_one`)."""
    while running:
        finished = [key for key, (_, job) in running.items() if job.done()]
        for key in finished:
            spec, job = running.pop(key)
            tracker.finish(key, _outcome(job, spec))
        if finished and until_one:
            return
        if running:
            tracker.report_running()
            time.sleep(poll_s)
