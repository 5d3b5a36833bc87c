"""Progress of a running grid: one line per finished job, the running jobs' progress, grid_status.json."""
from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

from experiments.grid_config import GridConfig
from experiments.jobs import JobSpec, is_finished, train_command
from utils.io import read_json, write_json
from utils.model_dir import RUN_STATUS

log = logging.getLogger(__name__)
STATUS = "grid_status.json"


def _fmt(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds >= 3600:
        return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
    return f"{seconds // 60}m{seconds % 60:02d}s"


class Tracker:
    """Job states, one progress line per finished job, and grid_status.json (rewritten atomically)."""

    def __init__(self, cfg: GridConfig, specs: list[JobSpec]):
        self.path = cfg.setup_dir / STATUS
        self.t0 = time.time()
        self.header = {"setup": cfg.setup, "launcher": cfg.launcher, "max_parallel": cfg.max_parallel,
                       "threads_per_job": cfg.threads, "started": time.strftime("%Y-%m-%d %H:%M:%S")}
        self.jobs: dict[str, dict[str, Any]] = {}
        for spec in specs:
            done = is_finished(Path(spec.model_dir), spec.uncertainty)
            self.jobs[spec.key] = {"key": spec.key, "state": "skipped" if done else "pending",
                                   "model_dir": spec.model_dir, "command": train_command(spec),
                                   "log": spec.log_path, "error": "", "seconds": None}
        self.ran = 0
        self.progress_every_s = cfg.progress_every_s
        self.last_report = time.time()

    def count(self, *states: str) -> int:
        return sum(j["state"] in states for j in self.jobs.values())

    def start(self, key: str, worker_log: str = "") -> None:
        self.jobs[key].update(state="running", worker_log=worker_log)
        self.write()

    def finish(self, key: str, outcome: dict[str, Any]) -> None:
        job = self.jobs[key]
        job.update(state=outcome["state"], error=outcome.get("error", ""), seconds=outcome.get("seconds"))
        self.ran += 1
        elapsed = time.time() - self.t0
        finished, total = self.count("done", "failed", "skipped"), len(self.jobs)
        left = total - finished
        eta = elapsed / self.ran * left if left else 0.0
        took = f" in {_fmt(job['seconds'])}" if job["seconds"] is not None else ""
        line = (f"[{finished}/{total}, {self.count('failed')} failed] {key}: {job['state']}{took}; "
                f"elapsed {_fmt(elapsed)}, ETA {_fmt(eta)}")
        if job["state"] == "failed":
            line += f"\n    {job['error']} (log: {job['log']})"
        log.info(line)
        self.write()

    def report_running(self) -> None:
        """Every `progress_every_s`: one line per running job with the progress its train.py records in
        run_status.json (iteration / total, Gaussians), also kept in grid_status.json as the job's "progress"."""
        if time.time() - self.last_report < self.progress_every_s:
            return
        self.last_report = time.time()
        for job in self.jobs.values():
            if job["state"] != "running":
                continue
            status = read_json(Path(job["model_dir"]) / RUN_STATUS, missing="none", damaged="none")
            if not (status is not None and status.get("status") == "running" and "iteration" in status):
                continue
            job["progress"] = {k: status.get(k) for k in ("iteration", "total_iterations", "num_gaussians",
                                                          "updated")}
            log.info(f"  running {job['key']}: iteration {status['iteration']}/{status.get('total_iterations', '?')}, "
                     f"{status.get('num_gaussians', '?')} Gaussians (as of {status.get('updated', '?')})")
        self.write()

    def write(self) -> None:
        counts = {s: self.count(s) for s in ("pending", "running", "done", "skipped", "failed")}
        write_json(self.path, {**self.header, "updated": time.strftime("%Y-%m-%d %H:%M:%S"),
                               "elapsed_s": round(time.time() - self.t0, 1), "counts": counts,
                               "jobs": list(self.jobs.values())})
