"""scripts/pick_objective.py (experiments/pick_objective.py): the covered share of cover_pool's objective against
the objective written out; on a grid run, the replayed first acquisition's cover_pool picks are the run's recorded
picks and coverage's are a coverage run's; its table and its bad input."""
import json
import subprocess
import sys

import pytest
import torch

from experiments.pick_objective import covered_share
from scene.gaussian_model import GaussianModel
from tests.conftest import ROOT
from tests.test_cover_pool import reference_objective
from tests.test_fisher_cache import spiral_cameras
from tests.test_selection_fit import ENV, script, tiny_grid


def test_covered_share_is_the_objective_drop_written_out():
    g = torch.Generator().manual_seed(3)
    means = (torch.rand(25, 3, generator=g, dtype=torch.float64) * 2 - 1) * 1.2  # [25, 3]
    logits = torch.randn(25, generator=g, dtype=torch.float64)
    gaussians = GaussianModel(0, {"means": means, "logit_opacities": logits})
    cams = spiral_cameras(10)
    before = reference_objective(means, torch.sigmoid(logits), cams, [0])
    after = reference_objective(means, torch.sigmoid(logits), cams, [0, 4, 7])
    assert covered_share(gaussians, cams, [0], [4, 7]) == pytest.approx((before - after) / before, rel=1e-9)


@pytest.mark.slow
def test_a_grid_run_replays_to_its_recorded_picks(tiny_scene, tmp_path):
    run = tiny_grid(tiny_scene, tmp_path / "out", "cover_pool", "coverage") / "cover_pool" / "seed0"
    rows_path = tmp_path / "rows.json"
    r = script("pick_objective.py", str(run), "--json", str(rows_path))
    assert r.returncode == 0, r.stdout + r.stderr
    [row] = json.loads(rows_path.read_text())
    stage = json.loads((run / "selection.json").read_text())["stages"][0]
    assert row["captured"] == stage["train_views"] and row["cover_pool"]["picks"] == stage["selected"]
    coverage_run = json.loads((run.parents[1] / "coverage" / "seed0" / "selection.json").read_text())
    assert row["coverage"]["picks"] == coverage_run["stages"][0]["selected"]  # the same seed views, deterministic
    for name in ("cover_pool", "coverage"):
        assert 0.0 < row[name]["early"] <= 1.0 and 0.0 < row[name]["final"] <= 1.0
    r = script("pick_objective.py", "--table", str(rows_path))
    assert r.returncode == 0 and f"| {tiny_scene.name} | 1 | " in r.stdout, r.stdout + r.stderr


@pytest.mark.parametrize("args, expected", [
    ([], "pass finished grid run directories"),
    (["--table", "missing.json"], "missing.json not found"),
    (["--table", "damaged.json"], "objective rows damaged.json is not valid JSON"),
    (["seed0"], "seed0 is not a grid run directory"),
])
def test_bad_input_is_one_error_line(tmp_path, args, expected):
    (tmp_path / "damaged.json").write_text("[{")
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "pick_objective.py"), *args], capture_output=True,
                       text=True, env=ENV, cwd=tmp_path, timeout=120)
    assert r.returncode != 0 and r.stderr.strip().startswith("error:") and expected in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
