"""How well each model fitted its captured views when it chose, for grid runs made before selection.json recorded it.

    python scripts/selection_fit.py output/paper_stages_6seeds/setup1/mic/cover_pool/seed0 ... [--json rows.json]
    python scripts/selection_fit.py --table rows.json     # mean fit per scene and acquisition, from saved rows

For every run directory: the first acquisition's model is trained again from the run's logged train.py command
(`ROOT/SETUP/logs/SCENE/METHOD/SEEDn.log`, written by scripts/grid.py) up to that acquisition, in a temporary
directory; the later acquisitions' models are the stage checkpoints the run kept. For each, the mean PSNR over the
views captured at that acquisition (train fit) and over the test views; the replayed test PSNR must equal the run's
recorded stage value (the same machine replays the same floats), or the script stops. New runs record the train fit
themselves (selection.json, stage `train_psnr`).
"""
from __future__ import annotations

import argparse
import statistics
from collections import defaultdict
from pathlib import Path

import torch

from experiments.replay import first_acquisition, logged_argv, saved_rows
from training.state import fresh_state, restore_state
from training.step import mean_psnr
from utils.checkpoint import RunDirectory, load_checkpoint
from utils.errors import UserError, run_cli
from utils.io import read_json, write_json

REPLAY_TOLERANCE_DB = 1e-3


def stage_fits(run_dir: Path) -> list[dict]:
    """One row per acquisition of `run_dir`: stage, iteration, captured views, train fit, test PSNR (dB)."""
    logged_argv(run_dir)  # a grid run: checked before anything is read
    stages = read_json(run_dir / "selection.json", what="selection record",
                       fix="pass a run that has acquired, trained with a selector").get("stages", [])
    rows = []
    with first_acquisition(run_dir) as (run, cfg):
        models = {run.state.iteration: run.state.gaussians}
        for _, path in RunDirectory(run_dir).checkpoints():
            state = fresh_state(run.scene, cfg, [], run.plan.total_iterations)
            restore_state(state, load_checkpoint(path), cfg, run.scene)
            models[state.iteration] = state.gaussians
        for record in stages:
            gaussians = models.get(record["iteration"])
            if gaussians is None:
                continue  # a checkpoint the run did not keep
            cams = [run.scene.train_cameras[v] for v in record["train_views"]]
            row = {"run": str(run_dir), "stage": record["stage"], "iteration": record["iteration"],
                   "captured": len(cams),
                   "train_psnr": mean_psnr(gaussians, cams, run.background, run.settings),
                   "test_psnr": mean_psnr(gaussians, run.scene.test_cameras, run.background, run.settings)}
            if abs(row["test_psnr"] - record["test_psnr"]) > REPLAY_TOLERANCE_DB:
                raise UserError(f"{run_dir} stage {record['stage']}: replayed test PSNR {row['test_psnr']:.3f} "
                                f"dB, recorded {record['test_psnr']:.3f}: not the run's model (another machine "
                                "or code?)")
            rows.append(row)
    return rows


def fit_table(rows: list[dict]) -> str:
    """Markdown: the mean train fit over the runs of each scene (a run's SCENE folder) at each acquisition."""
    fits: dict[str, dict[tuple[int, int, int], list[float]]] = defaultdict(lambda: defaultdict(list))
    for row in rows:
        fits[Path(row["run"]).parents[1].name][(row["stage"], row["captured"], row["iteration"])].append(
            row["train_psnr"])
    stages = sorted({key for per_scene in fits.values() for key in per_scene})
    lines = ["| scene | runs | " + " | ".join(f"fit at {n} views, {it} it. (dB)" for _, n, it in stages) + " |",
             "|---|---|" + "---|" * len(stages)]
    for scene, per_scene in sorted(fits.items()):
        cells = [f"{statistics.mean(per_scene[key]):.2f}" if key in per_scene else "–" for key in stages]
        lines.append(f"| {scene} | {max(len(v) for v in per_scene.values())} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("runs", nargs="*", type=Path, help="run directories (ROOT/SETUP/SCENE/METHOD/SEED)")
    p.add_argument("--json", type=Path, help="also write the rows to this JSON file")
    p.add_argument("--table", type=Path, help="print the per-scene table of a rows file written by --json, run nothing")
    args = p.parse_args()
    if args.table:
        print(fit_table(saved_rows(args.table, "fit rows")))
        return
    if not args.runs:
        raise UserError("pass run directories (ROOT/SETUP/SCENE/METHOD/SEED), or --table ROWS.json")
    torch.set_num_threads(1)
    rows = []
    print("| run | stage | iteration | captured | train fit (dB) | test (dB) |\n|---|---|---|---|---|---|")
    for run_dir in args.runs:
        for row in stage_fits(run_dir):
            rows.append(row)
            print(f"| {row['run']} | {row['stage']} | {row['iteration']} | {row['captured']} | "
                  f"{row['train_psnr']:.2f} | {row['test_psnr']:.2f} |", flush=True)
    if args.json:
        write_json(args.json, rows)


if __name__ == "__main__":
    run_cli(main)
