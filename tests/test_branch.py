"""scripts/branch_pick.py (experiments/branch.py): undoing the last acquisition of a checkpoint; a branch with the
run's own deterministic selector reproduces the run to the last digit, a branch with another selector keeps the
run's history and changes only the last pick; bad input."""
import json
import subprocess
import sys

import pytest

from experiments.branch import short_flags, undo_last_acquisition
from tests.conftest import ROOT
from tests.test_selection_fit import ENV, script, tiny_grid
from utils.errors import UserError


def checkpoint(stage_reset: bool = False) -> dict:
    stages = [{"iteration": 20, "selected": [5, 6]}, {"iteration": 50, "selected": [1, 9]}]
    return {"iteration": 50, "stage": 2, "stages": stages, "train_views": [0, 3, 5, 6, 1, 9], "view_stack": [4],
            "config": {"active": {"stage_reset": stage_reset}}}


def test_undo_removes_the_last_picks_and_their_record():
    undone = undo_last_acquisition(checkpoint())
    assert undone["stage"] == 1 and undone["stages"] == checkpoint()["stages"][:1]
    assert undone["train_views"] == [0, 3, 5, 6] and undone["view_stack"] == [] and undone["iteration"] == 50


def test_long_id_lists_are_counted_in_the_table():
    assert short_flags("--exclude_views 4 12 14 16 18 --eps 0.3") == "--exclude_views (5 ids) --eps 0.3"
    assert short_flags("--exclude_views 4 12") == "--exclude_views 4 12" and short_flags("") == ""


@pytest.mark.parametrize("change, expected", [
    ({"iteration": 60}, "was not written by an acquisition"),
    ({"stage": 1}, "was not written by an acquisition"),
    ({"config": {"active": {"stage_reset": True}}}, "--stage_reset"),
])
def test_undo_refuses_a_checkpoint_it_cannot_undo(change, expected):
    with pytest.raises(UserError, match=expected):
        undo_last_acquisition({**checkpoint(), **change})


@pytest.mark.slow
def test_a_branch_with_the_runs_own_selector_is_the_run(tiny_scene, tmp_path):
    run = tiny_grid(tiny_scene, tmp_path / "out", "coverage") / "coverage" / "seed0"
    branches = tmp_path / "branches"
    rows = tmp_path / "rows.json"
    r = script("branch_pick.py", str(run), "--specs", "coverage", "random", "--out", str(branches), "--json", str(rows))
    assert r.returncode == 0, r.stdout + r.stderr
    original = json.loads((run / "selection.json").read_text())
    same = json.loads((branches / tiny_scene.name / "coverage" / "coverage" / "seed0" / "selection.json").read_text())
    other = json.loads((branches / tiny_scene.name / "coverage" / "random" / "seed0" / "selection.json").read_text())
    assert [s["selected"] for s in same["stages"]] == [s["selected"] for s in original["stages"]]
    assert same["final"]["test_psnr"] == original["final"]["test_psnr"]  # bit for bit: the same model, state, picks
    assert [s["selected"] for s in other["stages"][:-1]] == [s["selected"] for s in original["stages"][:-1]]
    assert other["stages"][-1]["test_psnr"] == original["stages"][-1]["test_psnr"]  # picked from the same model
    assert other["stages"][-1]["selected"] != original["stages"][-1]["selected"]
    row = f"| {tiny_scene.name} | coverage | coverage | "
    assert row in r.stdout and "| 1 | +0.00 | – | 0 / 0 | no |" in r.stdout, r.stdout
    again = script("branch_pick.py", "--table", str(rows))
    assert again.returncode == 0 and again.stdout.strip() in r.stdout and row in again.stdout, \
        again.stdout + again.stderr
    rerun = script("branch_pick.py", str(run), "--specs", "coverage", "--out", str(branches))  # finished: skipped
    assert rerun.returncode == 0 and "already finished" in rerun.stdout, rerun.stdout + rerun.stderr
    mixed = script("branch_pick.py", str(run), "--specs", "coverage", "--out", str(branches),
                   "--train_args=--exclude_views 1")  # other train.py flags never land in a folder made without them
    assert mixed.returncode != 0 and "give these flags their own --out" in mixed.stderr, mixed.stderr
    early = script("branch_pick.py", str(run), "--specs", "random", "--out", str(branches), "--stage", "0")
    assert early.returncode != 0 and "kept no checkpoint of acquisition 0" in early.stderr, early.stderr


@pytest.mark.slow
def test_a_branch_at_the_first_acquisition(tiny_scene, tmp_path):
    """A run that kept every checkpoint, branched at acquisition 0: the branch with the run's own selector is the run;
    with another, only acquisition 0 is that selector's, the later ones the run's own (coverage's, no oracle)."""
    grid = tiny_grid(tiny_scene, tmp_path / "out", "coverage", train_flags=("--keep_checkpoints", "0"))
    run = grid / "coverage" / "seed0"
    branches = tmp_path / "branches"
    r = script("branch_pick.py", str(run), "--specs", "coverage", "lite_gs", "--out", str(branches), "--stage", "0")
    assert r.returncode == 0, r.stdout + r.stderr
    original = json.loads((run / "selection.json").read_text())
    folder = branches / tiny_scene.name / "coverage"
    same = json.loads((folder / "coverage@0" / "seed0" / "selection.json").read_text())
    other = json.loads((folder / "lite_gs@0" / "seed0" / "selection.json").read_text())
    assert same["final"]["test_psnr"] == original["final"]["test_psnr"]
    assert [s["selected"] for s in same["stages"]] == [s["selected"] for s in original["stages"]]
    assert other["stages"][0]["test_psnr"] == original["stages"][0]["test_psnr"]  # picked from the same model
    assert other["stages"][0]["selected"] != original["stages"][0]["selected"]
    assert [s.get("stage_method") for s in other["stages"]] == ["lite_gs", None, None]
    assert [s["oracle_calls"]["evaluated"] > 0 for s in other["stages"]] == [True, False, False]
    assert "| coverage | lite_gs at acquisition 0 |" in r.stdout, r.stdout
    beyond = script("branch_pick.py", str(run), "--specs", "random", "--out", str(branches), "--stage", "3")
    assert beyond.returncode != 0 and "made acquisitions 0 to 2" in beyond.stderr, beyond.stderr


@pytest.mark.parametrize("args, expected", [
    (["seed0", "--specs", "coverage", "--out", "b"], "seed0 is not a grid run directory"),
    (["r/s/sc/m/seed0", "--specs", "coverage", "--out", "b"], "has no checkpoint to branch from"),
    (["r/s/sc/m/seed0"], "pass finished grid runs, --specs and --out"),
    (["--table", "missing.json"], "missing.json not found"),
])
def test_bad_input_is_one_error_line(tmp_path, args, expected):
    (tmp_path / "r/s/sc/m/seed0").mkdir(parents=True)
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "branch_pick.py"), *args], capture_output=True,
                       text=True, env=ENV, cwd=tmp_path, timeout=120)
    assert r.returncode != 0 and r.stderr.strip().startswith("error:") and expected in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_pick_information_is_the_recorded_gains(tiny_scene, tmp_path):
    """The information of a lite_gs run's own last picks is the sum of the marginal gains its record holds (the
    same oracle on the same model); a branch with the run's own selector has margin 0."""
    run = tiny_grid(tiny_scene, tmp_path / "out", "lite_gs") / "lite_gs" / "seed0"
    branches, rows_path = tmp_path / "branches", tmp_path / "rows.json"
    assert script("branch_pick.py", str(run), "--specs", "lite_gs", "coverage", "--out", str(branches)).returncode == 0
    r = script("pick_information.py", str(run), "--specs", "lite_gs", "coverage", "--out", str(branches),
               "--json", str(rows_path))
    assert r.returncode == 0, r.stdout + r.stderr
    rows = {row["spec"]: row for row in json.loads(rows_path.read_text())}
    recorded = json.loads((run / "selection.json").read_text())["stages"][-1]
    assert rows["lite_gs"]["rho_run"] == pytest.approx(sum(recorded["gains"]), rel=1e-6)
    assert rows["lite_gs"]["rho_branch"] == rows["lite_gs"]["rho_run"]
    assert rows["coverage"]["branch_picks"] != recorded["selected"]
    assert rows["coverage"]["rho_branch"] < rows["coverage"]["rho_run"]  # greedy on the log-det beats coverage on it
    assert "| lite_gs | coverage |" in r.stdout and "| lite_gs | lite_gs | 2 | 1 | +0.000" in r.stdout, r.stdout
