"""experiments/summary.py (and its CLI scripts/summarize.py) on synthetic model directories with known values: every method and column present,
means/stds against numpy, oracle counts averaged over steps and rounded up, incomplete runs listed, PNGs written."""
import csv
import json
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
from PIL import Image

from experiments import summary as summarize
from tests.conftest import run_cli


POOL = 12  # synthetic training-camera pool (ids 0..11)


def make_run(root: Path, setup: str, scene: str, tag: str, seed: int, method: str, k: int, eps: float,
             counts: list[tuple[int, int]], metrics: tuple[float, float, float] | None) -> Path:
    """Write selection.json, cameras.json, run_status.json and (when metrics is given) results.json.
    counts: (conservative, evaluated) per acquisition step."""
    model = root / setup / scene / tag / f"seed{seed}"
    model.mkdir(parents=True)
    views, stages = [0, 6], []
    for i, (cons, ev) in enumerate(counts):
        chosen = [v for v in range(POOL) if v not in views][:k]
        stages.append({"stage": i, "iteration": 10 * i, "train_views": list(views), "candidates": POOL - len(views),
                       "selected": chosen, "gains": [1.0] * k, "oracle_calls": {"conservative": cons, "evaluated": ev},
                       "fisher_seconds": 0.5 * (i + 1), "select_seconds": 1.0 * (i + 1), "test_psnr": 10.0 + i})
        views += chosen
    options = {"eps": eps} if method in ("lite_gs", "ssg") else {}
    selection = {"config": {"method": method, "selector_options": options, "num_init_views": 2, "views_per_step": k,
                            "max_views": len(views), "iters_per_view": 1, "iterations": 50, "seed": seed},
                 "stages": stages, "final": {"iteration": 50, "train_views": views, "test_psnr": 20.0 + seed}}
    (model / "selection.json").write_text(json.dumps(selection))
    angles = np.linspace(0, 2 * np.pi, POOL, endpoint=False)
    (model / "cameras.json").write_text(json.dumps([
        {"id": i, "img_name": f"r_{i}", "width": 8, "height": 8, "position": [4 * math.cos(a), 4 * math.sin(a), 1.0],
         "rotation": np.eye(3).tolist(), "fx": 8.0, "fy": 8.0} for i, a in enumerate(angles)]))
    (model / "run_status.json").write_text(json.dumps({"status": "complete" if metrics else "running"}))
    if metrics:
        psnr, ssim, lpips = metrics
        (model / "results.json").write_text(json.dumps({
            "ours_10": {"PSNR": 0.0, "SSIM": 0.0, "LPIPS": 1.0, "LPIPS_variant": "squeeze"},  # older: must be ignored
            "ours_50": {"PSNR": psnr, "SSIM": ssim, "LPIPS": lpips, "LPIPS_variant": "squeeze"}}))
    return model


def build(root: Path) -> dict:
    """Setup 1 (2 scenes x 2 seeds x 3 methods, one lite_gs run unfinished), Setup 4 (K = 3, 4, 6; eps 0.3 / 0.6
    at K = 6) and an SSG ablation pair; returns the expected values."""
    rng = np.random.default_rng(0)
    expect = {"quality": {}, "oracle": {}}
    s1_counts = {"random": [(0, 0)] * 3, "pop_gs": [(10, 10), (7, 7), (4, 4)], "lite_gs": [(8, 5), (6, 5), (4, 3)]}
    for method, counts in s1_counts.items():
        values = []
        for scene in ("lego", "ship"):
            for seed in (0, 1):
                m = (float(rng.uniform(15, 25)), float(rng.uniform(0.5, 0.9)), float(rng.uniform(0.1, 0.3)))
                unfinished = method == "lite_gs" and scene == "ship" and seed == 1
                make_run(root, "setup1", scene, method, seed, method, 3, 0.1, counts, None if unfinished else m)
                if not unfinished:
                    values.append(m)
        label = f"{method} K=3" + (" eps=0.1" if method == "lite_gs" else "")
        expect["quality"][("setup1", label)] = np.array(values)
    # Setup 4: per-step counts whose step average is not an integer, and differs between seeds.
    s4 = {("pop_gs", 3, 0.1): [[(12, 12), (9, 9), (6, 6), (4, 4)], [(12, 12), (9, 9), (6, 6), (3, 3)]],
          ("lite_gs", 3, 0.1): [[(9, 7), (7, 6), (5, 5), (4, 3)], [(9, 8), (7, 7), (5, 4), (3, 3)]],
          ("pop_gs", 4, 0.1): [[(15, 15), (11, 11), (6, 6)]] * 2,
          ("lite_gs", 4, 0.1): [[(9, 7), (7, 6), (5, 4)]] * 2,
          ("pop_gs", 6, 0.1): [[(20, 20), (11, 11)]] * 2,
          ("lite_gs", 6, 0.1): [[(9, 8), (6, 5)]] * 2,
          ("lite_gs", 6, 0.3): [[(5, 4), (3, 3)]] * 2,
          ("lite_gs", 6, 0.6): [[(2, 2), (1, 1)]] * 2}
    for (method, k, eps), per_seed in s4.items():
        tag = f"{method}_k{k}" + (f"_eps{eps:g}" if eps != 0.1 else "")
        for seed, counts in enumerate(per_seed):
            make_run(root, "setup4", "ship", tag, seed, method, k, eps, counts, (20.0 + eps, 0.8, 0.2))
        steps = [c for counts in per_seed for c in counts]
        expect["oracle"][("setup4", k, method, f"eps={eps:g}" if method == "lite_gs" else "")] = tuple(
            math.ceil(Fraction(sum(c[i] for c in steps), len(steps))) for i in (0, 1))
    for eps in (0.1, 0.4):
        for method in ("lite_gs", "ssg"):
            make_run(root, "ablation_ssg", "ship", f"{method}_eps{eps:g}", 0, method, 4, eps,
                     [(8, 6), (6, 5), (4, 4)], (22.0, 0.8, 0.2))
    return expect


def test_tables_match_numpy_and_rounded_up_counts(tmp_path):
    expect = build(tmp_path / "out")
    # A run whose selection.json was cut off mid-write, with nothing else readable: listed, not a crash.
    broken = tmp_path / "out" / "setup1" / "lego" / "pop_gs" / "seed7"
    broken.mkdir()
    (broken / "selection.json").write_text('{"config": {"meth')
    runs = summarize.find_runs([str(tmp_path / "out")])
    written = summarize.write_outputs(runs, tmp_path / "summary")

    quality = {(r["setup"], r["method"]): r for r in summarize.quality_rows(runs)}
    for key, values in expect["quality"].items():
        row = quality[key]
        assert row["runs"] == len(values)
        for j, metric in enumerate(("PSNR", "SSIM", "LPIPS")):
            # 1e-12: the same float64 sums in a different order
            assert abs(row[f"{metric}_mean"] - values[:, j].mean()) < 1e-12
            assert abs(row[f"{metric}_std"] - values[:, j].std(ddof=1)) < 1e-12
        assert row["LPIPS_variant"] == "squeeze"
    assert quality[("setup1", "lite_gs K=3 eps=0.1")]["incomplete"] == 1
    assert quality[("setup1", "random K=3")]["incomplete"] == 0

    oracle = {(r["setup"], r["K"], r["method"], r["options"]): r for r in summarize.oracle_rows(runs)}
    for key, (cons, ev) in expect["oracle"].items():
        assert (oracle[key]["conservative"], oracle[key]["evaluated"]) == (cons, ev), key
    # Exhaustive greedy on Setup 4's K = 6 steps (seeds [0, 6], pool 12): M = 10 picks 6, then M = 4 picks the last 4.
    exhaustive = math.ceil(Fraction((10 + 9 + 8 + 7 + 6 + 5) + (4 + 3 + 2 + 1), 2))
    for eps in ("0.1", "0.3", "0.6"):
        lite = expect["oracle"][("setup4", 6, "lite_gs", f"eps={eps}")][0]
        row = oracle[("setup4", 6, "lite_gs", f"eps={eps}")]
        assert row["exhaustive"] == exhaustive and abs(row["reduction_%"] - 100 * (1 - lite / exhaustive)) < 1e-9
    assert ("ablation_ssg", 4, "ssg", "eps=0.4") in oracle and oracle[("setup1", 3, "pop_gs", "")]["conservative"] == 7
    assert not any(key[2] == "random" for key in oracle)  # no oracle calls: not in the oracle table

    times = {(r["setup"], r["method"]): r for r in summarize.time_rows(runs)}
    # three steps with select_seconds 1, 2, 3 and fisher_seconds 0.5, 1, 1.5 in every run
    assert times[("setup1", "pop_gs K=3")]["select_s_per_run_mean"] == 6.0
    assert times[("setup1", "pop_gs K=3")]["fisher_s_per_run_mean"] == 3.0

    md = (tmp_path / "summary" / "summary.md").read_text()
    for label in ["random K=3", "pop_gs K=3", "lite_gs K=3 eps=0.1", "lite_gs K=6 eps=0.6", "ssg K=4 eps=0.4"]:
        assert f"| {label} |" in md, label
    for header in ["| PSNR |", "| SSIM |", "| LPIPS |", "| LPIPS_variant |", "| conservative |", "| evaluated |",
                   "| reduction_% |", "| select_s_per_run |", "| fisher_s_per_run |"]:
        assert header in md, header
    assert "## Incomplete runs" in md and "ship/lite_gs/seed1" in md and "seed7`: no readable" in md

    with open(tmp_path / "summary" / "summary.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["table"] for r in rows} == {"quality", "per_seed", "views", "paired", "oracles", "time"}
    assert "## Paired differences against the best mean" in md
    q = next(r for r in rows if r["table"] == "quality" and r["method"] == "pop_gs K=3")
    assert abs(float(q["PSNR_mean"]) - expect["quality"][("setup1", "pop_gs K=3")][:, 0].mean()) < 1e-9

    names = {p.name for p in written}
    assert names >= {"psnr_vs_views.png", "oracles_vs_k.png", "eps_tradeoff.png", "chosen_cameras.png"}
    for p in written:
        if p.suffix == ".png":
            with Image.open(p) as im:
                assert im.size[0] > 100 and im.size[1] > 100


def test_per_seed_table_keeps_every_seed_and_counts_orderings(tmp_path):
    """seed_rows per scene: each seed's PSNR, mean/std over seeds, 'first in' (ties count for each) and 'above random
    in' against random's run of the same seed; a seed missing for one method is left out of its counts."""
    psnr = {("lego", "random"): [20.0, 22.0, 21.0], ("lego", "pop_gs"): [21.0, 21.5, 23.0],
            ("lego", "lite_gs"): [21.0, 22.5, None], ("mic", "random"): [30.0, 29.0, 28.0],
            ("mic", "pop_gs"): [29.0, 29.5, 27.0]}
    for (scene, method), values in psnr.items():
        for seed, value in enumerate(values):
            make_run(tmp_path / "out", "setup1", scene, method, seed, method, 3, 0.1, [(4, 4)],
                     None if value is None else (value, 0.8, 0.2))
    runs = summarize.find_runs([str(tmp_path / "out")])
    rows = {(r["scene"], r["method"].split()[0]): r for r in summarize.seed_rows(runs)}
    assert len(rows) == 5
    pop = rows[("lego", "pop_gs")]
    assert (pop["seed_0"], pop["seed_1"], pop["seed_2"]) == (21.0, 21.5, 23.0)
    assert abs(pop["PSNR_mean"] - np.mean([21.0, 21.5, 23.0])) < 1e-12
    assert abs(pop["PSNR_std"] - np.std([21.0, 21.5, 23.0], ddof=1)) < 1e-12
    assert pop["first_in"] == "2/3" and pop["above_random_in"] == "2/3"  # seed 0 tied with lite_gs: both first
    lite = rows[("lego", "lite_gs")]
    assert lite["seed_2"] is None and lite["first_in"] == "2/2" and lite["above_random_in"] == "2/2"
    assert rows[("lego", "random")]["first_in"] == "0/3" and rows[("lego", "random")]["above_random_in"] == ""
    assert rows[("mic", "pop_gs")]["above_random_in"] == "1/3" and rows[("mic", "random")]["first_in"] == "2/3"
    md = summarize.seed_tables(summarize.seed_rows(runs))
    assert "### setup1, lego" in md and "### setup1, mic" in md
    assert "| pop_gs K=3 | **21.00** | 21.50 | **23.00** | 21.83 ± 1.04 | 2/3 | 2/3 |" in md
    assert "| lite_gs K=3 eps=0.1 | **21.00** | **22.50** | – | 21.75 ± 1.06 | 2/2 | 2/2 |" in md
    # paired against lego's best mean (pop_gs, 21.83): lite_gs over its two seeds, (21 - 21 + 22.5 - 21.5) / 2
    paired = {(r["scene"], r["method"].split()[0]): r for r in summarize.against_leader(summarize.seed_rows(runs))}
    assert paired[("lego", "lite_gs")]["seeds"] == 2 and abs(paired[("lego", "lite_gs")]["diff"] - 0.5) < 1e-12
    assert paired[("lego", "random")]["leader"] == "pop_gs K=3" and ("lego", "pop_gs") not in paired


def test_cli_writes_outputs_and_rejects_missing_root(tmp_path):
    make_run(tmp_path / "out", "setup1", "lego", "pop_gs", 0, "pop_gs", 3, 0.1, [(10, 10), (7, 7)], (20, 0.8, 0.2))
    r = run_cli("scripts/summarize.py", str(tmp_path / "out"))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "summary.md").is_file() and (tmp_path / "out" / "psnr_vs_views.png").is_file()
    assert "| pop_gs K=3 |" in r.stdout
    r = run_cli("scripts/summarize.py", str(tmp_path / "nowhere"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and r.stderr.startswith("error: ")
    (tmp_path / "empty").mkdir()
    r = run_cli("scripts/summarize.py", str(tmp_path / "empty"))
    assert r.returncode == 2 and "no runs" in r.stderr


def test_provenance_counts_machines_codes_and_resumes(tmp_path):
    """The Provenance section: each run's machine and code (a resume under other code as 'A then B'), counted;
    runs without sessions are said to be unrecorded."""
    def session(code, started, threads=1):
        return {"started": started, "from_iteration": 0, "code": code, "machine": "Linux-x", "cpu": "Xeon", "cpus": 2,
                "threads": threads, "device": "cpu", "torch": "2.14.1"}
    sessions = {0: [session("aaaaaaa", "2026-12-03T05:40:00")],
                1: [session("aaaaaaa", "2026-12-03T05:41:00"), session("bbbbbbb+changes", "2026-12-03T07:02:00")],
                2: None}
    for seed, recorded in sessions.items():
        model = make_run(tmp_path / "out", "setup1", "lego", "pop_gs", seed, "pop_gs", 3, 0.1, [(4, 4)],
                         (20.0, 0.8, 0.2))
        if recorded:
            sel = json.loads((model / "selection.json").read_text())
            (model / "selection.json").write_text(json.dumps({**sel, "sessions": recorded}))
    lines = summarize.provenance_lines(summarize.find_runs([str(tmp_path / "out")]))
    assert "- machine: Linux-x, 2 x Xeon, torch 2.14.1, cpu (2 runs)" in lines
    assert "- threads per process: 1 (2 runs)" in lines
    assert "- code: aaaaaaa (1 run); aaaaaaa then bbbbbbb+changes (1 run)" in lines
    assert "- trained between 2026-12-03 05:40:00 and 2026-12-03 07:02:00 (session starts)" in lines
    assert lines[-1].startswith("- 1 run(s) without a record")
    assert summarize.grid_lines(summarize.find_runs([str(tmp_path / "out")])) == []  # no grid.json: not a grid

    # A grid's record and status: its scale line, and each run's job minutes in the time table.
    grid = tmp_path / "out" / "setup1"
    (grid / "grid.json").write_text(json.dumps({"resolution": 8, "iter_scale": 0.1, "stage_scale": None,
                                                "num_points": 3000, "train_args": ["--sh_degree", "1"]}))
    jobs = [{"model_dir": str(grid / "lego" / "pop_gs" / f"seed{s}"), "state": "done", "seconds": 60.0 * (s + 1)}
            for s in (0, 1)] + [{"model_dir": str(grid / "lego" / "pop_gs" / "seed2"), "state": "skipped",
                                 "seconds": None}]
    (grid / "grid_status.json").write_text(json.dumps({"started": "2026-12-03 05:50:01", "max_parallel": 2,
                                                       "threads_per_job": 1, "elapsed_s": 150.0, "jobs": jobs}))
    runs = summarize.find_runs([str(tmp_path / "out")])
    assert sorted(r.job_seconds for r in runs if r.job_seconds is not None) == [60.0, 120.0]
    assert summarize.grid_lines(runs) == [
        "- grid `setup1`: --resolution 8, --iter_scale 0.1, --num_points 3000; train.py flags after `--`: "
        "--sh_degree 1; its last invocation (started 2026-12-03 05:50:01, 2 job(s) at a time, 1 thread(s) each) "
        "ran 2 job(s) in 2 min wall, 0.05 h of job time"]
    (time_row,) = summarize.time_rows(runs)
    assert time_row["job_min_mean"] == 1.5 and abs(time_row["job_min_std"] - np.std([1.0, 2.0], ddof=1)) < 1e-12
    summarize.write_outputs(runs, tmp_path / "summary")
    md = (tmp_path / "summary" / "summary.md").read_text()
    assert "## Provenance" in md and "- grid `setup1`" in md and "| 1.5 ± 0.7 |" in md


def test_job_minutes_sum_every_invocation_that_worked_on_a_run(tmp_path):
    """A run's grid_job_seconds.json (one record per grid job invocation that ran a step) beats grid_status.json's
    last invocation, which for a run finished earlier says ~0 s ("already finished")."""
    from experiments.jobs import JOB_TIMES, record_job_time, recorded_job_seconds
    grid = tmp_path / "out" / "setup1"
    model = make_run(tmp_path / "out", "setup1", "lego", "pop_gs", 0, "pop_gs", 3, 0.1, [(4, 4)], (20.0, 0.8, 0.2))
    (grid / "grid.json").write_text(json.dumps({"resolution": 8, "iter_scale": 0.1, "stage_scale": None,
                                                "num_points": 3000, "train_args": []}))
    (grid / "grid_status.json").write_text(json.dumps({"jobs": [{"model_dir": str(model), "state": "done",
                                                                 "seconds": 0.2}]}))
    assert recorded_job_seconds(model) is None
    assert summarize.find_runs([str(tmp_path / "out")])[0].job_seconds == 0.2  # no record: the grid's status
    record_job_time(model, 100.0, "failed")  # interrupted, then resumed by a later invocation
    record_job_time(model, 50.0, "done")
    assert [r["state"] for r in json.loads((model / JOB_TIMES).read_text())] == ["failed", "done"]
    assert summarize.find_runs([str(tmp_path / "out")])[0].job_seconds == 150.0


def test_an_unfinished_run_is_reported_with_its_last_progress_not_as_running(tmp_path):
    """run_status.json says "running" until the process ends; a killed run keeps saying it. The summary gives the time
    of the last record (the progress so far), never a claim that the run is still going."""
    model = make_run(tmp_path, "setup1", "lego", "pop_gs", 0, "pop_gs", 3, 0.1, [(10, 10)], None)
    (model / "run_status.json").write_text(json.dumps(
        {"status": "running", "iteration": 1805, "total_iterations": 2000, "updated": "2026-12-03 14:20:22"}))
    problem = summarize.load_run(model).problem
    assert problem == ("no results.json (training unfinished: 1 step(s) done, iteration 1805/2000, "
                       "last progress recorded at 2026-12-03 14:20:22)")
    (model / "run_status.json").unlink()
    assert summarize.load_run(model).problem == "no results.json (no run_status.json, 1 step(s) done)"


def test_views_table_averages_each_view_count_over_the_complete_seeds(tmp_path):
    """views_rows: stage values (before each acquisition) and the final one, keyed by the training-view count,
    mean and sample std over the complete runs only; one markdown table per setup and scene."""
    for seed in (0, 1, 2):  # stages at 2 and 5 views (10 and 11 dB), final at 8 views (20 + seed dB)
        make_run(tmp_path / "out", "setup1", "lego", "pop_gs", seed, "pop_gs", 3, 0.1, [(4, 4), (3, 3)],
                 None if seed == 2 else (21.0, 0.8, 0.2))  # seed 2 unfinished: left out
    runs = summarize.find_runs([str(tmp_path / "out")])
    (row,) = summarize.views_rows(runs)
    assert (row["scene"], row["method"]) == ("lego", "pop_gs K=3")
    assert (row["views_2_mean"], row["views_5_mean"], row["views_8_mean"]) == (10.0, 11.0, 20.5)
    assert row["views_2_std"] == 0.0 and abs(row["views_8_std"] - math.sqrt(0.5)) < 1e-12
    md = summarize.views_tables(summarize.views_rows(runs))
    assert "### setup1, lego" in md and "| method | 2 views | 5 views | 8 views |" in md
    assert "| pop_gs K=3 | 10.00 ± 0.00 | 11.00 ± 0.00 | 20.50 ± 0.71 |" in md


def test_runs_with_other_seed_views_or_stage_methods_are_never_pooled(tmp_path):
    """Two grids of one method, one with the default seed views, one with --seed_start random and one with
    --stage_method: three settings, each with its own seeds."""
    for tag, extra in (("plain", {}), ("drawn", {"seed_start": "random"}),
                       ("mixed", {"seed_start": "first", "stage_method": ["0:coverage"]})):
        for seed in range(2):
            model = make_run(tmp_path / tag, "setup1", "lego", "lite_gs", seed, "lite_gs", 2, 0.1, [(5, 4)],
                             (20.0, 0.9, 0.1))
            record = json.loads((model / "selection.json").read_text())
            record["config"].update(extra)
            (model / "selection.json").write_text(json.dumps(record))
    runs = [summarize.load_run(m) for m in sorted(tmp_path.rglob("seed*"))]
    assert sorted({r.setting for r in runs}) == ["lite_gs K=2 eps=0.1", "lite_gs K=2 eps=0.1 seed_start=random",
                                                 "lite_gs K=2 eps=0.1 stage_method=0:coverage"]
