"""Where a result came from: the code (git commit, and whether tracked files differed from it), the machine, the
library versions, the thread count and the date. train.py records one such session per start or resume in
selection.json; the experiment summary prints them beside its tables.

    session_record(iteration=0, device="cpu")
    # {"started": "2026-12-03T05:40:12", "from_iteration": 0, "code": "593579e", "machine": "Linux-6.1-x86_64-...",
    #  "cpu": "Intel(R) Xeon(R) Processor", "cpus": 2, "threads": 2, "device": "cpu", "python": "3.11.9",
    #  "torch": "2.14.1"}
"""
from __future__ import annotations

import os
import platform
import subprocess
import time
from pathlib import Path
from typing import Any

import torch

UNKNOWN_CODE = "unknown"  # not a git checkout, or git missing
REPO_ROOT = Path(__file__).resolve().parents[1]  # the checkout this code runs from


def _git(root: Path, *args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10,
                              check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def code_version(root: str | os.PathLike) -> str:
    """The checkout's short commit, with "+changes" when tracked files differ from it; "unknown" outside git."""
    commit = _git(Path(root), "rev-parse", "--short=7", "HEAD")
    if not commit:
        return UNKNOWN_CODE
    changed = _git(Path(root), "status", "--porcelain", "--untracked-files=no")
    return commit + ("+changes" if changed else "")


def cpu_model() -> str:
    """The processor's name (/proc/cpuinfo on Linux, else what platform knows; "" when neither says)."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def environment_record(*, device: str, root: str | os.PathLike = REPO_ROOT) -> dict[str, Any]:
    """The code at `root` and this machine, now: date, commit, platform, CPUs, torch threads, device, versions."""
    return {"started": time.strftime("%Y-%m-%dT%H:%M:%S"), "code": code_version(root), "machine": platform.platform(),
            "cpu": cpu_model(), "cpus": os.cpu_count(), "threads": torch.get_num_threads(), "device": device,
            "python": platform.python_version(), "torch": torch.__version__.split("+")[0]}


def session_record(*, iteration: int, device: str, root: str | os.PathLike = REPO_ROOT) -> dict[str, Any]:
    """One training session (a start, or a resume at `iteration`): `environment_record` with the iteration."""
    return {"from_iteration": iteration, **environment_record(device=device, root=root)}
