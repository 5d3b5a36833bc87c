"""`auto`: the rule that chooses cover_pool or lite_gs per step, its picks (those of the chosen selector, through
recommend.py's pipeline and train.py's acquisition stage), its records and its bad-input lines."""
from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

from active import build_selector
from active.base import StepChoice
from active.selectors.auto import GEOMETRIC_EVIDENCE
from recommender.candidates import generate
from recommender.pipeline import load_model, make_pool, recommend
from tests.conftest import run_cli
from training.acquisition import model_iterations
from utils.errors import UserError
from tests.test_recommend import EYES, _cameras_json, _cli_error, _graphdeco_ply


@pytest.mark.parametrize("captured, iterations, expected", [
    (5, 1000, "cover_pool"),  # recommend-then-train: 5 views, 1,000 iterations
    (2, 200, "cover_pool"), (5, 700, "cover_pool"),  # Setup 1 with the paper's stage lengths, first two steps
    (8, 1500, "lite_gs"),  # ... its third step
    (8, 150, "cover_pool"),  # Setup 1 at the default stage lengths: 19 iterations per view
    (8, 800, "lite_gs"), (8, 799, "cover_pool"), (7, 10_000, "cover_pool"),  # both thresholds at their edge
    (8, None, "lite_gs"),  # a PLY from another trainer: training length unknown, taken as trained
])
def test_rule_chooses_by_captured_views_and_training_length(captured, iterations, expected):
    choice = build_selector("auto").for_step(captured, iterations)
    line = choice.rule
    assert choice.selector.name == expected
    assert line.startswith(f"auto: {captured} captured views") and "\n" not in line
    assert ("geometric" in line) == (expected == "cover_pool")
    assert (GEOMETRIC_EVIDENCE in line) == (expected == "cover_pool")  # the geometric branch says what it measured


def test_options_reach_the_rule_and_the_fisher_branch():
    auto = build_selector("auto", auto_min_views=3, auto_min_iters_per_view=0, eps=0.3)
    assert auto.for_step(3, 0).selector.name == "lite_gs" and auto.for_step(3, 0).selector.config.eps == 0.3
    assert auto.for_step(2, 10**6).selector.name == "cover_pool"
    assert auto.for_step(2, 10**6).selector.config.pool_compare == "none"
    compared = build_selector("auto", pool_compare="coverage").for_step(2, 0)
    assert compared.selector.config.pool_compare == "coverage" and "compared with coverage's" in compared.rule
    assert build_selector("auto", pool_compare="coverage").conservative_count(10, 3) == 27 + 3
    cover_pool = build_selector("cover_pool")
    assert cover_pool.for_step(5, 1000) == StepChoice(cover_pool, None)  # a selector without a rule runs itself
    assert auto.delegates and not build_selector("cover_pool").delegates
    with pytest.raises(RuntimeError, match="for_step"):  # never run by itself: its oracle kind depends on the step
        auto.select(None, 3)


@pytest.mark.auto_backend
@pytest.mark.parametrize("options, branch", [({}, "cover_pool"), ({"auto_min_views": 3}, "lite_gs"),
                                             ({"auto_geometric": "coverage"}, "coverage")])
def test_recommend_makes_the_chosen_selectors_picks_and_says_why(tmp_path, options, branch):
    ply = tmp_path / "splat.ply"
    _graphdeco_ply(ply)
    model = load_model(ply, _cameras_json(tmp_path / "cameras.json", EYES))  # 3 captured views, no iteration
    pool = make_pool(model, generate("orbit", 8, model.captured))
    rec = recommend(model, pool, build_selector("auto", **options), 3, seed=2)
    ref = recommend(model, pool, build_selector(branch), 3, seed=2)
    assert rec.used.name == branch and rec.picks == ref.picks and rec.pick_gains == ref.pick_gains
    assert rec.acquisition.evaluated == ref.acquisition.evaluated
    assert rec.acquisition.selection.conservative == ref.acquisition.selection.conservative
    assert rec.rule in rec.notes and ref.rule is None
    assert ("geometric" in rec.rule) == (branch != "lite_gs")


def test_geometric_branch_option_and_the_count_of_either_branch():
    """--auto_geometric coverage: coverage's picks on the geometric steps, lite_gs's after; the conservative count is
    the larger branch's worst case (the step's branch is not known before it runs)."""
    auto = build_selector("auto", auto_geometric="coverage")
    assert auto.for_step(5, 1000).selector.name == "coverage" and "geometric (coverage)" in auto.for_step(5, 1000).rule
    assert auto.for_step(8, 1500).selector.name == "lite_gs"
    lite_gs = build_selector("lite_gs", eps=0.1).conservative_count(100, 4)
    assert auto.conservative_count(100, 4) == lite_gs > 0  # coverage evaluates no oracle
    assert build_selector("auto").conservative_count(100, 4) == build_selector("cover_pool").conservative_count(100, 4)
    with pytest.raises(UserError, match="--pool_compare applies to cover_pool's steps"):
        build_selector("auto", auto_geometric="coverage", pool_compare="coverage")


def test_coverage_from_a_number_of_captured_views():
    """--auto_coverage_from 5: cover_pool's picks below 5 captured views, coverage's from 5 until the Fisher's."""
    auto = build_selector("auto", auto_coverage_from=5)
    steps = {n: auto.for_step(n, 100 * n) for n in (2, 4, 5, 7, 8)}
    assert [steps[n].selector.name for n in steps] == ["cover_pool", "cover_pool", "coverage", "coverage", "lite_gs"]
    assert "geometric (coverage, coverage's from 5 captured views)" in steps[5].rule
    assert "geometric (cover_pool, coverage's from 5 captured views)" in steps[2].rule
    assert build_selector("auto").for_step(7, 700).selector.name == "cover_pool"  # 0, the default: never
    assert auto.conservative_count(100, 4) == build_selector("auto").conservative_count(100, 4)


@pytest.mark.parametrize("stage_reset, expected", [(False, 700), (True, 500)])
def test_the_rule_counts_the_iterations_of_the_current_model(stage_reset, expected):
    """With --stage_reset the model starts afresh at each acquisition: only the iterations since the last one count."""
    state = SimpleNamespace(iteration=700, stages=[{"iteration": 200}])
    cfg = SimpleNamespace(active=SimpleNamespace(stage_reset=stage_reset))
    assert model_iterations(state, cfg) == expected
    first = SimpleNamespace(iteration=200, stages=[])  # before the first acquisition: every iteration
    assert model_iterations(first, cfg) == 200


def test_train_py_switches_at_the_rule_and_records_it(tiny_scene, tmp_path):
    common = ["-s", str(tiny_scene), "--num_init_views", "2", "--views_per_step", "3", "--iters_per_view", "10",
              "--seed", "4", "--quiet"]
    model = tmp_path / "auto"
    r = run_cli("train.py", *common, "-m", str(model), "--method", "auto", "--max_views", "8", "--iterations", "100",
                "--auto_min_views", "5", "--auto_min_iters_per_view", "10")
    assert r.returncode == 0, r.stderr
    stages = json.loads((model / "selection.json").read_text())["stages"]
    # step 0: 2 views after 20 iterations; step 1: 5 views after 20 + 50 = 70 iterations (14 per view)
    assert [(s["iteration"], s["selector_used"]) for s in stages] == [(20, "cover_pool"), (70, "lite_gs")]
    assert all(s["rule"].startswith(f"auto: {len(s['train_views'])} captured views") for s in stages)
    ref = tmp_path / "cover_pool"
    r = run_cli("train.py", *common, "-m", str(ref), "--method", "cover_pool", "--max_views", "5",
                "--iterations", "60")
    assert r.returncode == 0, r.stderr
    ref_stage = json.loads((ref / "selection.json").read_text())["stages"][0]
    assert stages[0]["selected"] == ref_stage["selected"] and stages[0]["oracle_calls"] == ref_stage["oracle_calls"]
    assert "rule" not in ref_stage


def test_the_pool_compare_note_reaches_selection_json_and_recommendations(tiny_scene, tmp_path):
    """Which set `--pool_compare coverage` kept is one line in train.py's stage record and recommend.py's notes."""
    model = tmp_path / "compared"
    r = run_cli("train.py", "-s", str(tiny_scene), "--num_init_views", "2", "--views_per_step", "3",
                "--iters_per_view", "10", "--seed", "4", "--quiet", "-m", str(model), "--method", "auto",
                "--pool_compare", "coverage", "--max_views", "5", "--iterations", "60")
    assert r.returncode == 0, r.stderr
    [stage] = json.loads((model / "selection.json").read_text())["stages"]
    assert stage["note"].startswith("cover_pool --pool_compare coverage: kept ")
    assert stage["oracle_calls"]["conservative"] == sum(12 - j for j in range(3)) + 3  # 12 candidates, K = 3
    ply = tmp_path / "splat.ply"
    _graphdeco_ply(ply)
    captured = load_model(ply, _cameras_json(tmp_path / "cameras.json", EYES))
    pool = make_pool(captured, generate("orbit", 8, captured.captured))
    rec = recommend(captured, pool, build_selector("auto", pool_compare="coverage"), 3, seed=2)
    assert rec.acquisition.selection.note in rec.notes and "kept" in rec.acquisition.selection.note


@pytest.mark.parametrize("flag, value, expected", [
    ("--auto_min_views", "0", "--auto_min_views must be an integer >= 1, got 0"),
    ("--auto_min_iters_per_view", "-1", "--auto_min_iters_per_view must be an integer >= 0, got -1"),
    ("--eps", "1.5", "eps"),
    ("--pool_compare", "fps", "--pool_compare must be one of none, coverage, got 'fps'"),
    ("--auto_geometric", "cover", "--auto_geometric must be one of cover_pool, coverage, got 'cover'"),
    ("--auto_coverage_from", "-2", "--auto_coverage_from must be an integer >= 0 (0: never), got -2"),
])
def test_out_of_range_options_are_one_error_line(tmp_path, flag, value, expected):
    ply = tmp_path / "splat.ply"
    _graphdeco_ply(ply)
    captured = _cameras_json(tmp_path / "cameras.json", EYES)
    line = _cli_error(tmp_path, "-m", str(ply), "--captured", str(captured), "--method", "auto", flag, value)
    assert expected in line
