"""The log-det information of a branch's picks against the run's own, on the model that chose them.

For a finished grid run and its branches (`experiments.branch`), at the branched acquisition: rho(S), the log-det
gain of a set of picks S over the run's prior then (its captured views), with the run's Fisher settings, for the
run's own picks and each branch's, on the acquisition's model (its checkpoint, the acquisition undone). The question
it answers: does the Fisher's own margin over another selector's picks, rho(S_branch) / rho(S_run) - 1, say which
of the two ends with the better test PSNR (docs/diagnosis.md)? CLI: scripts/pick_information.py.
"""
from __future__ import annotations

import contextlib
import statistics
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from active.fisher import build_oracle
from arguments import FisherSettings
from experiments.branch import acquisition_checkpoint, branch_dir, final_psnr, undo_last_acquisition
from experiments.replay import reopened
from training.engine import Run
from utils.io import read_json
from utils.model_dir import SELECTION
from utils.uncertainty_metrics import spearman


@contextlib.contextmanager
def model_at(run_dir: Path, stage: int | None) -> Iterator[tuple[Run, dict[str, Any]]]:
    """The run opened (in a temporary directory) as it stood before acquisition `stage` (None: its last), and that
    acquisition's record."""
    ckpt = acquisition_checkpoint(run_dir, stage)
    with reopened(run_dir, undo_last_acquisition(ckpt)) as (run, _):
        yield run, ckpt["stages"][-1]


def set_information(run: Run, picks: list[int]) -> float:
    """rho(S) = log det(H_0 + sum_S H_v) - log det H_0 over the block-diagonal Fisher: the picks' marginal gains
    summed in order (nats)."""
    oracle = build_oracle("logdet", run.state.gaussians, run.scene.train_cameras, run.state.train_views,
                          run.background, run.settings, fisher=FisherSettings.from_active(run.cfg.active))
    total = 0.0
    for view in picks:
        total += oracle.gain(view)
        oracle.commit(view)
    return total


def information_rows(runs: list[Path], specs: list[str], out: Path, stage: int | None = None) -> list[dict]:
    """One row per run and spec with a finished branch in `out`: both pick sets, their information, both PSNRs."""
    rows = []
    for run_dir in runs:
        branches = {spec: branch_dir(out, run_dir, spec, stage) for spec in specs}
        branches = {spec: d for spec, d in branches.items() if (d / SELECTION).is_file()
                    and read_json(d / SELECTION).get("final")}
        if not branches:
            continue
        with model_at(run_dir, stage) as (run, record):
            own = set_information(run, record["selected"])
            for spec, d in branches.items():
                picks = read_json(d / SELECTION)["stages"][record["stage"]]["selected"]
                rows.append({"scene": run_dir.parents[1].name, "source_method": run_dir.parent.name, "spec": spec,
                             "stage": record["stage"], "seed": int(run_dir.name[4:]), "run_picks": record["selected"],
                             "branch_picks": picks, "rho_run": own, "rho_branch": set_information(run, picks),
                             "psnr_run": final_psnr(run_dir), "psnr_branch": final_psnr(d)})
    return rows


def information_table(rows: list[dict]) -> str:
    """Markdown: per scene, source method and spec, the mean information margin of the branch's picks over the
    run's, the mean PSNR difference, and their Spearman correlation over the seeds (from 4 seeds)."""
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        groups.setdefault((row["scene"], row["source_method"], row["spec"], row["stage"]), []).append(row)
    lines = ["| scene | runs of | pick by | at acquisition | seeds | information margin, mean [min, max] | "
             "PSNR branch − run (mean) | Spearman(margin, PSNR difference) |", "|---|---|---|---|---|---|---|---|"]
    for (scene, method, spec, stage), members in sorted(groups.items()):
        margin = [r["rho_branch"] / r["rho_run"] - 1 for r in members]
        diff = [r["psnr_branch"] - r["psnr_run"] for r in members]
        rho = spearman(np.asarray(margin), np.asarray(diff)) if len(members) >= 4 else None
        lines.append(f"| {scene} | {method} | {spec} | {stage} | {len(members)} | {statistics.mean(margin):+.3f} "
                     f"[{min(margin):+.3f}, {max(margin):+.3f}] | {statistics.mean(diff):+.2f} | "
                     + ("–" if rho is None else f"{rho:+.2f}") + " |")
    return "\n".join(lines)
