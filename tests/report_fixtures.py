"""Hand-made inputs of the report tests: a recommend.py output folder and a grid folder built from a model dir."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
from PIL import Image

from scene.cameras import look_at


def orbit_c2w(angle_deg: float, radius: float = 4.0, height: float = 1.5) -> list[list[float]]:
    """Camera-to-world 4x4 (OpenCV axes) of a camera on a circle looking at the origin."""
    a = math.radians(angle_deg)
    viewmat = look_at([radius * math.cos(a), radius * math.sin(a), height]).numpy()
    return np.linalg.inv(viewmat).tolist()


def make_recommendation(folder: Path, model: Path | None, captured: bool) -> dict:
    """recommendations.json as recommend.py writes it (fields of docs/reports.md): 2 picks among 6 candidates
    (4 evaluated, 2 not), previews for pick 1 only; captured poses explicit or (captured=False) the model's
    prior.view_ids [0, 1]. Returns the record."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "previews").mkdir(exist_ok=True)
    rng = np.random.default_rng(0)
    for name in ("pick_01.png", "pick_01_uncertainty.png"):
        Image.fromarray(rng.integers(0, 255, (24, 32, 3), dtype=np.uint8)).save(folder / "previews" / name)
    intr = {"fx": 30.0, "fy": 30.0, "cx": 16.0, "cy": 12.0, "width": 32, "height": 24}
    picks = [{"rank": r + 1, "candidate": c, "name": f"orbit_{c:03d}", "gain": g, "visible_gaussians": 500,
              "c2w": orbit_c2w(60 * c), **intr, "preview": f"previews/pick_{r + 1:02d}.png",
              "uncertainty_map": f"previews/pick_{r + 1:02d}_uncertainty.png"}
             for r, (c, g) in enumerate([(3, 2.5), (0, 1.25)])]
    gains = {0: 1.25, 1: 0.5, 2: None, 3: 2.5, 4: 0.75, 5: None}
    candidates = [{"candidate": c, "name": f"orbit_{c:03d}", "gain": g, "evaluated": g is not None,
                   "rank": {3: 1, 0: 2}.get(c), "position": np.asarray(orbit_c2w(60 * c))[:3, 3].tolist()}
                  for c, g in gains.items()]
    record = {"model": str(model) if model else "/nonexistent/model", "selector": "lite_gs",
              "selector_options": {"eps": 0.1}, "k": 2, "k_taken": 2, "picks": picks, "candidate_gains": candidates,
              "prior": {"views": 2, "view_ids": [0, 1]}, "oracle_calls": {"conservative": 9, "evaluated": 7},
              "fisher_views_computed": 6, "seconds": {"fisher": 1.5, "gain": 0.25, "total": 2.0},
              "settings": {"seed": 0, "device": "cpu"}, "notes": ["hand-made test fixture"]}
    if captured:
        record["captured"] = [{"name": f"captured_{i}", "c2w": orbit_c2w(30 + 120 * i, 3.0), **intr}
                              for i in range(3)]
    (folder / "recommendations.json").write_text(json.dumps(record))
    return record


def make_grid(setup_dir: Path, model: Path) -> list[Path]:
    """A grid folder <scene>/<method>/seed<S> of copies of `model`: pop_gs seeds 0 and 1 (seed 1's PSNRs + 1 dB
    and oracle counts + 2 per stage) and random seed 0. Returns the run folders."""
    runs = []
    for tag, seed in (("pop_gs", 0), ("pop_gs", 1), ("random", 0)):
        run = setup_dir / "tiny" / tag / f"seed{seed}"
        shutil.copytree(model, run, ignore=shutil.ignore_patterns("checkpoints", "report.html"))
        if seed == 1:
            sel = json.loads((run / "selection.json").read_text())
            for s in sel["stages"]:
                s["test_psnr"] += 1.0
                s["oracle_calls"]["evaluated"] += 2
            (run / "selection.json").write_text(json.dumps(sel))
            res = json.loads((run / "results.json").read_text())
            for r in res.values():
                r["PSNR"] += 1.0
            (run / "results.json").write_text(json.dumps(res))
        runs.append(run)
    return runs
