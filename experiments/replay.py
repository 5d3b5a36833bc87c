"""Replay a grid run from the train.py command scripts/grid.py logged: its config written elsewhere
(`logged_config`), the run opened again in a temporary directory from scratch or from a checkpoint (`reopened`), and
its model trained again up to the first selection (`first_acquisition`; the same machine replays the same floats).
Used by scripts/selection_fit.py, pick_objective.py, branch_pick.py and pick_information.py, which also read back
their saved rows here (`saved_rows`)."""
from __future__ import annotations

import contextlib
import shlex
import tempfile
from pathlib import Path
from typing import Any, Iterator

from tqdm import tqdm

from training.config import TrainConfig, parse_config
from training.engine import Run, close_run, open_run, train_stage
from utils.checkpoint import RunDirectory
from utils.errors import UserError
from utils.io import read_json

LAYOUT = "pass run directories of a scripts/grid.py output (ROOT/SETUP/SCENE/METHOD/SEED)"


def check_grid_run(run_dir: Path) -> None:
    """One error line unless `run_dir` has the depth of a grid run directory (ROOT/SETUP/SCENE/METHOD/SEED)."""
    if len(run_dir.parents) < 4:
        raise UserError(f"{run_dir} is not a grid run directory; {LAYOUT}")


def logged_argv(run_dir: Path) -> list[str]:
    """The train.py arguments scripts/grid.py logged for `run_dir` (ROOT/SETUP/SCENE/METHOD/SEED)."""
    check_grid_run(run_dir)
    setup_dir, scene, method, seed = run_dir.parents[2], run_dir.parents[1].name, run_dir.parent.name, run_dir.name
    log = setup_dir / "logs" / scene / method / f"{seed}.log"
    if not log.is_file():
        raise UserError(f"{log} not found; {LAYOUT}")
    first = log.read_text().splitlines()[:1]
    words = shlex.split(first[0].split(": ", 1)[-1]) if first else []
    start = next((i + 1 for i, w in enumerate(words) if w.endswith("train.py")), None)
    if start is None:
        raise UserError(f"{log} does not start with the train.py command scripts/grid.py logs; is it a grid log?")
    return words[start:]


def logged_config(run_dir: Path, model_path: str | Path, extra: tuple[str, ...] = ()) -> TrainConfig:
    """The config of `run_dir`'s logged train.py command, writing to `model_path`, quiet, `extra` flags after its own."""
    argv = logged_argv(run_dir)
    argv[argv.index("-m") + 1] = str(model_path)
    return parse_config([*argv, "--quiet", *extra])


@contextlib.contextmanager
def reopened(run_dir: Path, start: dict[str, Any] | None = None) -> Iterator[tuple[Run, TrainConfig]]:
    """`run_dir`'s logged command opened in a temporary directory, from scratch or resuming checkpoint `start` (e.g. an
    acquisition undone), and its config."""
    with tempfile.TemporaryDirectory() as tmp:
        cfg = logged_config(run_dir, tmp)
        if start is not None:
            RunDirectory(tmp).save_checkpoint({**start, "config": cfg.to_dict()})
        run = open_run(cfg, tmp)
        try:
            yield run, cfg
        finally:
            close_run(run)


@contextlib.contextmanager
def first_acquisition(run_dir: Path) -> Iterator[tuple[Run, TrainConfig]]:
    """The open run (scene, settings, state) trained again up to `run_dir`'s first acquisition, and its config."""
    with reopened(run_dir) as (run, cfg):
        train_stage(run, tqdm(disable=True))
        yield run, cfg


def saved_rows(path: Path, what: str) -> list[dict]:
    """The rows a replay script wrote with --json (one error line if the file is missing or damaged)."""
    if not path.is_file():
        raise UserError(f"{path} not found; write it first with --json")
    return read_json(path, kind=list, what=what, fix="write them again with --json")
