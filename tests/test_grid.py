"""scripts/grid.py: job expansion against the paper's protocols, the generated sbatch text, bad input, skip / resume /
failure handling and SIGKILL-and-rerun with a fake interpreter (fast), and a tiny grid end to end through the real
CLIs with the local launcher."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from active import build_selector, list_selectors
from active.oracle_counts import mean_rounded_up, schedule_counts
from active.registry import selector_options
from active.schedule import farthest_point_views, plan_stages
from experiments import grid_args
from experiments.protocols import PROTOCOLS, RunScale, expand, stage_view_sum
from tests.conftest import ROOT
from tests.fake_cli import calls, make_fake, option
from utils.errors import UserError



def takes_eps(method: str) -> bool:
    return "eps" in selector_options(method)


def grid(*args: str, env: dict | None = None, timeout: int = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "scripts" / "grid.py"), *args], capture_output=True, text=True,
                          env=env or {**os.environ, "PYTHONPATH": str(ROOT)}, timeout=timeout)


# The paper's protocols (Setups 1-4 and the SSG ablation): seed views, K values, budget, iterations per view per
# stage, total iterations, eps values of lite_gs per K.
PAPER = {"setup1": (2, (3,), 11, 100, 11_000, {3: {0.1}}),
         "setup2": (5, (4,), 21, 300, 21_000, {4: {0.1}}),
         "setup3": (3, (4,), 15, 100, 11_000, {4: {0.1}}),
         "setup4": (3, (3, 4, 6), 15, 300, 15_000, {3: {0.1}, 4: {0.1}, 6: {0.1, 0.3, 0.6}}),
         "ablation_ssg": (3, (4,), 15, 300, 15_000, {4: {0.1, 0.2, 0.25, 0.4, 0.6}}),
         # FisherRF's scripts/blender_seq1.sh and mip360_seq1.sh with schema v20seq1_inplace (active/schema.py)
         "fisherrf20": (4, (1,), 20, 100, 30_000, {1: {0.1}}),
         "fisherrf20_360": (4, (1,), 20, 100, 20_000, {1: {0.1}})}


@pytest.mark.parametrize("setup", list(PAPER))
def test_expansion_matches_the_paper_protocols(setup):
    n0, ks, vmax, ipv, total, lite_eps = PAPER[setup]
    methods = ["random", "pop_gs", "lite_gs", "ssg"]
    runs = expand(setup, ["ship", "lego"], methods, 3, 0.1, takes_eps)
    per_scene_seed = sum(len(ks) if not takes_eps(m) else sum(len(e) for e in lite_eps.values()) for m in methods)
    assert len(runs) == 2 * 3 * per_scene_seed
    assert len({r.key for r in runs}) == len(runs)  # no two runs share a directory
    for r in runs:
        args = r.schedule_args(PROTOCOLS[setup], RunScale(iter_scale=1.0))
        assert [option(args, f) for f in ("--num_init_views", "--max_views", "--iters_per_view", "--iterations")] \
            == [str(n0), str(vmax), str(ipv), str(total)]
        assert int(option(args, "--views_per_step")) == r.k and r.k in ks
        assert ("--eps" in args) == takes_eps(r.method) == (r.eps is not None)
    for k, eps_values in lite_eps.items():
        assert {r.eps for r in runs if r.method == "lite_gs" and r.k == k} == eps_values
    tags = {r.tag for r in runs if r.scene == "ship" and r.seed == 0}
    if setup == "setup4":
        assert {"random_k3", "pop_gs_k6", "lite_gs_k4", "lite_gs_k6_eps0.3", "ssg_k6_eps0.6"} <= tags
    elif setup == "ablation_ssg":
        assert tags == {f"{m}_eps{e:g}" for m in ("lite_gs", "ssg") for e in lite_eps[4]} | {"random", "pop_gs"}
    else:
        assert tags == set(methods)


def fisherrf_seed_views(centers: torch.Tensor, n: int) -> list[int]:
    """FisherRF's VNSeqMInplace seeding, transcribed: view 0, then the candidate farthest from the chosen set."""
    chosen, candidates = [0], list(range(1, len(centers)))
    while len(chosen) < n:
        dist = torch.cdist(centers[candidates], centers[chosen]).min(dim=1).values
        chosen.append(candidates.pop(int(dist.argmax())))
    return chosen


def test_fisherrf_protocol_schedule_and_seeds():
    """Views added at FisherRF's iterations (100 x |train| after each stage: 400, 900, 1500, ..., 18,400) and the
    same seed views as FisherRF's seeding on random and on ring-shaped (tied) camera layouts."""
    p = PROTOCOLS["fisherrf20"]
    plan = plan_stages(p.num_init_views, p.ks[0], p.max_views, 100, p.iters_per_view, p.iterations)
    assert plan.adds == (1,) * 16
    assert plan.stage_end[:3] == (400, 900, 1500) and plan.stage_end[15] == 18_400 and plan.stage_end[16] == 30_000
    g = torch.Generator().manual_seed(0)
    ring = torch.stack([torch.cos(torch.arange(12) * 0.5236), torch.sin(torch.arange(12) * 0.5236),
                        torch.zeros(12)], 1).double()
    for centers in (torch.randn(100, 3, generator=g, dtype=torch.float64), ring):
        assert farthest_point_views(centers, 4) == fisherrf_seed_views(centers, 4)


def test_eps_naming_and_scaling():
    runs = expand("setup1", ["lego"], ["random", "lite_gs"], 1, 0.3, takes_eps)
    assert [r.tag for r in runs] == ["random", "lite_gs_eps0.3"]  # a non-default eps gets its own directory
    runs = expand("setup4", ["ship"], ["lite_gs"], 1, 0.3, takes_eps)
    assert [r.tag for r in runs] == ["lite_gs_k3_eps0.3", "lite_gs_k4_eps0.3", "lite_gs_k6_eps0.3", "lite_gs_k6_eps0.6"]
    # 100 * 0.025 = 2.5 rounds half up to 3; 300 * 0.001 = 0.3 -> at least 1
    assert RunScale(iter_scale=0.025).scaled(100) == 3 and RunScale(iter_scale=0.001).scaled(300) == 1
    args = runs[0].schedule_args(PROTOCOLS["setup4"], RunScale(iter_scale=0.01))
    assert [option(args, f) for f in ("--iters_per_view", "--iterations", "--densify_from_iter",
                                      "--opacity_reset_interval")] == ["3", "150", "5", "30"]


def test_slurm_dry_run_writes_the_sbatch_file(tmp_path):
    env, python, data, _ = make_fake(tmp_path)
    out = tmp_path / "out"
    r = grid("--setup", "setup4", "--data", str(data), "--scenes", "ship", "--methods", "pop_gs", "lite_gs",
             "--seeds", "2", "--out", str(out), "--launcher", "slurm", "--dry_run", "--slurm_partition", "gpu",
             "--gpus_per_job", "1", "--cpus_per_job", "6", "--time_min", "240", "--max_parallel", "4", env=env)
    assert r.returncode == 0, r.stderr
    assert "16 job(s), 16 to run, 6 thread(s) each" in r.stdout
    assert r.stdout.count("--method lite_gs --eps 0.6") == 2 and "--device auto" in r.stdout
    text = (out / "setup4" / "slurm_dry_run" / "array.sbatch").read_text()
    for line in ["#SBATCH --array=0-15%4", "#SBATCH --partition=gpu", "#SBATCH --gpus-per-node=1",
                 "#SBATCH --cpus-per-task=6", "#SBATCH --time=240", "#SBATCH --signal=USR2@90",
                 "#SBATCH --job-name=litegs_setup4", f"export PYTHONPATH={ROOT}",
                 f"-u -m submitit.core._submit {out / 'setup4' / '.submitit' / '%j'}"]:
        assert line in text, line
    assert text.startswith("#!/bin/bash") and "srun --unbuffered" in text
    assert not (out / "setup4" / "grid_status.json").exists()  # nothing ran


@pytest.mark.parametrize("args, expect", [
    (["--setup", "setup9"], "setup1, setup2, setup3, setup4, ablation_ssg"),
    (["--setup", "setup1", "--scenes", "lego", "chair"], "scenes in"),
    (["--setup", "setup1", "--methods", "pop_gs", "no_such"],
     "registered selectors: " + ", ".join(sorted(list_selectors()))),
    (["--setup", "setup1", "--max_parallel", "0"], "--max_parallel must be an integer >= 1"),
    (["--setup", "setup1", "--seeds", "0"], "--seeds"),
    (["--setup", "setup1", "--eps", "1"], "--eps"),
    (["--setup", "setup1", "--iter_scale", "-2"], "--iter_scale"),
    (["--setup", "setup1", "--device", "tpu"], "--device"),
    (["--setup", "setup1", "--launcher", "inline", "--max_parallel", "2"], "--launcher local"),
    (["--setup", "setup1", "--launcher", "slurm"], "use --dry_run"),
])
def test_bad_input_is_a_user_error(tmp_path, monkeypatch, args, expect):
    _, python, data, _ = make_fake(tmp_path)
    monkeypatch.setenv("PATH", "/usr/bin:/bin")  # no sbatch here
    with pytest.raises(UserError) as exc:
        grid_args.parse(["--data", str(data), "--out", str(tmp_path / "out"), "--python", str(python), *args])
    assert expect in str(exc.value) and "\n" not in str(exc.value), str(exc.value)
    if "chair" in args:
        assert "lego" in str(exc.value) and "ship" in str(exc.value)  # the scenes that exist


def test_bad_input_cli_is_one_error_line(tmp_path):
    env, python, data, log = make_fake(tmp_path)
    r = grid("--setup", "setup1", "--data", str(data), "--methods", "no_such", "--python", str(python), env=env)
    assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1 and r.stderr.startswith("error: ")
    assert not log.exists()


def test_skip_resume_failure_and_flag_mismatch(tmp_path):
    env, python, data, log = make_fake(tmp_path)
    out = tmp_path / "out"
    args = ["--setup", "setup1", "--data", str(data), "--scenes", "ship", "--methods", "pop_gs", "lite_gs",
            "--seeds", "2", "--out", str(out), "--python", str(python), "--iter_scale", "0.01", "--threads", "1",
            "--launcher", "local", "--max_parallel", "2", "--", "--sh_degree", "1"]
    r = grid(*args, env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    root = out / "setup1"
    keys = {f"ship/{m}/seed{s}" for m in ("pop_gs", "lite_gs") for s in (0, 1)}
    assert all((root / k / "results.json").is_file() and (root / "logs" / f"{k}.log").is_file() for k in keys)
    train = calls(log, "train.py")
    assert len(train) == 4 and len(calls(log, "render.py")) == 4 and len(calls(log, "metrics.py")) == 4
    for c in train:
        assert (option(c, "--iters_per_view"), option(c, "--iterations"), option(c, "--num_init_views")) \
            == ("1", "110", "2")
        assert "--white_background" in c and c[-3:] == ["--device", "cpu", "OMP_NUM_THREADS=1"]
        assert c[c.index("--quiet") + 1:c.index("--device")] == ["--sh_degree", "1"]
    assert r.stdout.count("failed] ship/") == 4 and "[4/4, 0 failed]" in r.stdout and "ETA" in r.stdout
    assert "| setup1 | pop_gs K=3 | ship | 2 | 0 |" in (root / "summary.md").read_text()

    def job_times(key):  # the states of a run's grid job invocations that worked on it
        return [r["state"] for r in json.loads((root / key / "grid_job_seconds.json").read_text())]
    assert all(job_times(k) == ["done"] for k in keys)

    # Rerun: finished jobs are skipped, one without results.json is rerun from its metrics step, a failing one
    # does not stop the others; the exit status is the number of failed jobs.
    log.unlink()
    (root / "ship/lite_gs/seed1/results.json").unlink()
    for f in ("results.json", "run_status.json"):
        (root / "ship/pop_gs/seed0" / f).unlink()
    r = grid(*args, env={**env, "FAKE_FAIL": str(root / "ship/pop_gs/seed0")})
    assert r.returncode == 1, r.stdout + r.stderr
    assert "2 to run" in r.stdout and "[4/4, 1 failed] " in r.stdout
    assert f"train: error: fake failure of {root / 'ship/pop_gs/seed0'} (log: {root / 'logs/ship/pop_gs/seed0.log'})" \
        in r.stdout
    assert "Traceback" not in r.stdout + r.stderr
    assert [option(c, "-m") for c in calls(log, "train.py")] == [str(root / "ship/pop_gs/seed0")]
    assert [option(c, "-m") for c in calls(log, "metrics.py")] == [str(root / "ship/lite_gs/seed1")]
    status = json.loads((root / "grid_status.json").read_text())
    states = {j["key"]: j["state"] for j in status["jobs"]}
    assert states == {"ship/pop_gs/seed0": "failed", "ship/pop_gs/seed1": "skipped", "ship/lite_gs/seed0": "skipped",
                      "ship/lite_gs/seed1": "done"}
    failed = next(j for j in status["jobs"] if j["state"] == "failed")
    assert failed["error"].startswith("train: error: fake failure") and failed["log"].endswith("pop_gs/seed0.log")
    assert "--method pop_gs" in failed["command"]
    assert job_times("ship/pop_gs/seed0") == ["done", "failed"] and job_times("ship/lite_gs/seed1") == ["done", "done"]
    assert job_times("ship/pop_gs/seed1") == ["done"]  # skipped: no invocation worked on it

    # Other flags on the same output directory: refused, naming the flag; nothing runs.
    log.unlink()
    r = grid(*[a if a != "0.01" else "0.02" for a in args], env=env)
    assert r.returncode == 2 and "--iter_scale 0.01" in r.stderr and "0.02" in r.stderr, r.stderr
    r = grid(*args[:-1], "2", env=env)
    assert r.returncode == 2 and "extra train.py flags" in r.stderr and "--sh_degree 1" in r.stderr, r.stderr
    assert not log.exists()


def test_uncertainty_rerun_adds_the_maps_to_finished_runs(tmp_path):
    """--uncertainty renders with render.py --uncertainty; on a finished grid it re-renders and re-scores each run
    (no training), and the summary gains the Spearman and AUSE columns."""
    env, python, data, log = make_fake(tmp_path)
    out = tmp_path / "out"
    args = ["--setup", "setup1", "--data", str(data), "--scenes", "ship", "--methods", "random", "--seeds", "2",
            "--out", str(out), "--python", str(python), "--iter_scale", "0.01", "--launcher", "inline"]
    r = grid(*args, env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    assert all("--uncertainty" not in c for c in calls(log, "render.py"))
    assert "AUSE" not in (out / "setup1" / "summary.md").read_text()
    log.unlink()
    r = grid(*args, "--uncertainty", env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "2 to run" in r.stdout and not calls(log, "train.py")
    renders = calls(log, "render.py")
    assert len(renders) == 2 and all("--uncertainty" in c for c in renders) and len(calls(log, "metrics.py")) == 2
    summary = (out / "setup1" / "summary.md").read_text()
    assert "| Spearman/fisherrf/object | AUSE_MAE_norm/fisherrf/object | LPIPS_variant |" in summary, summary
    assert "| 0.500 ± 0.000 | 0.0150 ± 0.0071 |" in summary, summary
    log.unlink()
    r = grid(*args, "--uncertainty", env=env)  # now finished with the maps: nothing runs
    assert r.returncode == 0 and "0 to run" in r.stdout and not log.exists(), r.stdout


def test_running_jobs_report_their_progress(tmp_path):
    """--progress_every S: a line per running job with the iteration and Gaussian count its run_status.json holds,
    also kept in grid_status.json."""
    env, python, data, log = make_fake(tmp_path)
    out = tmp_path / "out"
    r = grid("--setup", "setup1", "--data", str(data), "--scenes", "ship", "--methods", "random", "--out", str(out),
             "--python", str(python), "--iter_scale", "0.01", "--launcher", "local", "--progress_every", "0.3",
             env={**env, "FAKE_SLEEP": "2"})
    assert r.returncode == 0, r.stdout + r.stderr
    assert "running ship/random/seed0: iteration 7/110, 123 Gaussians (as of now)" in r.stdout, r.stdout
    job = json.loads((out / "setup1" / "grid_status.json").read_text())["jobs"][0]
    assert job["state"] == "done" and job["progress"]["iteration"] == 7
    r = grid("--setup", "setup1", "--data", str(data), "--progress_every", "0", env=env)
    assert r.returncode == 2 and "--progress_every must be a number > 0" in r.stderr


def test_runs_made_with_other_flags_are_refused(tmp_path):
    """A run directory from before the grid (no grid.json) whose cfg_args differ from what the grid would pass."""
    from training.config import parse_config
    env, python, data, log = make_fake(tmp_path)
    out = tmp_path / "out"
    args = ["--setup", "setup1", "--data", str(data), "--scenes", "lego", "--methods", "random", "--out", str(out),
            "--python", str(python), "--launcher", "inline", "--iter_scale", "0.05"]
    r = grid(*args, "--dry_run", env=env)
    assert r.returncode == 0, r.stderr
    argv = r.stdout.split("train.py ", 1)[1].split("\n")[0].split()
    model = Path(argv[argv.index("-m") + 1])
    model.mkdir(parents=True)
    cfg = parse_config(argv[:-2] + ["--iterations", "1100", "--device", "cpu"]).to_dict()
    (model / "cfg_args").write_text(json.dumps(cfg))
    r = grid(*args, env=env)
    assert r.returncode == 2 and str(model) in r.stderr and "--iterations 1100" in r.stderr, r.stderr
    assert "--iter_scale" in r.stderr and not log.exists()
    cfg["run"]["iterations"] = 550  # the flags it was made with: accepted and resumed
    (model / "cfg_args").write_text(json.dumps(cfg))
    r = grid(*args, env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    assert len(calls(log, "train.py")) == 1


def _summary_quality(root: Path) -> str:
    md = (root / "summary.md").read_text()
    return md.split("## Quality on the test views")[1].split("##")[0]


def test_sigkill_runner_then_rerun_finishes_without_rerunning_jobs(tmp_path):
    """SIGKILL the runner while jobs run; the same command finishes the grid, every run is trained once, and the
    summary equals an uninterrupted grid's."""
    env, python, data, log = make_fake(tmp_path)
    env = {**env, "FAKE_SLEEP": "1.5"}

    def args(out: Path) -> list[str]:
        return [sys.executable, str(ROOT / "scripts" / "grid.py"), "--setup", "setup1", "--data", str(data),
                "--scenes", "ship", "--methods", "random", "lite_gs", "--seeds", "2", "--out", str(out),
                "--python", str(python), "--threads", "1", "--launcher", "local", "--max_parallel", "2"]

    out = tmp_path / "killed"
    runner = subprocess.Popen(args(out), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    deadline = time.time() + 120
    while len(calls(log, "train.py")) < 3 and time.time() < deadline:  # two jobs done or going, a third started
        time.sleep(0.2)
    runner.send_signal(signal.SIGKILL)
    runner.wait()
    started = len(calls(log, "train.py"))
    assert 3 <= started <= 4
    r = subprocess.run(args(out), capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    trained = [option(c, "-m") for c in calls(log, "train.py")]
    assert len(trained) == len(set(trained)) == 4  # every run trained exactly once
    status = json.loads((out / "setup1" / "grid_status.json").read_text())
    assert status["counts"]["failed"] == 0 and status["counts"]["done"] + status["counts"]["skipped"] == 4

    log.unlink()
    r = subprocess.run(args(tmp_path / "whole"), capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert _summary_quality(out / "setup1") == _summary_quality(tmp_path / "whole" / "setup1")


def test_timeout_checkpoints_and_requeues(tmp_path, monkeypatch):
    """submitit's timeout signal reaches GridJob.checkpoint: train.py is stopped, the job requeued, and the requeued
    job resumes the run instead of starting it again (local executor, 3 s limit, signal 1 s before)."""
    import submitit
    from experiments.jobs import GridJob, JobSpec
    env, python, data, log = make_fake(tmp_path)
    for var, value in (("FAKE_LOG", env["FAKE_LOG"]), ("FAKE_SLEEP", "30"), ("PYTHONPATH", str(ROOT))):
        monkeypatch.setenv(var, value)  # the executor's processes inherit them
    model = tmp_path / "out" / "setup1" / "ship" / "random" / "seed0"
    spec = JobSpec(key="ship/random/seed0", model_dir=str(model), log_path=str(tmp_path / "job.log"),
                   python=str(python), root=str(ROOT), device="cpu", threads=1,
                   train_args=("-s", str(data / "ship"), "-m", str(model), "--seed", "0", "--method", "random",
                               "--num_init_views", "2", "--views_per_step", "3", "--max_views", "11",
                               "--iterations", "55"))
    executor = submitit.LocalExecutor(tmp_path / "submitit", max_num_timeout=5)
    executor.update_parameters(timeout_min=3 / 60, signal_delay_s=1)
    job = executor.submit(GridJob(spec))
    outcome = job.result()
    assert outcome["state"] == "done", outcome
    assert [option(c, "-m") for c in calls(log, "train.py")] == [str(model)] * 2  # stopped once, then resumed
    text = (tmp_path / "job.log").read_text()
    assert text.count("train (fresh start)") == 1 and text.count("] train, 1 thread(s)") == 1
    assert "Requeued" in (job.stdout() or "") + (job.stderr() or "") and (model / "results.json").is_file()


def test_inline_launcher(tmp_path):
    env, python, data, log = make_fake(tmp_path)
    r = grid("--setup", "ablation_ssg", "--data", str(data), "--out", str(tmp_path / "out"), "--python", str(python),
             "--methods", "ssg", "--launcher", "inline", "--iter_scale", "0.001", "--report", env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    report = tmp_path / "out" / "ablation_ssg" / "report.html"
    assert f"wrote {report}" in r.stdout and "ssg_eps0.25" in report.read_text()  # --report: the grid report
    assert {p.name for p in (tmp_path / "out" / "ablation_ssg" / "ship").iterdir()} == {
        f"ssg_eps{e}" for e in ("0.1", "0.2", "0.25", "0.4", "0.6")}
    assert {(option(c, "--iters_per_view"), option(c, "--iterations"), option(c, "--views_per_step"))
            for c in calls(log, "train.py")} == {("1", "15", "4")}


# Slow: the runner's layout, skip/resume and summary are covered with the fake CLIs above, and train.py ->
# render.py -> metrics.py by tests/test_train_e2e.py::test_train_render_metrics.
@pytest.mark.slow
def test_tiny_grid_end_to_end_local(tiny_scene, tmp_path):
    """2 methods x 2 seeds through the real train.py, render.py and metrics.py, two jobs at a time."""
    out = tmp_path / "out"
    r = grid("--setup", "setup1", "--data", str(tiny_scene.parent), "--scenes", tiny_scene.name, "--methods",
             "random", "pop_gs", "--seeds", "2", "--out", str(out), "--launcher", "local", "--max_parallel", "2",
             "--threads", "1", "--iter_scale", "0.005", "--num_points", "150", "--resolution", "-1", "--device", "cpu",
             "--", "--sh_degree", "1", timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    md = (out / "setup1" / "summary.md").read_text()
    for label in ("random K=3", "pop_gs K=3"):
        assert f"| setup1 | {label} | {tiny_scene.name} | 2 | 0 |" in md, label
    assert "Incomplete runs" not in md and "| conservative |" in md
    pop = mean_rounded_up(schedule_counts(build_selector("pop_gs"), 14, 2, 3, 11))
    assert f"| setup1 | {tiny_scene.name} | 3 | pop_gs |  | 2 | 6 | {pop} | {pop} |" in md
    sel = json.loads((out / "setup1" / tiny_scene.name / "pop_gs" / "seed1" / "selection.json").read_text())
    assert [s["oracle_calls"]["conservative"] for s in sel["stages"]] == [
        sum(s["candidates"] - j for j in range(3)) for s in sel["stages"]]
    status = json.loads((out / "setup1" / "grid_status.json").read_text())
    assert status["counts"]["done"] == 4 and status["threads_per_job"] == 1
    for job in status["jobs"]:
        text = Path(job["log"]).read_text()
        assert "train (fresh start), 1 thread(s)" in text and "rendered iteration 55" in text
        assert (Path(job["model_dir"]) / "results.json").is_file()
    r = grid("--setup", "setup1", "--data", str(tiny_scene.parent), "--scenes", tiny_scene.name, "--methods",
             "random", "pop_gs", "--seeds", "2", "--out", str(out), "--iter_scale", "0.005", "--num_points", "150",
             "--resolution", "-1", "--device", "cpu", "--", "--sh_degree", "1")
    assert r.returncode == 0 and "4 already finished, 0 to run" in r.stdout, r.stdout + r.stderr


def test_stage_scale_keeps_the_stages_and_scales_the_refinement():
    """--stage_scale 1 --iter_scale 0.1 on Setup 1: the paper's stages (100 v after 2, 5, 8 views = 1,500 iterations,
    densification from 500, opacity reset every 3,000) and a tenth of its refinement (11,000 - 1,500 = 9,500 -> 950);
    per K on Setup 4 (stages of 3, 7, 11 views at K = 4; 3, 9 at K = 6). Unset, everything follows --iter_scale."""
    assert stage_view_sum(PROTOCOLS["setup1"], 3) == 15 and stage_view_sum(PROTOCOLS["fisherrf20"], 1) == 184
    scale = RunScale(iter_scale=0.1, stage_scale=1.0)
    run = expand("setup1", ["lego"], ["lite_gs"], 1, 0.1, takes_eps)[0]
    args = run.schedule_args(PROTOCOLS["setup1"], scale)
    assert [option(args, f) for f in ("--iters_per_view", "--iterations", "--densify_from_iter",
                                      "--opacity_reset_interval")] == ["100", "2450", "500", "3000"]
    totals = {r.k: option(r.schedule_args(PROTOCOLS["setup4"], RunScale(iter_scale=0.01, stage_scale=0.1)),
                          "--iterations") for r in expand("setup4", ["ship"], ["pop_gs"], 1, 0.1, takes_eps)}
    # stages of 300 v x 0.1 = 30 v; refinement x 0.01. K = 3: views 3+6+9+12 = 30 -> 900 + 6,000 x 0.01 = 960;
    # K = 4: 3+7+11 = 21 -> 630 + 87 = 717; K = 6: 3+9 = 12 -> 360 + 114 = 474
    assert totals == {3: "960", 4: "717", 6: "474"}
    plain = run.schedule_args(PROTOCOLS["setup1"], RunScale(iter_scale=0.1))
    assert [option(plain, f) for f in ("--iters_per_view", "--iterations")] == ["10", "1100"]
    assert plain == run.schedule_args(PROTOCOLS["setup1"], RunScale(iter_scale=0.1, stage_scale=None))
