"""Run a grid of jobs with submitit (local processes, Slurm arrays) or inline, track them, summarize at the end.

Layout under OUT/<setup>: the runs (<scene>/<tag>/seed<S>), logs/<scene>/<tag>/seed<S>.log (one per job),
grid.json (the flags the runs were made with), grid_status.json (every job's state, command, log, error line),
.submitit/ (submitit's pickles and worker logs), summary.md / summary.csv / plots (scripts/summarize.py).
"""
from __future__ import annotations

import fcntl
import logging
import os
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from experiments.jobs import GridJob, JobSpec, error_line, is_finished, read_json
from experiments.protocols import PROTOCOLS, RunScale, RunSpec
from utils.errors import UserError
from utils.io import write_json

log = logging.getLogger(__name__)
ROOT = Path(__file__).resolve().parents[1]
RECORD = "grid.json"
STATUS = "grid_status.json"
# cfg_args entries that may differ between runs of one grid (paths, device, logging, restart flags)
NOT_COMPARED = {"source_path", "model_path", "device", "quiet", "resume", "overwrite"}
# train.py config field -> the grid flag that sets it
GRID_FLAG = {"resolution": "--resolution", "num_random_points": "--num_points", "iterations": "--iter_scale",
             "iters_per_view": "--iter_scale", "densify_from_iter": "--iter_scale",
             "opacity_reset_interval": "--iter_scale"}


@dataclass(frozen=True)
class SlurmOptions:
    """Resources of one Slurm job (array task)."""

    partition: str | None = None
    gpus_per_job: int = 0
    cpus_per_job: int = 2
    time_min: int = 1440  # also the local launcher's per-job limit


@dataclass(frozen=True)
class GridConfig:
    """A validated grid command line."""

    setup: str
    data: Path
    out: Path  # OUT; runs go to OUT/<setup>/...
    runs: tuple[RunSpec, ...]
    scale: RunScale
    device: str  # auto | cpu | cuda
    extra_args: tuple[str, ...]  # appended to every train.py call
    launcher: str  # local | slurm | inline
    max_parallel: int
    threads: int  # per job (OMP/MKL/numba)
    python: str  # interpreter of the jobs' CLI calls
    slurm: SlurmOptions = field(default_factory=SlurmOptions)
    dry_run: bool = False
    uncertainty: bool = False  # render.py --uncertainty in every job
    progress_every_s: float = 300.0  # a line per running job (its run_status.json progress) this often

    @property
    def setup_dir(self) -> Path:
        return self.out / self.setup

    def record(self) -> dict[str, Any]:
        """The flags that change results (grid.json): runs made with other values are never mixed."""
        return {"resolution": self.scale.resolution, "iter_scale": self.scale.iter_scale,
                "num_points": self.scale.num_points, "train_args": list(self.extra_args)}


def job_spec(cfg: GridConfig, run: RunSpec) -> JobSpec:
    """The job of one run: train.py flags, log path, interpreter and thread count."""
    model = cfg.setup_dir / run.key
    scene_dir = cfg.data / run.scene
    train_args = ["-s", str(scene_dir), "-m", str(model), "--eval", "-r", str(cfg.scale.resolution)]
    if (scene_dir / "transforms_train.json").is_file():
        train_args.append("--white_background")  # Blender scenes: RGBA on white
    train_args += run.schedule_args(PROTOCOLS[cfg.setup], cfg.scale) + ["--quiet", *cfg.extra_args]
    return JobSpec(key=run.key, model_dir=str(model), log_path=str(cfg.setup_dir / "logs" / f"{run.key}.log"),
                   python=cfg.python, root=str(ROOT), train_args=tuple(train_args), device=cfg.device,
                   threads=cfg.threads, uncertainty=cfg.uncertainty)


def train_command(spec: JobSpec) -> str:
    return shlex.join(spec.commands(spec.device)[0][1])


# ----------------------------------------------------------------------------------------------- flag checks


def check_flags(cfg: GridConfig, specs: list[JobSpec]) -> None:
    """Refuse an output directory holding runs made with other flags (grid.json, then each run's cfg_args)."""
    record = read_json(cfg.setup_dir / RECORD)
    if isinstance(record, dict):
        for key, value in cfg.record().items():
            if key in record and record[key] != value:
                flag = "-- (extra train.py flags)" if key == "train_args" else f"--{key}"
                raise UserError(f"{cfg.setup_dir} holds runs made with {flag} {_show(record[key])}, this command "
                                f"has {_show(value)}; use another --out, or the same flags (runs made with "
                                "different flags are never mixed in one summary)")
    started = [(s, run) for s, run in zip(specs, cfg.runs) if (Path(s.model_dir) / "cfg_args").is_file()]
    if not started:
        return
    import train  # the exact config train.py would resolve from the same flags
    from active.registry import list_selectors, selector_options
    any_selector_option = {o for m in list_selectors() for o in selector_options(m)}
    for spec, run in started:
        saved = read_json(Path(spec.model_dir) / "cfg_args")
        if not isinstance(saved, dict):
            continue  # unreadable: train.py itself reports it
        expected = train.parse_config([*spec.train_args, "--device", "cpu"]).to_dict()
        for group, values in expected.items():
            for name, value in values.items():
                if name in NOT_COMPARED or (name in any_selector_option
                                            and name not in selector_options(run.method)):
                    continue  # another selector's option: this run's method ignores it
                old = saved.get(group, {}).get(name, value) if isinstance(saved.get(group), dict) else value
                if old != value:
                    flag = GRID_FLAG.get(name, "an extra train.py flag after --")
                    raise UserError(f"{spec.model_dir} was trained with --{name} {_show(old)}, this grid asks for "
                                    f"{_show(value)} (set by {flag}); use another --out, or the flags it was made "
                                    "with (runs made with different flags are never mixed in one summary)")


def _show(value: Any) -> str:
    return shlex.join(value) if isinstance(value, list) else str(value)


def lock_held(spec: JobSpec) -> bool:
    """Whether another process (e.g. a job of an earlier, killed runner) is working on this run right now."""
    if not spec.lock_path.is_file():
        return False
    fd = os.open(spec.lock_path, os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return False
    except BlockingIOError:
        return True
    finally:
        os.close(fd)


# ----------------------------------------------------------------------------------------------- progress


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
            status = read_json(Path(job["model_dir"]) / "run_status.json")
            if not (isinstance(status, dict) and status.get("status") == "running" and "iteration" in status):
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


# ----------------------------------------------------------------------------------------------- launchers


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


def _run_inline(cfg: GridConfig, todo: list[JobSpec], tracker: Tracker) -> None:
    for spec in todo:
        tracker.start(spec.key)
        tracker.finish(spec.key, GridJob(spec)())


def _run_submitit(cfg: GridConfig, todo: list[JobSpec], tracker: Tracker) -> None:
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


# ----------------------------------------------------------------------------------------------- the grid


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
        (_run_inline if cfg.launcher == "inline" else _run_submitit)(cfg, todo, tracker)
    failed = tracker.count("failed")
    has_runs = any(next(cfg.setup_dir.rglob(marker), None) for marker in ("selection.json", "run_status.json"))
    summary_ok = summarize(cfg.setup_dir) if has_runs else True
    if failed:
        log.info(f"{failed} job(s) failed (see the log paths above and {tracker.path}); rerun the same command "
                 "to resume them")
    return failed + (0 if summary_ok else 1)


def summarize(setup_dir: Path) -> bool:
    """scripts/summarize.py on OUT/<setup> (tables and plots next to the runs); False when it fails."""
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "summarize.py"), str(setup_dir), "--out",
                        str(setup_dir)], capture_output=True, text=True)
    if r.stdout:
        log.info(r.stdout.rstrip())
    if r.returncode != 0:
        log.info(f"summary: {error_line(r.stderr)}")
    return r.returncode == 0
