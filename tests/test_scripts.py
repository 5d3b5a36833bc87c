"""Experiment scripts (scripts/setup*.sh, ablation_ssg.sh via common.sh): option errors, the run loop's directory
layout, iteration scaling, skip / resume / continue-after-failure, driven by a fake interpreter that records each
CLI call; and (slow) a miniature Setup 1 end to end with the real train.py, render.py and metrics.py."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from active import build_selector
from active.oracle_counts import mean_rounded_up, schedule_counts
from tests.conftest import ROOT

POOL = 20  # training views of the fake scenes

# Stands in for the Python interpreter ($PYTHON): records train/render/metrics calls as JSON lines in $FAKE_LOG
# and writes the files the real CLIs would write (selection.json with closed-form counts, results.json); a model
# path listed in $FAKE_FAIL makes train.py fail. `-c` snippets and summarize.py run for real.
FAKE = r'''#!{python}
import argparse, json, os, sys
from pathlib import Path
args = sys.argv[1:]
if args[0] == "-c" or args[0].endswith("summarize.py"):
    os.execv(sys.executable, [sys.executable] + args)
with open(os.environ["FAKE_LOG"], "a") as fh:
    fh.write(json.dumps([Path(args[0]).name] + args[1:]) + "\n")
p = argparse.ArgumentParser()
for name in ["-s", "-m", "-r", "--device", "--seed", "--method", "--eps", "--num_init_views", "--views_per_step",
             "--max_views", "--iters_per_view", "--iterations", "--num_random_points"]:
    p.add_argument(name)
a, _ = p.parse_known_args(args[1:])
model = Path(a.m)
if Path(args[0]).name == "train.py":
    if str(model) in os.environ.get("FAKE_FAIL", "").split(":"):
        sys.exit(1)
    import math  # closed-form counts written out here (importing the active package would import torch)
    def step_count(method, m, k, eps):
        if method == "pop_gs":
            return sum(m - j for j in range(k))
        if method == "lite_gs":
            return sum(min(m - j, max(1, math.floor((m - j) * math.log(1 / eps) / k))) for j in range(k))
        if method == "ssg":
            p = min(m, max(k, math.floor(m * math.log(1 / eps) / k)))
            return sum(p - j for j in range(k))
        return 0
    n0, k, vmax, eps = int(a.num_init_views), int(a.views_per_step), int(a.max_views), float(a.eps)
    views, stages = list(range(n0)), []
    while len(views) < vmax:
        step = min(k, vmax - len(views))
        count = step_count(a.method, {pool} - len(views), step, eps)
        stages.append({{"train_views": list(views), "candidates": {pool} - len(views),
                       "selected": list(range(len(views), len(views) + step)), "test_psnr": 10.0,
                       "oracle_calls": {{"conservative": count, "evaluated": count}},
                       "fisher_seconds": 0.0, "select_seconds": 0.0}})
        views += stages[-1]["selected"]
    model.mkdir(parents=True, exist_ok=True)
    options = {{"eps": eps}} if a.method in ("lite_gs", "ssg") else {{}}
    (model / "selection.json").write_text(json.dumps({{"config": {{"method": a.method, "selector_options": options,
        "views_per_step": k, "seed": int(a.seed)}}, "stages": stages}}))
    (model / "run_status.json").write_text('{{"status": "complete"}}')
elif Path(args[0]).name == "metrics.py":
    (model / "results.json").write_text(json.dumps({{"ours_5": {{"PSNR": 20.0, "SSIM": 0.8, "LPIPS": None}}}}))
'''


@pytest.fixture
def fake(tmp_path):
    """(env, data root, log path): a fake interpreter, and a data root with Blender-like scenes ship and lego."""
    python = tmp_path / "fake_python"
    python.write_text(FAKE.format(python=sys.executable, pool=POOL, root=ROOT))
    python.chmod(0o755)
    data = tmp_path / "data"
    for scene in ("ship", "lego"):
        (data / scene).mkdir(parents=True)
        (data / scene / "transforms_train.json").write_text("{}")
    log = tmp_path / "calls.jsonl"
    env = {**os.environ, "PYTHON": str(python), "FAKE_LOG": str(log), "PYTHONPATH": str(ROOT)}
    return env, data, log


def script(name: str, *args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(ROOT / "scripts" / name), *args], capture_output=True, text=True,
                          env=env, timeout=300)


def calls(log: Path, cli: str) -> list[list[str]]:
    if not log.exists():
        return []
    return [c for c in map(json.loads, log.read_text().splitlines()) if c[0] == cli]


def option(call: list[str], name: str) -> str:
    return call[call.index(name) + 1]


def test_missing_scene_is_one_line_listing_the_scenes(fake, tmp_path):
    env, data, log = fake
    r = script("setup1.sh", "--data", str(data), "--out", str(tmp_path / "out"), "--scenes", "lego chair", env=env)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("error: ")
    assert "chair" in r.stderr and "lego" in r.stderr and "ship" in r.stderr  # the scenes found
    assert not log.exists()  # nothing ran


@pytest.mark.parametrize("args", [["--bogus"], ["--seeds", "0"], ["--eps", "1"], ["--iter_scale", "-2"],
                                  ["--device", "tpu"], ["--out"]])
def test_bad_options_are_one_line_errors(fake, args):
    env, data, _ = fake
    r = script("setup2.sh", "--data", str(data), *args, env=env)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and r.stderr.startswith("error: "), r.stderr


def test_setup4_layout_scaling_skip_resume_and_failure(fake, tmp_path):
    env, data, log = fake
    out = tmp_path / "out"
    args = ["--data", str(data), "--out", str(out), "--scenes", "ship", "--methods", "pop_gs lite_gs", "--seeds", "2",
            "--iter_scale", "0.01", "--device", "cpu"]
    r = script("setup4.sh", *args, env=env)
    assert r.returncode == 0, r.stderr
    tags = {"pop_gs_k3", "pop_gs_k4", "pop_gs_k6", "lite_gs_k3", "lite_gs_k4", "lite_gs_k6", "lite_gs_k6_eps0.3",
            "lite_gs_k6_eps0.6"}
    assert {p.name for p in (out / "setup4" / "ship").iterdir()} == tags
    assert all((out / "setup4" / "ship" / t / f"seed{s}" / "results.json").is_file() for t in tags for s in (0, 1))
    train = calls(log, "train.py")
    assert len(train) == 16 and len(calls(log, "render.py")) == 16 and len(calls(log, "metrics.py")) == 16
    for c in train:
        # 300 v and 15,000 scaled by 0.01; Blender scenes on white; protocol constants
        assert (option(c, "--iters_per_view"), option(c, "--iterations")) == ("3", "150")
        assert "--white_background" in c and (option(c, "--num_init_views"), option(c, "--max_views")) == ("3", "15")
        tag = Path(option(c, "-m")).parent.name
        assert option(c, "--views_per_step") == tag.split("_k")[1][0]
        assert option(c, "--eps") == (tag.split("eps")[1] if "eps" in tag else "0.1")
    md = (out / "setup4" / "summary.md").read_text()
    for k in (3, 4, 6):
        pop = mean_rounded_up(schedule_counts(build_selector("pop_gs"), POOL, 3, k, 15))
        assert f"| setup4 | ship | {k} | pop_gs |  | 2 |" in md and f"| {pop} | {pop} |" in md

    # Rerun: finished runs are skipped, an unfinished one (no results.json) is resumed, and a failing one does
    # not stop the others; the script then exits 1.
    log.unlink()
    (out / "setup4/ship/lite_gs_k4/seed1/results.json").unlink()
    (out / "setup4/ship/pop_gs_k3/seed0/results.json").unlink()
    r = script("setup4.sh", *args, env={**env, "FAKE_FAIL": str(out / "setup4/ship/pop_gs_k3/seed0")})
    assert r.returncode == 1 and "FAILED" in r.stderr and "1 run(s) failed" in r.stderr
    assert r.stdout.count("done, skipping") == 14
    assert [option(c, "-m") for c in calls(log, "train.py")] == [
        str(out / "setup4/ship/pop_gs_k3/seed0"), str(out / "setup4/ship/lite_gs_k4/seed1")]
    assert (out / "setup4/ship/lite_gs_k4/seed1/results.json").is_file()
    assert "pop_gs_k3/seed0`: no results.json" in (out / "setup4" / "summary.md").read_text()


def test_ablation_and_rounding(fake, tmp_path):
    env, data, log = fake
    r = script("ablation_ssg.sh", "--data", str(data), "--out", str(tmp_path / "out"), "--iter_scale", "0.001",
               "--device", "cpu", env=env)
    assert r.returncode == 0, r.stderr
    assert {p.name for p in (tmp_path / "out" / "ablation_ssg" / "ship").iterdir()} == {
        f"{m}_eps{e}" for m in ("lite_gs", "ssg") for e in ("0.1", "0.2", "0.25", "0.4")}
    train = calls(log, "train.py")
    # 300 * 0.001 = 0.3 -> at least 1; 15,000 * 0.001 = 15
    assert {(option(c, "--iters_per_view"), option(c, "--iterations"), option(c, "--views_per_step")) for c in train} \
        == {("1", "15", "4")}
    log.unlink()
    r = script("setup1.sh", "--data", str(data), "--out", str(tmp_path / "out"), "--iter_scale", "0.025",
               "--methods", "lite_gs", "--eps", "0.3", "--device", "cpu", env=env)
    assert r.returncode == 0, r.stderr
    (c,) = calls(log, "train.py")
    # 100 * 0.025 = 2.5 rounds half up to 3; a non-default eps gets its own directory
    assert (option(c, "--iters_per_view"), option(c, "--iterations")) == ("3", "275")
    assert option(c, "-m").endswith("setup1/lego/lite_gs_eps0.3/seed0")


def test_miniature_setup1_end_to_end(tiny_scene, tmp_path):
    """Setup 1 through the real CLIs on the 32 px built-in scene (14 training views), 55 iterations per run."""
    out = tmp_path / "out"
    env = {**os.environ, "PYTHON": sys.executable, "EXTRA_TRAIN_ARGS": "--sh_degree 1"}
    r = script("setup1.sh", "--data", str(tiny_scene.parent), "--out", str(out), "--scenes", tiny_scene.name,
               "--iter_scale", "0.005", "--num_points", "150", "--resolution", "-1", "--device", "cpu", env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    md = (out / "setup1" / "summary.md").read_text()
    for label in ("random K=3", "pop_gs K=3", "lite_gs K=3 eps=0.1"):
        assert f"| setup1 | {label} | {tiny_scene.name} | 1 | 0 |" in md, label
    for header in ("| PSNR |", "| SSIM |", "| LPIPS |", "| conservative |", "| evaluated |", "| reduction_% |",
                   "| select_s_per_run |"):
        assert header in md, header
    assert "Incomplete runs" not in md
    sel = json.loads((out / "setup1" / tiny_scene.name / "pop_gs" / "seed0" / "selection.json").read_text())
    for stage in sel["stages"]:
        m = stage["candidates"]
        assert stage["oracle_calls"]["conservative"] == sum(m - j for j in range(3))
    pop = mean_rounded_up(schedule_counts(build_selector("pop_gs"), 14, 2, 3, 11))
    assert f"| setup1 | {tiny_scene.name} | 3 | pop_gs |  | 1 | 3 | {pop} | {pop} |" in md
    assert all((out / "setup1" / f).is_file() for f in ("psnr_vs_views.png", "chosen_cameras.png", "summary.csv"))
