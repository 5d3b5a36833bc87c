"""The experiment wrappers (scripts/setup*.sh, ablation_ssg.sh via common.sh) call scripts/grid.py with their setup:
option errors, the directory layout, iteration scaling and EXTRA_TRAIN_ARGS, with a fake interpreter for the CLIs.
The grid runner itself is tested in test_grid.py."""
import os
import shutil
import subprocess
import sys

import pytest

from active import build_selector
from active.oracle_counts import mean_rounded_up, schedule_counts
from tests.conftest import ROOT, run_cli
from tests.fake_cli import POOL, calls, make_fake, option


def script(name: str, *args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(ROOT / "scripts" / name), *args], capture_output=True, text=True,
                          env={**(env or os.environ), "PYTHON": sys.executable}, timeout=300)


def test_missing_scene_is_one_line_listing_the_scenes(tmp_path):
    env, python, data, log = make_fake(tmp_path)
    r = script("setup1.sh", "--data", str(data), "--out", str(tmp_path / "out"), "--scenes", "lego chair",
               "--python", str(python), env=env)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("error: ")
    assert "chair" in r.stderr and "lego" in r.stderr and "ship" in r.stderr  # the scenes found
    assert not log.exists()  # nothing ran


def test_setup4_wrapper_layout_scaling_and_extra_args(tmp_path):
    env, python, data, log = make_fake(tmp_path)
    out = tmp_path / "out"
    r = script("setup4.sh", "--data", str(data), "--out", str(out), "--scenes", "ship", "--methods", "pop_gs lite_gs",
               "--seeds", "2", "--iter_scale", "0.01", "--device", "cpu", "--python", str(python),
               env={**env, "EXTRA_TRAIN_ARGS": "--sh_degree 1"})
    assert r.returncode == 0, r.stdout + r.stderr
    tags = {"pop_gs_k3", "pop_gs_k4", "pop_gs_k6", "lite_gs_k3", "lite_gs_k4", "lite_gs_k6", "lite_gs_k6_eps0.3",
            "lite_gs_k6_eps0.6"}
    assert {p.name for p in (out / "setup4" / "ship").iterdir()} == tags
    assert all((out / "setup4" / "ship" / t / f"seed{s}" / "results.json").is_file() for t in tags for s in (0, 1))
    assert "(local, 1 at a time" in r.stdout  # the wrappers' default: one job after another
    train = calls(log, "train.py")
    assert len(train) == 16 and len(calls(log, "render.py")) == 16 and len(calls(log, "metrics.py")) == 16
    for c in train:
        # 300 v and 15,000 scaled by 0.01; Blender scenes on white; protocol constants; EXTRA_TRAIN_ARGS appended
        assert (option(c, "--iters_per_view"), option(c, "--iterations")) == ("3", "150")
        assert "--white_background" in c and (option(c, "--num_init_views"), option(c, "--max_views")) == ("3", "15")
        tag = os.path.basename(os.path.dirname(option(c, "-m")))
        assert option(c, "--views_per_step") == tag.split("_k")[1][0]
        if tag.startswith("lite_gs"):
            assert option(c, "--eps") == (tag.split("eps")[1] if "eps" in tag else "0.1")
        else:
            assert "--eps" not in c  # pop_gs takes no eps
        assert option(c, "--sh_degree") == "1"
    md = (out / "setup4" / "summary.md").read_text()
    for k in (3, 4, 6):
        pop = mean_rounded_up(schedule_counts(build_selector("pop_gs"), POOL, 3, k, 15))
        assert f"| setup4 | ship | {k} | pop_gs |  | 2 |" in md and f"| {pop} | {pop} | {pop} |" in md


def test_ablation_wrapper_dry_run(tmp_path):
    env, python, data, log = make_fake(tmp_path)
    r = script("ablation_ssg.sh", "--data", str(data), "--out", str(tmp_path / "out"), "--seeds", "2", "--dry_run",
               "--python", str(python), env=env)
    assert r.returncode == 0, r.stderr
    assert "20 job(s), 20 to run" in r.stdout  # lite_gs and ssg at 5 eps values, 2 seeds, on ship
    assert sum(line.startswith("ship/ssg_eps0.25/seed") for line in r.stdout.splitlines()) == 2
    assert not log.exists()


@pytest.mark.parametrize("wrapper", ["setup1.sh", "ablation_ssg.sh"])
def test_wrapper_without_venv_or_python_sets_up_the_environment(tmp_path, wrapper):
    # A fresh clone: no .venv, no PYTHON. The wrapper must take its interpreter from scripts/setup_env.sh (stubbed
    # here in a copy of scripts/: it prints a fake python that records its arguments), never a bare `python`.
    scripts = tmp_path / "clone" / "scripts"
    scripts.mkdir(parents=True)
    for name in ("common.sh", wrapper):
        shutil.copy(ROOT / "scripts" / name, scripts / name)
    log, python = tmp_path / "calls.txt", tmp_path / "venv-python"
    python.write_text(f'#!/usr/bin/env bash\necho "$@" >> {log}\n')
    python.chmod(0o755)
    (scripts / "setup_env.sh").write_text(f'echo "setup_env: stub" >&2\necho {python}\n')
    env = {k: v for k, v in os.environ.items() if k != "PYTHON"}
    r = subprocess.run(["bash", str(scripts / wrapper), "--scenes", "lego"], capture_output=True, text=True, env=env,
                       timeout=60)
    assert r.returncode == 0, r.stderr
    assert "setup_env: stub" in r.stderr
    assert log.read_text().startswith(f"{scripts / 'grid.py'} --setup ")


def test_bench_selection_without_a_model_is_one_error_line(tmp_path):
    """benchmarks/bench_selection.py (through run_cli) names the missing model and the way out, no traceback."""
    r = run_cli("benchmarks/bench_selection.py", "--model", str(tmp_path / "absent"))
    assert r.returncode != 0 and "Traceback" not in r.stderr
    assert "error:" in r.stderr and "quickstart" in r.stderr and "--model" in r.stderr
