"""The runs of a grid output folder (OUT/<setup>/<scene>/<tag>/seed<S>, scripts/grid.py), read for the grid report."""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from reports.run_data import latest
from utils.errors import UserError
from utils.io import read_json
from utils.model_dir import CFG_ARGS, RESULTS, RUN_STATUS, SELECTION

_SEED = re.compile(r"seed(\d+)")


@dataclass
class GridRun:
    """One run of the grid: where it is and what it recorded (None / empty where absent)."""
    scene: str
    tag: str
    seed: int
    path: Path
    curve: list[tuple[int, float]]      # (training views, test PSNR) per stage, then the final value
    results: dict[str, Any] | None      # last results.json entry
    complete: bool
    oracle_conservative: int | None     # summed over stages
    oracle_evaluated: int | None
    fisher_seconds: float | None
    select_seconds: float | None


def read_run(path: Path, scene: str, tag: str, seed: int) -> GridRun:
    """A `GridRun` from a model directory."""
    selection = read_json(path / SELECTION, missing="none") or {}
    status = read_json(path / RUN_STATUS, missing="none") or {}
    results_all = read_json(path / RESULTS, missing="none") or {}
    key = latest([Path(k) for k in results_all])
    results = results_all[key.name] if key is not None else None
    stages = selection.get("stages", [])
    curve = [(len(s["train_views"]), float(s["test_psnr"])) for s in stages if s.get("test_psnr") is not None]
    final = selection.get("final") or ({"train_views": status["train_views"]} if "train_views" in status else None)
    if final is not None:
        psnr = results["PSNR"] if results else final.get("test_psnr")
        if psnr is not None:
            curve.append((len(final["train_views"]), float(psnr)))

    def total(get) -> Any:
        values = [get(s) for s in stages]
        return sum(values) if stages and all(v is not None for v in values) else None
    return GridRun(scene, tag, seed, path, curve, results, status.get("status") == "complete",
                   total(lambda s: s.get("oracle_calls", {}).get("conservative")),
                   total(lambda s: s.get("oracle_calls", {}).get("evaluated")),
                   total(lambda s: s.get("fisher_seconds")), total(lambda s: s.get("select_seconds")))


def find_runs(setup_dir: str | Path) -> list[GridRun]:
    """Every run below a grid setup folder (a model directory has cfg_args), sorted by scene, tag, seed.

    Raises:
        UserError: the folder does not exist or holds no run.
    """
    setup_dir = Path(setup_dir)
    if not setup_dir.is_dir():
        raise UserError(f"{setup_dir} is not a directory; pass a grid output folder OUT/<setup> of scripts/grid.py")
    runs = []
    for cfg in sorted(setup_dir.glob(f"*/*/seed*/{CFG_ARGS}")):
        run_dir = cfg.parent
        m = _SEED.fullmatch(run_dir.name)
        if m:
            runs.append(read_run(run_dir, run_dir.parent.parent.name, run_dir.parent.name, int(m.group(1))))
    if not runs:
        raise UserError(f"no runs under {setup_dir} (looked for <scene>/<method>/seed<S>/{CFG_ARGS}); pass the "
                        "folder OUT/<setup> that scripts/grid.py wrote")
    return sorted(runs, key=lambda r: (r.scene, r.tag, r.seed))


def mean_curve(curves: list[list[tuple[int, float]]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and (population) std over seeds at each number of views any seed reached: (views, mean, std) [S]."""
    by_views: dict[int, list[float]] = {}
    for curve in curves:
        for views, psnr in curve:
            by_views.setdefault(views, []).append(psnr)
    x = np.array(sorted(by_views))
    values = [np.array(by_views[v]) for v in x]
    return x, np.array([v.mean() for v in values]), np.array([v.std() for v in values])


def mean_std(values: list[float | None]) -> tuple[float, float, int] | None:
    """(mean, population std, count) of the values that are not None; None when there are none."""
    got = np.array([v for v in values if v is not None], dtype=np.float64)
    return (float(got.mean()), float(got.std()), len(got)) if len(got) else None
