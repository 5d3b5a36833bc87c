"""scripts/same_history.py (experiments/same_history.py): seeds grouped by the acquisition where two runs' picks
part, the paired differences at every later view count and at the end, against hand-computed values; bad input."""
import json
import subprocess
import sys

import pytest

from experiments.same_history import parting_stage, same_history
from tests.conftest import ROOT
from tests.test_selection_fit import ENV


def write_run(folder, seed, picks, psnrs, final_psnr):
    """A finished run's selection.json: 2 seed views, acquisitions of 3 views with `picks`, PSNR before each."""
    views, stages = [0, 1], []
    for stage, (selected, psnr) in enumerate(zip(picks, psnrs)):
        stages.append({"stage": stage, "train_views": list(views), "selected": selected, "test_psnr": psnr})
        views += selected
    run = folder / f"seed{seed}"
    run.mkdir(parents=True)
    (run / "selection.json").write_text(json.dumps({"stages": stages, "final": {"train_views": views,
                                                                               "test_psnr": final_psnr}}))


@pytest.fixture
def grid(tmp_path):
    a, b = tmp_path / "mic" / "a", tmp_path / "mic" / "b"
    # seed 0: same first picks (same model at 5 views), parts at acquisition 1; seeds 1 and 2 part at once
    write_run(a, 0, [[2, 3, 4], [5, 6, 7]], [14.0, 20.0], 27.0)
    write_run(b, 0, [[2, 3, 4], [8, 9, 10]], [14.0, 20.0], 27.5)
    write_run(a, 1, [[2, 3, 4], [5, 6, 7]], [15.0, 21.0], 28.0)
    write_run(b, 1, [[4, 3, 2], [5, 6, 7]], [15.0, 20.0], 27.0)
    write_run(a, 2, [[2, 3, 5], [6, 7, 8]], [13.0, 19.0], 26.0)
    write_run(b, 2, [[9, 3, 4], [6, 7, 8]], [13.0, 19.5], 26.5)
    write_run(a, 3, [[2, 3, 4], [5, 6, 7]], [13.0, 19.0], 26.0)  # only in a: left out
    return a, b


def test_seeds_are_grouped_where_the_picks_part(grid):
    a, b = grid
    rows = same_history(a, b)
    by = {(r["parting_stage"], r["views"]): r for r in rows}
    assert sorted(by) == [(0, 5), (0, 8), (1, 8)]
    assert by[(1, 8)]["seeds"] == [0] and by[(1, 8)]["difference"].mean == pytest.approx(-0.5)
    assert by[(1, 8)]["model_gap"] == 0.0 and by[(1, 8)]["parting_views"] == 5
    first = by[(0, 5)]["difference"]  # seed 1: +1.0, seed 2: -0.5
    assert by[(0, 5)]["seeds"] == [1, 2] and first.mean == pytest.approx(0.25) and (first.wins, first.losses) == (1, 1)
    assert by[(0, 8)]["difference"].mean == pytest.approx(0.25)  # final: +1.0, -0.5
    assert parting_stage({"stages": [{"selected": [1]}]}, {"stages": [{"selected": [1]}]}) == 1  # never parted


def test_cli_prints_the_table(grid):
    a, b = grid
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "same_history.py"), str(a), str(b), "--names", "x",
                        "y"], capture_output=True, text=True, env=ENV, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "| acquisition 1 (5) | 0.0000 | 8 | 1 | -0.50 | – | 0 / 1 | no |" in r.stdout


@pytest.mark.parametrize("which, expected", [("empty", "holds no finished run"), ("other", "share no finished seed")])
def test_bad_input_is_one_error_line(grid, tmp_path, which, expected):
    a, _ = grid
    other = tmp_path / "mic" / which
    other.mkdir()
    if which == "other":
        write_run(other, 7, [[2, 3, 4]], [14.0], 20.0)
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "same_history.py"), str(a), str(other)],
                       capture_output=True, text=True, env=ENV, timeout=120)
    assert r.returncode != 0 and r.stderr.strip().startswith("error:") and expected in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
