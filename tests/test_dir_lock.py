"""One writer per model directory (utils/dir_lock.py): a second writer is refused with one line naming the holder,
a lock whose holder died is taken over with a note, a released lock leaves no file behind; end to end, a second
train.py / render.py into the -m of a running train.py refuses within 2 s and the first run finishes complete."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from tests.conftest import ROOT
from utils import dir_lock
from utils.checkpoint import RunDirectory
from utils.errors import UserError
from utils.model_dir import LOCK_FILE, RUN_STATUS, SELECTION, folder_lock_file, point_cloud_ply

WAYS = "wait for it to finish, or pass a different -m"


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_second_writer_is_refused_with_the_holder(tmp_path):
    with dir_lock.writer_lock(tmp_path / "m", WAYS):
        lock = tmp_path / "m" / LOCK_FILE
        record = json.loads(lock.read_text())
        assert record["pid"] == os.getpid() and "command" in record
        with pytest.raises(UserError) as err:  # another open file description: conflicts even in this process
            dir_lock.acquire(lock, tmp_path / "m", WAYS)
        message = str(err.value)
        assert "\n" not in message
        assert str(tmp_path / "m") in message and f"pid {os.getpid()}" in message and WAYS in message
        assert record["command"] in message
    assert not (tmp_path / "m").exists()  # made for the lock, left empty: removed with it


def test_release_deletes_the_lock_file_and_keeps_a_filled_folder(tmp_path):
    folder = tmp_path / "m"
    with dir_lock.writer_lock(folder, WAYS):
        (folder / "cfg_args").write_text("{}")
    assert sorted(p.name for p in folder.iterdir()) == ["cfg_args"]


def test_reentrant_in_one_process(tmp_path):
    with dir_lock.writer_lock(tmp_path, WAYS):
        with dir_lock.writer_lock(tmp_path, WAYS):
            pass
        assert (tmp_path / LOCK_FILE).exists()  # still held by the outer block
    assert not (tmp_path / LOCK_FILE).exists()


def test_stale_lock_of_a_dead_process_is_taken_over_with_a_note(tmp_path, capsys):
    pid = dead_pid()
    (tmp_path / LOCK_FILE).write_text(json.dumps({"pid": pid, "command": "python train.py -m x"}))
    with dir_lock.writer_lock(tmp_path, WAYS):
        assert json.loads((tmp_path / LOCK_FILE).read_text())["pid"] == os.getpid()
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("note: ") and f"pid {pid}" in err[0], err
    assert "no longer running" in err[0] and "python train.py -m x" in err[0]


def test_missing_folder_is_not_created_without_create(tmp_path):
    with dir_lock.writer_lock(tmp_path / "nope", WAYS, create=False):
        pass
    assert not (tmp_path / "nope").exists()


def test_unwritable_folder_is_one_line(tmp_path):
    (tmp_path / "a_file").write_text("x")
    with pytest.raises(UserError, match="cannot write to"):
        with dir_lock.writer_lock(tmp_path / "a_file" / "m", WAYS):
            pass


def test_overwrite_clear_keeps_the_lock(tmp_path):
    (tmp_path / RUN_STATUS).write_text('{"status": "running"}')
    (tmp_path / "point_cloud").mkdir()
    with dir_lock.writer_lock(tmp_path, WAYS):
        RunDirectory(tmp_path).clear()
        assert [p.name for p in tmp_path.iterdir()] == [LOCK_FILE]


def test_a_folder_replaced_whole_is_locked_beside_it(tmp_path):
    out = tmp_path / "model" / "recommend"
    assert folder_lock_file(out) == tmp_path / "model" / ".recommend.lock"


def start(*args: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, *args], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


@pytest.mark.auto_backend  # the CLI's default backend, as a user runs it
def test_second_writer_refuses_fast_and_the_first_run_completes(tiny_scene, tmp_path):
    model = tmp_path / "m"
    args = ["-s", str(tiny_scene), "-m", str(model), "--eval", "--method", "lite_gs", "--num_init_views", "2",
            "--views_per_step", "3", "--max_views", "8", "--iters_per_view", "12", "--iterations", "400",
            "--num_random_points", "600", "--quiet", "--seed", "3"]
    first = start("train.py", *args)
    try:
        deadline = time.time() + 120
        while time.time() < deadline and not (model / "cfg_args").exists():  # the first run is training
            assert first.poll() is None, first.communicate()
            time.sleep(0.05)
        holder = json.loads((model / LOCK_FILE).read_text())
        assert holder["pid"] == first.pid
        for second_args in (["train.py", *args], ["render.py", "-m", str(model), "--quiet"]):
            t0 = time.perf_counter()
            second = start(*second_args)
            out, err = second.communicate(timeout=60)
            seconds = time.perf_counter() - t0
            assert first.poll() is None, "the first run ended before the second writer started; make it longer"
            lines = [ln for ln in err.splitlines() if ln.strip()]
            assert second.returncode == 2, (out, err)
            assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err, err
            assert str(model) in lines[0] and f"pid {first.pid}" in lines[0] and "train.py" in lines[0], lines[0]
            assert "wait for it to finish" in lines[0] and "-m" in lines[0], lines[0]
            assert ("--overwrite" in lines[0]) == (second_args[0] == "train.py"), lines[0]  # only train.py has it
            print(f"{second_args[0]} refused in {seconds:.2f} s")
            assert seconds < 2.0 + float(os.environ.get("LITEGS_LOCK_SLACK_S", "0")), f"{seconds:.2f} s"
        out, err = first.communicate(timeout=240)
        assert first.returncode == 0, err
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    status = json.loads((model / RUN_STATUS).read_text())
    assert status["status"] == "complete" and status["iteration"] == 400
    assert len(json.loads((model / SELECTION).read_text())["stages"]) == 2
    assert point_cloud_ply(model, 400).is_file()
    assert not (model / LOCK_FILE).exists()
    # the refused writers left no trace: the model equals one trained alone (same seed), byte for byte
    alone = tmp_path / "alone"
    run = start("train.py", *[str(alone) if a == str(model) else a for a in args])
    assert run.wait(timeout=240) == 0, run.communicate()
    assert point_cloud_ply(model, 400).read_bytes() == point_cloud_ply(alone, 400).read_bytes()
    picks = [[s["selected"] for s in json.loads((d / SELECTION).read_text())["stages"]] for d in (model, alone)]
    assert picks[0] == picks[1]
    files = [sorted(p.relative_to(d) for p in d.rglob("*")) for d in (model, alone)]
    assert files[0] == files[1]
