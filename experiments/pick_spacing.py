"""How close each selector's picks lie to the captured (seed) views, from a recommend-then-train results.json: per
method, the distance from its picks' camera centres to the nearest seed view's, divided by the median of that
distance over all candidates (1: a typical candidate; near 0: a view beside one already taken). CLI:
scripts/pick_spacing.py."""
from __future__ import annotations

from pathlib import Path

import torch

from experiments.seed_dataset import training_centers
from utils.io import read_json


def pick_spacing(results: dict, centers: torch.Tensor) -> dict[str, tuple[float, float]]:
    """Per method of `results` (recommend-then-train's results.json content; the first seed's picks): (nearest,
    mean) pick distance to the seed views over the candidates' median. `centers`: training camera centres [V, 3]."""
    seeds = results["settings"]["seed_views"]
    nearest = torch.cdist(centers, centers[seeds]).min(dim=1).values  # [V]
    candidates = [v for v in range(len(centers)) if v not in seeds]
    median = float(nearest[candidates].median())
    spacing = {}
    for key, row in results.items():
        method = key.rpartition("/seed")[0]
        if key == "settings" or not row.get("picks") or method in spacing:
            continue
        picks = nearest[row["picks"]] / median
        spacing[method] = (float(picks.min()), float(picks.mean()))
    return spacing


def spacing_table(results_path: Path, data: Path) -> str:
    """A markdown table of `pick_spacing` for a results.json and its dataset."""
    spacing = pick_spacing(read_json(results_path, what="recommend-then-train results"), training_centers(data))
    lines = ["| method | nearest pick / median | mean pick / median |", "|---|---|---|"]
    lines += [f"| {m} | {near:.2f} | {mean:.2f} |" for m, (near, mean) in spacing.items()]
    return "\n".join(lines) + "\n"
