"""Run directory bookkeeping: atomic checkpoints, newest-first resume, corrupt files reported clearly."""
import pytest
import torch

from utils.checkpoint import KEEP_CHECKPOINTS, RunDirectory
from utils.errors import UserError


def test_checkpoints_roundtrip_and_pruning(tmp_path):
    run = RunDirectory(tmp_path / "m")
    run.start({"a": 1})
    assert run.latest_checkpoint() is None
    for it in (10, 20, 30):
        run.save_checkpoint({"iteration": it, "x": torch.full((2,), float(it))})
    ckpt = run.latest_checkpoint()
    assert ckpt["iteration"] == 30 and torch.equal(ckpt["x"], torch.full((2,), 30.0))
    assert len(list((tmp_path / "m" / "checkpoints").iterdir())) == KEEP_CHECKPOINTS
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
