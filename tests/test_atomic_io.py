"""Atomic outputs (utils.io.atomic_write): a write that fails with a full disk (ENOSPC, injected) or a permission error
leaves no truncated or temporary file, keeps the old file, and is one `UserError` line naming the path, the bytes
being written and the free space."""
from __future__ import annotations

import errno
import json
import os
import stat

import plyfile
import pytest
import torch

import utils.io
from scene.ply_io import load_ply, save_ply
from tests.scenes import random_gaussians
from utils.errors import UserError
from tests.conftest import run_cli
from tests.test_resume import ARGS
from utils.io import atomic_write, save_torch, write_json


def ply_params(n: int, seed: int) -> dict[str, torch.Tensor]:
    p = random_gaussians(n, seed=seed, sh_degree=1, dtype=torch.float32)
    return {"means": p["means"], "quats": p["quats"], "log_scales": p["log_scales"],
            "logit_opacities": p["logit_opacities"], "sh_dc": p["sh_coeffs"][:, :1], "sh_rest": p["sh_coeffs"][:, 1:]}


def no_space(*_args, **_kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def assert_disk_error(err: pytest.ExceptionInfo, path) -> str:
    message = str(err.value)
    assert "\n" not in message, message
    assert str(path) in message and "no space left on device" in message, message
    assert "free there" in message and ("writing" in message or "failed after" in message), message
    return message


def leftovers(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


def test_ply_write_out_of_space_mid_body_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "point_cloud.ply"
    save_ply(path, ply_params(50, seed=0))
    before = path.read_bytes()

    def half_then_full(element, stream, text, byte_order):  # the vertex body: half of it reaches the disk
        data = element.data.astype(element.dtype(byte_order)).tobytes()
        stream.write(data[:len(data) // 2])
        no_space()
    monkeypatch.setattr(plyfile.PlyElement, "_write", half_then_full)
    with pytest.raises(UserError) as err:
        save_ply(path, ply_params(80, seed=1))
    message = assert_disk_error(err, path)
    assert "failed after" in message  # the bytes that reached the temporary file before the disk filled
    assert path.read_bytes() == before and leftovers(tmp_path) == []
    monkeypatch.undo()
    params, _ = load_ply(path)
    assert params["means"].shape == (50, 3)


def test_new_ply_out_of_space_at_fsync_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(utils.io, "_fsync", no_space)
    with pytest.raises(UserError) as err:
        save_ply(tmp_path / "new.ply", ply_params(10, seed=0))
    assert_disk_error(err, tmp_path / "new.ply")
    assert list(tmp_path.iterdir()) == []


def test_json_write_out_of_space_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "selection.json"
    write_json(path, {"stages": [1, 2]})
    before = path.read_bytes()
    real_write = os.write

    def short_write(fd, data):  # the first chunk reaches the disk, then it is full
        if len(data) > 8:
            real_write(fd, bytes(data[:8]))
            no_space()
        return real_write(fd, data)
    monkeypatch.setattr(utils.io.os, "write", short_write)
    with pytest.raises(UserError) as err:
        write_json(path, {"stages": list(range(100))})
    monkeypatch.undo()
    message = assert_disk_error(err, path)
    size = len(json.dumps({"stages": list(range(100))}, indent=2)) + 1
    assert f"writing {utils.io._size(size)}" in message, message
    assert path.read_bytes() == before and leftovers(tmp_path) == []


def test_checkpoint_out_of_space_keeps_the_old_checkpoint(tmp_path, monkeypatch):
    path = tmp_path / "chkpnt.pt"
    save_torch(path, {"iteration": 1})
    monkeypatch.setattr(utils.io, "_fsync", no_space)
    with pytest.raises(UserError) as err:
        save_torch(path, {"iteration": 2, "x": torch.zeros(1000)})
    assert_disk_error(err, path)
    monkeypatch.undo()
    assert torch.load(path)["iteration"] == 1 and leftovers(tmp_path) == []


def test_permission_denied_is_one_line(tmp_path, monkeypatch):
    def denied(*_args, **_kwargs):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))
    monkeypatch.setattr(utils.io.tempfile, "mkstemp", denied)
    with pytest.raises(UserError) as err:
        write_json(tmp_path / "results.json", {})
    assert "permission denied" in str(err.value) and "results.json" in str(err.value)
    assert "\n" not in str(err.value)


def test_other_errors_propagate_without_a_temporary_file(tmp_path):
    def broken(tmp):
        with open(tmp, "w") as fh:
            fh.write("partial")
        raise ValueError("bug")
    with pytest.raises(ValueError):
        atomic_write(tmp_path / "x.json", broken)
    assert list(tmp_path.iterdir()) == []


def test_written_file_has_the_usual_mode_and_content(tmp_path):
    atomic_write(tmp_path / "a.txt", "héllo")
    assert (tmp_path / "a.txt").read_text(encoding="utf-8") == "héllo"
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o666 & ~mask  # not mkstemp's 0600


FULL_DISK_RUNNER = """
import atexit, errno, os, runpy, sys
import utils.io
limit, calls, real = int(sys.argv[1]), [0], utils.io._fsync
def fsync(fd):
    calls[0] += 1
    if calls[0] > limit:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    real(fd)
utils.io._fsync = fsync
atexit.register(lambda: print(f"fsyncs: {calls[0]}"))
sys.argv = ["train.py", *sys.argv[2:]]
runpy.run_path("train.py", run_name="__main__")
"""


@pytest.mark.slow
def test_full_disk_mid_run_is_one_line_and_the_resumed_run_matches_an_uninterrupted_one(tiny_scene, tmp_path):
    """train.py whose disk fills (ENOSPC injected at an fsync half-way through its writes) stops with one `error:`
    line; once space is back, the same command resumes and ends with the uninterrupted run's picks and metrics."""
    def train(model, limit):
        return run_cli("-c", FULL_DISK_RUNNER, str(limit), "-s", str(tiny_scene), "-m", str(model), *ARGS)

    ref = train(tmp_path / "ref", 10**9)
    assert ref.returncode == 0, ref.stderr
    total = int(ref.stdout.rsplit("fsyncs: ", 1)[1].split()[0])
    full = train(tmp_path / "full", total // 2)
    assert full.returncode == 2, full.stdout + full.stderr
    errors = [line for line in full.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "no space left on device" in errors[0] and "Traceback" not in full.stderr, full.stderr
    assert not list((tmp_path / "full").rglob("*.tmp"))
    assert json.loads((tmp_path / "full" / "run_status.json").read_text())["status"] == "running"
    resumed = train(tmp_path / "full", 10**9)
    assert resumed.returncode == 0 and "resuming from iteration" in resumed.stdout, resumed.stdout + resumed.stderr
    a, b = (json.loads((tmp_path / d / "selection.json").read_text()) for d in ("ref", "full"))
    assert [s["selected"] for s in a["stages"]] == [s["selected"] for s in b["stages"]]
    assert abs(a["final"]["test_psnr"] - b["final"]["test_psnr"]) < 1e-6
