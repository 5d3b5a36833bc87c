"""How much of cover_pool's own objective its greedy picks cover, against coverage's farthest-camera picks, at a
grid run's first acquisition: the diagnosis behind `--pool_compare coverage` (docs/diagnosis.md). CLI:
scripts/pick_objective.py.

For a run directory, the first acquisition's model is trained again (`experiments.replay`), and from its captured
views both selectors pick the run's K: cover_pool (lazy greedy on the pool-coverage gain) and coverage (farthest
camera centres). Each set's drop of the objective, (F(S) - F(S + T)) / F(S), is measured over the Gaussians of the
model that chose (early) and over the run's final model (the geometry the captures end up explaining).
"""
from __future__ import annotations

import statistics
from collections import defaultdict
from pathlib import Path

from active.acquisition import run_selection
from active.pool_cover_oracle import PoolCoverageOracle
from active.registry import build_selector
from experiments.replay import first_acquisition, logged_argv
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from scene.trained import find_iteration
from training.acquisition import candidate_views
from utils.io import read_json
from utils.model_dir import point_cloud_ply

SELECTORS = ("cover_pool", "coverage")


def covered_share(gaussians: GaussianModel, cameras: list[Camera], captured: list[int], picks: list[int]) -> float:
    """(F(S) - F(S + T)) / F(S) of cover_pool's objective over `gaussians` (opacity weights): S the captured views,
    T the picks."""
    oracle = PoolCoverageOracle.for_model(gaussians, cameras, captured)
    before = oracle.objective()
    for view in picks:
        oracle.commit(view)
    return (before - oracle.objective()) / before


def final_model(run_dir: Path) -> GaussianModel:
    """The run's last saved model (point_cloud/iteration_N/point_cloud.ply, the largest N)."""
    return GaussianModel.load_ply(point_cloud_ply(run_dir, find_iteration(run_dir)))


def pick_objective(run_dir: Path) -> dict:
    """One row: scene, captured views, each selector's picks and covered share under the early and final model."""
    logged_argv(run_dir)  # a grid run: checked before anything is read
    stage = read_json(run_dir / "selection.json", what="selection record",
                      fix="pass a run that has acquired, trained with a selector")["stages"][0]
    final = final_model(run_dir)
    row = {"run": str(run_dir), "scene": run_dir.parents[1].name, "captured": stage["train_views"]}
    with first_acquisition(run_dir) as (run, cfg):
        captured = run.state.train_views
        cameras = run.scene.train_cameras
        candidates = candidate_views(run.state, run.scene, cfg)
        for name in SELECTORS:
            picks = run_selection(build_selector(name), run.state.gaussians, cameras, captured, candidates,
                                  len(stage["selected"]), run.background, run.settings).selection.ids
            row[name] = {"picks": picks,
                         "early": covered_share(run.state.gaussians, cameras, captured, picks),
                         "final": covered_share(final, cameras, captured, picks)}
    return row


def objective_table(rows: list[dict]) -> str:
    """Markdown: per scene, the mean covered share of each selector's picks (early and final model) and the runs in
    which coverage's picks cover more than cover_pool's."""
    scenes: dict[str, list[dict]] = defaultdict(list)
    for row in rows:
        scenes[row["scene"]].append(row)
    lines = ["| scene | runs | cover_pool, early model | coverage, early | coverage ahead (early) | cover_pool, final "
             "model | coverage, final | coverage ahead (final) |", "|---|---|---|---|---|---|---|---|"]
    for scene, group in sorted(scenes.items()):
        cells = []
        for model in ("early", "final"):
            greedy = [r["cover_pool"][model] for r in group]
            spread = [r["coverage"][model] for r in group]
            ahead = sum(s > g for g, s in zip(greedy, spread))
            cells += [f"{statistics.mean(greedy):.4f}", f"{statistics.mean(spread):.4f}", f"{ahead} / {len(group)}"]
        lines.append(f"| {scene} | {len(group)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
