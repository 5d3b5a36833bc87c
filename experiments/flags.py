"""A grid never mixes runs made with different flags: grid.json and each started run's cfg_args are checked against
the command line before anything runs."""
from __future__ import annotations

import shlex
from pathlib import Path
from typing import Any

from experiments.grid_config import GridConfig
from experiments.jobs import JobSpec
from utils.errors import UserError
from utils.io import read_json
from utils.model_dir import CFG_ARGS

RECORD = "grid.json"
# train.py config field -> the grid flag that sets it
SCALE_FLAGS = "--iter_scale / --stage_scale"
GRID_FLAG = {"resolution": "--resolution", "num_random_points": "--num_points", "iterations": SCALE_FLAGS,
             "iters_per_view": SCALE_FLAGS, "densify_from_iter": SCALE_FLAGS, "opacity_reset_interval": SCALE_FLAGS}


def check_flags(cfg: GridConfig, specs: list[JobSpec]) -> None:
    """Refuse an output directory holding runs made with other flags (grid.json, then each run's cfg_args)."""
    record = read_json(cfg.setup_dir / RECORD, missing="none", damaged="none")  # damaged: nothing to compare with
    if record is not None:
        for key, value in cfg.record().items():
            if key in record and record[key] != value:
                flag = "-- (extra train.py flags)" if key == "train_args" else f"--{key}"
                raise UserError(f"{cfg.setup_dir} holds runs made with {flag} {_show(record[key])}, this command "
                                f"has {_show(value)}; use another --out, or the same flags (runs made with "
                                "different flags are never mixed in one summary)")
    started = [(s, run) for s, run in zip(specs, cfg.runs) if (Path(s.model_dir) / CFG_ARGS).is_file()]
    if not started:
        return
    # imported here: torch and the selectors load only when some run has started (grid.py stays quick otherwise)
    from training.config import config_difference, parse_config  # the exact config train.py resolves
    for spec, run in started:
        saved = read_json(Path(spec.model_dir) / CFG_ARGS, missing="none", damaged="none")
        if saved is None:
            continue  # unreadable: train.py itself reports it
        expected = parse_config([*spec.train_args, "--device", "cpu"], notes=False).to_dict()
        difference = config_difference(saved, expected, run.method)
        if difference:
            name, old, value = difference
            flag = GRID_FLAG.get(name, "an extra train.py flag after --")
            raise UserError(f"{spec.model_dir} was trained with --{name} {_show(old)}, this grid asks for "
                            f"{_show(value)} (set by {flag}); use another --out, or the flags it was made "
                            "with (runs made with different flags are never mixed in one summary)")


def _show(value: Any) -> str:
    return shlex.join(value) if isinstance(value, list) else str(value)
