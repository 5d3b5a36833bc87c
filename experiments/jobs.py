"""One grid job: train -> render the test views -> metrics for one run, each step skipped when already done.

A job is a submitit `Checkpointable`: on a Slurm preemption or timeout signal it stops its train.py (whose
per-stage checkpoints are on disk) and is requeued; the requeued job resumes from the newest stage checkpoint.
A per-run lock file keeps two copies of a job (e.g. a rerun while an earlier runner's job still works) from
training the same directory at once: the second waits, then finds the run finished or resumes it.
"""
from __future__ import annotations

import fcntl
import json
import logging
import os
import shlex
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from submitit.helpers import Checkpointable

from utils.io import atomic_write, read_json
from utils.model_dir import CFG_ARGS, CHECKPOINTS_DIR, RESULTS, RUN_STATUS, method_name, render_dir

log = logging.getLogger(__name__)
THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")  # torch, BLAS and numba thread pools


JOB_TIMES = "grid_job_seconds.json"  # in a run's directory: one record per grid job invocation that ran a step


def record_job_time(model_dir: Path, seconds: float, state: str) -> None:
    """Append this invocation's wall seconds (train + render + metrics steps it ran) to the run's JOB_TIMES, so a
    run resumed by a later grid invocation keeps the time of every attempt."""
    records = read_json(model_dir / JOB_TIMES, missing="none", damaged="none", kind=list) or []  # damaged: anew
    records.append({"seconds": round(seconds, 3), "state": state, "ended": time.strftime("%Y-%m-%d %H:%M:%S")})
    text = json.dumps(records, indent=1)
    atomic_write(model_dir / JOB_TIMES, lambda tmp: Path(tmp).write_text(text))


def recorded_job_seconds(model_dir: Path) -> float | None:
    """Wall seconds of every grid job invocation that worked on the run (JOB_TIMES), None without a record."""
    records = read_json(model_dir / JOB_TIMES, missing="none", damaged="none", kind=list)
    if records is None:
        return None
    seconds = [r["seconds"] for r in records if isinstance(r, dict) and isinstance(r.get("seconds"), (int, float))]
    return float(sum(seconds)) if seconds else None


def trained_iteration(model_dir: Path) -> int | None:
    """The final iteration when run_status.json says the training is complete, else None."""
    status = read_json(model_dir / RUN_STATUS, missing="none", damaged="none")  # damaged: not complete
    if status is not None and status.get("status") == "complete":
        return int(status.get("iteration", -1))
    return None


def is_finished(model_dir: Path, uncertainty: bool = False) -> bool:
    """Trained, rendered and scored: results.json holds the final iteration's entry (with `uncertainty`, one that
    carries the uncertainty metrics)."""
    iteration = trained_iteration(model_dir)
    results = read_json(model_dir / RESULTS, missing="none", damaged="none")  # damaged: not scored
    entry = results.get(method_name(iteration)) if iteration is not None and results is not None else None
    return isinstance(entry, dict) and (not uncertainty or "uncertainty_object_region" in entry)


def is_rendered(model_dir: Path, iteration: int, uncertainty: bool = False) -> bool:
    """The test views of `iteration` are rendered (with `uncertainty`, their uncertainty maps too)."""
    rendered = render_dir(model_dir, "test", iteration)
    return (rendered / "renders").is_dir() and (not uncertainty or (rendered / "uncertainty").is_dir())


def is_started(model_dir: Path) -> bool:
    """train.py has written something a rerun resumes from (cfg_args, checkpoints)."""
    return (model_dir / CFG_ARGS).is_file() or (model_dir / CHECKPOINTS_DIR).is_dir()


def error_line(text: str) -> str:
    """The line that explains a failure: the last `error:` line, else the last non-empty line."""
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("error:")]
    return (errors or lines or ["(no output)"])[-1]


@dataclass(frozen=True)
class JobSpec:
    """Everything a job needs, picklable: its run directory, log, the three CLI calls and its thread count."""

    key: str  # <scene>/<tag>/seed<S>
    model_dir: str
    log_path: str
    python: str  # interpreter for train.py / render.py / metrics.py
    root: str  # repository root (train.py lives there)
    train_args: tuple[str, ...]  # train.py flags without --device
    device: str  # auto | cpu | cuda (auto: cuda when the job's machine has one)
    threads: int  # OMP/MKL/numba threads of each CLI process
    uncertainty: bool = False  # render.py --uncertainty: maps, and Spearman/AUSE in results.json

    @property
    def lock_path(self) -> Path:
        return Path(self.log_path).with_suffix(".lock")

    def commands(self, device: str) -> list[tuple[str, list[str]]]:
        """(step, argv) of train, render and metrics."""
        root = Path(self.root)
        render = [self.python, str(root / "render.py"), "-m", self.model_dir, "--skip_train", "--quiet"]
        return [("train", [self.python, str(root / "train.py"), *self.train_args, "--device", device]),
                ("render", render + (["--uncertainty"] if self.uncertainty else [])),
                ("metrics", [self.python, str(root / "metrics.py"), "-m", self.model_dir, "--quiet"])]


class GridJob(Checkpointable):
    """Callable run by submitit (or inline): returns {"state": "done"|"failed", "error", "seconds", "fresh"}; an
    invocation that ran a step also appends its seconds to the run's JOB_TIMES."""

    def __init__(self, spec: JobSpec):
        self.spec = spec
        self._child: subprocess.Popen | None = None

    def __getstate__(self) -> dict:
        return {"spec": self.spec}

    def __setstate__(self, state: dict) -> None:
        self.spec, self._child = state["spec"], None

    def __call__(self) -> dict[str, Any]:
        spec, t0 = self.spec, time.time()
        Path(spec.log_path).parent.mkdir(parents=True, exist_ok=True)
        lock_fd = os.open(spec.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            with open(spec.log_path, "a") as logf:
                try:
                    fcntl.flock(lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    self._note(logf, "another process is running this job; waiting for it")
                    fcntl.flock(lock_fd, fcntl.LOCK_EX)
                outcome = self._steps(logf, lock_fd)
                seconds = time.time() - t0
                if outcome.pop("ran"):
                    record_job_time(Path(spec.model_dir), seconds, outcome["state"])
                return {**outcome, "seconds": seconds}
        finally:
            self._stop_child()
            os.close(lock_fd)

    def _steps(self, logf, lock_fd: int) -> dict[str, Any]:
        spec, model = self.spec, Path(self.spec.model_dir)
        fresh = ran = False
        if is_finished(model, spec.uncertainty):
            self._note(logf, "already finished")
            return {"state": "done", "error": "", "fresh": False, "ran": False}
        env = {**os.environ, **{var: str(spec.threads) for var in THREAD_VARS}}
        for step, argv in spec.commands(self._device()):
            iteration = trained_iteration(model)
            if step == "train" and iteration is not None:
                continue
            if step == "render" and is_rendered(model, iteration, spec.uncertainty):
                continue
            if step == "train":
                fresh = not is_started(model)
            self._note(logf, f"{step}{' (fresh start)' if fresh and step == 'train' else ''}, "
                             f"{spec.threads} thread(s): {subprocess.list2cmdline(argv)}")
            logf.flush()
            start = logf.tell()
            ran = True
            # The child inherits the lock, so it stays held if this process dies while the child still works.
            self._child = subprocess.Popen(argv, stdout=logf, stderr=subprocess.STDOUT, env=env, cwd=spec.root,
                                           pass_fds=(lock_fd,))
            code = self._child.wait()
            self._child = None
            if code != 0:
                logf.flush()
                with open(spec.log_path) as fh:
                    fh.seek(start)
                    line = error_line(fh.read())
                self._note(logf, f"{step} failed (exit {code})")
                return {"state": "failed", "error": f"{step}: {line}", "fresh": fresh, "ran": ran}
        return {"state": "done", "error": "", "fresh": fresh, "ran": ran}

    def _device(self) -> str:
        if self.spec.device != "auto":
            return self.spec.device
        import torch  # only here: the runner's machine may differ from the job's
        return "cuda" if torch.cuda.is_available() else "cpu"

    @staticmethod
    def _note(logf, message: str) -> None:
        logf.write(f"[grid {time.strftime('%Y-%m-%d %H:%M:%S')}] {message}\n")
        logf.flush()

    def _stop_child(self) -> None:
        """Terminate a running CLI (its stage checkpoints stay on disk) and reap it.

        Reaped with os.waitpid, not Popen.wait: in submitit's signal handler the interrupted Popen.wait still
        holds the Popen's wait lock, and a second Popen.wait would spin until its timeout.
        """
        child, self._child = self._child, None
        if child is None or child.returncode is not None:
            return
        child.send_signal(signal.SIGTERM)
        deadline = time.time() + 30
        try:
            while os.waitpid(child.pid, os.WNOHANG)[0] == 0:
                if time.time() > deadline:
                    child.kill()
                    os.waitpid(child.pid, 0)
                    break
                time.sleep(0.05)
        except ChildProcessError:  # already reaped
            pass

    def checkpoint(self, *args: Any, **kwargs: Any):
        """submitit's preemption/timeout hook: stop train.py and requeue this job (it resumes from disk)."""
        self._stop_child()
        return super().checkpoint(*args, **kwargs)


def train_command(spec: JobSpec) -> str:
    return shlex.join(spec.commands(spec.device)[0][1])


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
