"""The model directory's run bookkeeping: status file, config, and atomic per-stage checkpoints."""
from __future__ import annotations

import os
import re
import shutil
import time
from pathlib import Path
from typing import Any

import torch

from utils.errors import UserError
from utils.io import read_json, save_torch, write_json
from utils.model_dir import CFG_ARGS, CHECKPOINTS_DIR, LOCK_FILE, RUN_STATUS, checkpoint_file

CHECKPOINT_FORMAT_VERSION = 1
_CKPT_RE = re.compile(r"^chkpnt_(\d+)\.pt$")
KEEP_CHECKPOINTS = 2  # by default the newest two: a fallback if the newest turns out unreadable (--keep_checkpoints)


class RunDirectory:
    """One model directory: `run_status.json` ("running" with the progress so far / "complete"), `cfg_args`,
    `checkpoints/`."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)

    @property
    def status_file(self) -> Path:
        return self.path / RUN_STATUS

    def status(self) -> dict[str, Any] | None:
        """The parsed status file, or None when there is none (or it is damaged: the run starts over)."""
        return read_json(self.status_file, missing="none", damaged="none")

    def is_complete(self) -> bool:
        status = self.status()
        return bool(status) and status.get("status") == "complete"

    def clear(self) -> None:
        """Delete a previous run in this directory (only if it looks like one of ours), keeping the writer lock
        (`LOCK_FILE`) that the caller holds."""
        if not self.path.is_dir():
            return
        entries = [p for p in self.path.iterdir() if p.name != LOCK_FILE]
        if not entries:
            return
        if not ((self.path / CFG_ARGS).exists() or self.status_file.exists()):
            raise UserError(f"--overwrite refused: {self.path} is not a model directory of this project "
                            "(no cfg_args / run_status.json); pick another -m/--model_path")
        for entry in entries:
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()

    def start(self, config: dict[str, Any]) -> None:
        """Create the directory and mark the run as running; fails with one line if it is not writable."""
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            write_json(self.status_file, {"status": "running"})
        except OSError as exc:
            raise UserError(f"cannot write to model path {self.path} ({exc.strerror}); "
                            "choose a writable -m/--model_path") from None
        write_json(self.path / CFG_ARGS, config)

    def progress(self, iteration: int, total_iterations: int, num_gaussians: int) -> None:
        """Record where a running run is (read by people and scripts watching a --quiet run, e.g. a grid job)."""
        write_json(self.status_file, {"status": "running", "iteration": iteration, "total_iterations": total_iterations,
                                      "num_gaussians": num_gaussians, "updated": time.strftime("%Y-%m-%d %H:%M:%S")})

    def finish(self, summary: dict[str, Any]) -> None:
        write_json(self.status_file, {"status": "complete", **summary})

    def checkpoints(self) -> list[tuple[int, Path]]:
        """(iteration, path) of the checkpoints kept, oldest first."""
        folder = self.path / CHECKPOINTS_DIR
        if not folder.is_dir():
            return []
        found = [(int(m.group(1)), p) for p in folder.iterdir() if (m := _CKPT_RE.match(p.name))]
        return sorted(found)

    def save_checkpoint(self, state: dict[str, Any], keep: int = KEEP_CHECKPOINTS) -> Path:
        """Write `checkpoints/chkpnt_<iteration>.pt` atomically and drop all but the newest `keep` (0: keep all)."""
        path = checkpoint_file(self.path, state["iteration"])
        save_torch(path, {"format_version": CHECKPOINT_FORMAT_VERSION, **state})
        for _, old in (self.checkpoints()[:-keep] if keep > 0 else []):
            old.unlink(missing_ok=True)
        return path

    def latest_checkpoint(self) -> dict[str, Any] | None:
        """The newest checkpoint, or None. A corrupt one is an error naming the file and the fix."""
        ckpts = self.checkpoints()
        return load_checkpoint(ckpts[-1][1]) if ckpts else None


def load_checkpoint(path: Path) -> dict[str, Any]:
    """A checkpoint file written by `RunDirectory.save_checkpoint`; a corrupt or unknown one is an error naming the
    file and the fix."""
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=False)
    except Exception:
        raise UserError(f"checkpoint {path} is corrupt or truncated; delete it to resume from the previous one, "
                        "or pass --overwrite to start again") from None
    if not isinstance(ckpt, dict) or ckpt.get("format_version") != CHECKPOINT_FORMAT_VERSION:
        raise UserError(f"checkpoint {path} has an unknown format (expected version {CHECKPOINT_FORMAT_VERSION}); "
                        "pass --overwrite to start again")
    return ckpt
