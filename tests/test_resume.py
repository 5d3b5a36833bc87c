"""A run killed (SIGKILL) in the middle of a stage resumes from its last checkpoint and ends exactly like an
uninterrupted run with the same seed; resumed with other flags, it is refused."""
import json
import os
import subprocess
import sys
import time

from tests.conftest import ROOT, run_cli

ARGS = ["--eval", "--method", "lite_gs", "--num_init_views", "2", "--views_per_step", "3", "--max_views", "8",
        "--iters_per_view", "12", "--iterations", "260", "--num_random_points", "600", "--quiet", "--seed", "3"]


def test_sigkill_then_resume_matches_uninterrupted(tiny_scene, tmp_path):
    ref, killed = tmp_path / "ref", tmp_path / "killed"
    assert run_cli("train.py", "-s", str(tiny_scene), "-m", str(ref), *ARGS).returncode == 0

    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "train.py", "-s", str(tiny_scene), "-m", str(killed), *ARGS], cwd=ROOT,
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline and not list((killed / "checkpoints").glob("chkpnt_*.pt")):
        time.sleep(0.05)
    proc.kill()  # SIGKILL right after the first stage checkpoint: the run dies inside stage 1
    proc.wait()
    assert proc.returncode != 0, "the run finished before it could be killed; make it longer"
    assert json.loads((killed / "run_status.json").read_text())["status"] == "running"

    # resumed with another value of a flag that decides the run: refused, the run left as it was
    other = [a if a != "lite_gs" else "pop_gs" for a in ARGS]
    for flags, line in ((other, "--method lite_gs, this call has pop_gs"),
                        ([*ARGS, "--eps", "0.3"], "--eps 0.1, this call has 0.3")):
        r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(killed), *flags)
        assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.strip().splitlines()[-1] == (
            f"error: {killed} was started with {line}: rerun it with the flags it started with to resume it (its "
            "cfg_args), or pass --overwrite to start it again"), r.stderr
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(killed), *ARGS)
    assert r.returncode == 0, r.stderr
    assert "resuming from iteration" in r.stdout
    a = json.loads((ref / "selection.json").read_text())
    b = json.loads((killed / "selection.json").read_text())
    assert [s["selected"] for s in a["stages"]] == [s["selected"] for s in b["stages"]]
    assert abs(a["final"]["test_psnr"] - b["final"]["test_psnr"]) < 1e-6
    # provenance: one session per start, the resumed one starting where the checkpoint left off
    assert len(a["sessions"]) == 1 and a["sessions"][0]["from_iteration"] == 0
    assert [s["from_iteration"] > 0 for s in b["sessions"]] == [False, True]
    assert b["sessions"][0]["started"] <= b["sessions"][1]["started"]
