"""Run directory bookkeeping: atomic checkpoints, newest-first resume, corrupt files reported clearly, progress."""
import json

import pytest
import torch

from utils.checkpoint import RunDirectory
from utils.errors import UserError


def test_checkpoints_roundtrip_and_pruning(tmp_path):
    run = RunDirectory(tmp_path / "m")
    run.start({"a": 1})
    assert run.latest_checkpoint() is None
    for it in (10, 20, 30):
        run.save_checkpoint({"iteration": it, "x": torch.full((2,), float(it))})
    ckpt = run.latest_checkpoint()
    assert ckpt["iteration"] == 30 and torch.equal(ckpt["x"], torch.full((2,), 30.0))
    assert len(list((tmp_path / "m" / "checkpoints").iterdir())) == 2  # the newest two are kept
    assert not run.is_complete()
    run.finish({"iteration": 30})
    assert run.is_complete()


def test_corrupt_checkpoint_is_a_clear_error(tmp_path):
    run = RunDirectory(tmp_path / "m")
    run.start({})
    path = run.save_checkpoint({"iteration": 5})
    path.write_bytes(path.read_bytes()[:20])
    with pytest.raises(UserError, match="corrupt or truncated"):
        run.latest_checkpoint()


def test_unwritable_model_path(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(UserError, match="cannot write to model path"):
        RunDirectory(blocker / "sub").start({})


def test_overwrite_refuses_foreign_directory(tmp_path):
    (tmp_path / "precious.txt").write_text("keep me")
    with pytest.raises(UserError, match="not a model directory"):
        RunDirectory(tmp_path).clear()
    assert (tmp_path / "precious.txt").exists()


def test_training_records_its_progress_in_run_status(tiny_scene, tmp_path, monkeypatch):
    """While training, run_status.json says how far the run is (iteration, total, Gaussians); at the end it says
    complete. Progress written at every iteration here (PROGRESS_EVERY_S = 0), read back as each write lands."""
    from training import engine
    from training.config import parse_config
    seen = []
    real = RunDirectory.progress

    def recording(self, iteration, total_iterations, num_gaussians):
        real(self, iteration, total_iterations, num_gaussians)
        seen.append(json.loads(self.status_file.read_text()))
    monkeypatch.setattr(engine, "PROGRESS_EVERY_S", 0.0)
    monkeypatch.setattr(RunDirectory, "progress", recording)
    model = tmp_path / "m"
    engine.training(parse_config(["-s", str(tiny_scene), "-m", str(model), "--iterations", "12",
                                  "--num_random_points", "200", "--quiet", "--raster_backend", "compiled"]))
    assert [s["iteration"] for s in seen] == list(range(1, 13))
    assert all(s["status"] == "running" and s["total_iterations"] == 12 and s["num_gaussians"] > 0 for s in seen)
    assert json.loads((model / "run_status.json").read_text())["status"] == "complete"
