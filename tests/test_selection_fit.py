"""scripts/selection_fit.py: the fit on the captured views replayed for a grid run equals what the run recorded
(selection.json stage `train_psnr` and `test_psnr`), at the first acquisition (trained again from the logged command)
and at the later ones (from the stage checkpoints); its table and its bad input."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT

ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}


def script(name: str, *args: str, timeout: int = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "scripts" / name), *args], capture_output=True, text=True,
                          env=ENV, timeout=timeout)


def tiny_grid(scene: Path, out: Path, *methods: str, train_flags: tuple[str, ...] = ()) -> Path:
    """A one-seed Setup 1 grid of `methods` on the tiny scene (seconds; three acquisitions, with `train_flags`
    added to train.py's); returns its scene folder OUT/setup1/SCENE."""
    r = script("grid.py", "--setup", "setup1", "--data", str(scene.parent), "--scenes", scene.name,
               "--methods", *methods, "--seeds", "1", "--out", str(out), "--launcher", "local", "--threads", "1",
               "--iter_scale", "0.005", "--num_points", "150", "--resolution", "-1", "--device", "cpu", "--",
               "--sh_degree", "1", *train_flags)
    assert r.returncode == 0, r.stdout + r.stderr
    return out / "setup1" / scene.name


@pytest.mark.slow
def test_replayed_fit_equals_the_recorded_one(tiny_scene, tmp_path):
    run = tiny_grid(tiny_scene, tmp_path / "out", "coverage") / "coverage" / "seed0"
    rows_path = tmp_path / "rows.json"
    r = script("selection_fit.py", str(run), "--json", str(rows_path))
    assert r.returncode == 0, r.stdout + r.stderr
    rows = json.loads(rows_path.read_text())
    recorded = {s["stage"]: s for s in json.loads((run / "selection.json").read_text())["stages"]}
    assert rows[0]["stage"] == 0 and len(rows) >= 2  # the replayed first acquisition and at least one checkpoint
    for row in rows:
        stage = recorded[row["stage"]]
        assert row["captured"] == len(stage["train_views"]) and row["iteration"] == stage["iteration"]
        assert row["train_psnr"] == pytest.approx(stage["train_psnr"], abs=1e-4)
        assert row["test_psnr"] == pytest.approx(stage["test_psnr"], abs=1e-4)
    r = script("selection_fit.py", "--table", str(rows_path))
    assert r.returncode == 0 and f"| {tiny_scene.name} | 1 | " in r.stdout, r.stdout + r.stderr


@pytest.mark.parametrize("args, expected", [
    ([], "pass run directories"),
    (["--table", "missing.json"], "missing.json not found"),
    (["--table", "damaged.json"], "fit rows damaged.json is not valid JSON"),
    (["nowhere/setup1/scene/method/seed0"], "seed0.log not found"),
    (["seed0"], "seed0 is not a grid run directory"),
    (["grid/setup1/scene/method/seed1"], "does not start with the train.py command"),
])
def test_bad_input_is_one_error_line(tmp_path, args, expected):
    log = tmp_path / "grid" / "setup1" / "logs" / "scene" / "method" / "seed1.log"
    log.parent.mkdir(parents=True)
    log.write_text("not a grid log\n")
    (tmp_path / "damaged.json").write_text("[{")
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "selection_fit.py"), *args], capture_output=True,
                       text=True, env=ENV, cwd=tmp_path, timeout=120)
    assert r.returncode != 0 and r.stderr.strip().startswith("error:") and expected in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
