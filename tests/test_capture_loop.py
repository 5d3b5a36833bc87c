"""experiments/closed_capture_loop.py (CLI scripts/capture_loop.py): the built-in ground truth "captured" at given
poses, and the summary and plot of an output folder (the loop itself trains with train.py:
`test_the_cli_runs_one_round`, slow)."""
import argparse
import json
import logging
import math

import pytest
import torch

from experiments.closed_capture_loop import (FirstNoteOnly, capture, run_capture_loop, run_loop, start_positions,
                                             summary_table, train)
from scene.builtin import CAMERA_ANGLE_X, hemisphere_positions
from scene.cameras import look_at
from scene.frames import GL_TO_CV
from scene.pose_files import read_pose_file
from tests.conftest import ROOT, run_cli
from utils.errors import UserError
from utils.image import load_rgba


@pytest.mark.auto_backend  # the built-in ground truth renders with the user's default, as the script does
def test_capture_writes_images_and_frames_that_read_back_as_the_poses(tmp_path):
    viewmats = [look_at(eye) for eye in hemisphere_positions(2, 0.5)]
    (tmp_path / "train").mkdir()
    frames = capture(tmp_path, viewmats, 16, 0, 5)
    assert [f["file_path"] for f in frames] == ["./train/c_005", "./train/c_006"]
    for f, viewmat in zip(frames, viewmats):
        assert load_rgba(tmp_path / (f["file_path"] + ".png")).shape[-2:] == (16, 16)
        c2w = torch.linalg.inv(viewmat.double()) @ GL_TO_CV
        assert torch.allclose(torch.tensor(f["transform_matrix"], dtype=torch.float64), c2w)
    (tmp_path / "transforms.json").write_text(json.dumps({"camera_angle_x": CAMERA_ANGLE_X, "frames": frames}))
    cams = read_pose_file(tmp_path / "transforms.json", default_size=(16, 16))
    assert len(cams) == 2 and math.isclose(cams[0].fx, 8 / math.tan(CAMERA_ANGLE_X / 2), rel_tol=1e-6)
    for cam, viewmat in zip(cams, viewmats):
        assert torch.allclose(cam.viewmat.double(), viewmat.double(), atol=1e-5)


def test_random_start_turns_the_start_views_about_the_up_axis_by_a_seed_drawn_azimuth():
    fixed = hemisphere_positions(3, 0.5)
    assert torch.equal(start_positions("first", 7), fixed)
    turned = {seed: start_positions("random", seed) for seed in (0, 1)}
    for positions in turned.values():
        assert torch.allclose(positions[:, 2], fixed[:, 2])  # same elevations
        assert torch.allclose(torch.cdist(positions, positions), torch.cdist(fixed, fixed))  # a rotation
        assert not torch.allclose(positions, fixed, atol=1e-3)
    assert not torch.allclose(turned[0], turned[1], atol=1e-3)
    assert torch.equal(start_positions("random", 0), turned[0])  # drawn from the seed alone


def test_plot_only_draws_and_tables_every_method_folder(tmp_path):
    runs = tmp_path / "runs"
    for method, psnr in (("coverage", 20.0), ("lite_gs", 21.0)):
        folder = runs / method / "seed0"
        folder.mkdir(parents=True)
        rounds = [{"views": 3, "test_psnr": psnr}, {"views": 5, "test_psnr": psnr + 1}]
        (folder / "loop.json").write_text(json.dumps({"method": method, "seed": 0, "rounds": rounds}))
    (runs / "builtin_r32").mkdir()  # the shared ground-truth scene: not a method
    png = tmp_path / "plot" / "psnr.png"

    args = type("Args", (), {"plot": str(runs), "png": str(png), "output": str(tmp_path / "unused")})()
    run_capture_loop(args)
    assert png.is_file() and png.stat().st_size > 0
    assert not (tmp_path / "unused").exists()
    summary = (runs / "summary.md").read_text()  # rewritten from the folders: a method added later joins the table
    assert "| coverage | 1 | 20.00 ± 0.00 | 21.00 ± 0.00 |" in summary and "| lite_gs | 1 |" in summary
    assert "builtin_r32" not in summary


def test_summary_tables_mean_and_std_over_seeds(tmp_path):
    for seed, psnr in ((0, 20.0), (1, 22.0)):
        folder = tmp_path / "random" / f"seed{seed}"
        folder.mkdir(parents=True)
        rounds = [{"views": 3, "test_psnr": psnr}, {"views": 5, "test_psnr": psnr + 1}]
        (folder / "loop.json").write_text(json.dumps({"method": "random", "seed": seed, "rounds": rounds}))
    table = summary_table(tmp_path)
    assert "| method | seeds | 3 views | 5 views |" in table
    assert "| random | 2 | 21.00 ± 1.00 | 22.00 ± 1.00 |" in table


def _loop_args(tmp_path, **changes):
    flags = {"methods": ["coverage"], "seeds": [0], "output": str(tmp_path), "resolution": 32, "num_test": 8,
             "budget": 9, "k": 2, "candidates": 24, "elevation": (10.0, 75.0), "seed_start": "random",
             "iters_per_view": 40, "max_gaussians": 4000, "num_random_points": 10_000, "plot": None, "png": None,
             "overwrite": False}
    return argparse.Namespace(**(flags | changes))


def test_a_finished_loop_is_kept_and_one_of_other_flags_is_an_error(tmp_path):
    """An interrupted run resumes at its first unfinished loop: a finished loop of the same flags is not run again
    (nothing is trained here: the folder holds only its loop.json), one of other flags is one error line."""
    out = tmp_path / "coverage" / "seed0"
    out.mkdir(parents=True)
    finished = {"method": "coverage", "seed": 0, "rounds": [{"views": 3, "test_psnr": 10.0}],
                "settings": vars(_loop_args(tmp_path, methods=["coverage", "random"], seeds=[0, 1, 2]))
                | {"elevation": [10.0, 75.0]}}
    (out / "loop.json").write_text(json.dumps(finished))
    assert run_loop("coverage", 0, out, _loop_args(tmp_path)) == finished
    assert sorted(p.name for p in out.iterdir()) == ["loop.json"]
    with pytest.raises(UserError, match=r"ran with other flags \(--num_random_points 10000 against 3000\).*--overwrite"):
        run_loop("coverage", 0, out, _loop_args(tmp_path, num_random_points=3000))


def test_loops_of_other_flags_are_not_tabled_together(tmp_path):
    for method, points in (("coverage", 10_000), ("random", 3000)):
        folder = tmp_path / method / "seed0"
        folder.mkdir(parents=True)
        settings = vars(_loop_args(tmp_path, num_random_points=points)) | {"elevation": [10.0, 75.0]}
        (folder / "loop.json").write_text(json.dumps({"rounds": [{"views": 3, "test_psnr": 10.0}],
                                                      "settings": settings}))
    with pytest.raises(UserError, match="random/seed0/loop.json and .*coverage/seed0/loop.json ran with different "
                                        "flags .--num_random_points 3000 against 10000"):
        summary_table(tmp_path)
    old = tmp_path / "random" / "seed0" / "loop.json"  # a loop from before --num_random_points: it ran with 10,000
    record = json.loads(old.read_text())
    del record["settings"]["num_random_points"]
    old.write_text(json.dumps(record))
    assert "| random | 1 |" in summary_table(tmp_path)


def test_a_failed_training_is_one_error_line_with_train_pys_reason(tmp_path):
    with pytest.raises(UserError, match=r"^train.py failed on .*nope: --num_random_points must be at least 1, got -5$"):
        train(tmp_path / "nope", tmp_path / "model", 10, 0, 500, -5)


@pytest.mark.parametrize("folder", ["missing", "empty"])
def test_plot_of_a_folder_without_loops_is_one_error_line(folder, tmp_path):
    (tmp_path / "empty").mkdir()
    r = run_cli(str(ROOT / "scripts" / "capture_loop.py"), "--plot", str(tmp_path / folder))
    assert r.returncode == 2 and r.stderr.strip().splitlines()[-1].startswith("error: --plot")
    assert "Traceback" not in r.stderr
    assert list((tmp_path / "empty").iterdir()) == []  # no empty summary or plot left behind


@pytest.mark.parametrize("bad", ["10", "80,10", "a,b", "0,95"])
def test_a_bad_elevation_range_is_one_error_line(bad, tmp_path):
    r = run_cli(str(ROOT / "scripts" / "capture_loop.py"), "--elevation", bad, "-o", str(tmp_path / "x"))
    assert r.returncode == 2 and "--elevation" in r.stderr.strip().splitlines()[-1]
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_the_cli_runs_one_round(tmp_path):
    out = tmp_path / "loop"
    r = run_cli(str(ROOT / "scripts" / "capture_loop.py"), "--methods", "coverage", "--seeds", "0", "1", "-o", str(out),
                "--resolution", "16", "--num_test", "2", "--budget", "5", "-k", "2", "--candidates", "6",
                "--iters_per_view", "10", "--max_gaussians", "500", "--png", str(tmp_path / "psnr.png"),
                "--elevation", "10,75", "--seed_start", "random", "--num_random_points", "700", timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    cfg = json.loads((out / "coverage" / "seed0" / "model" / "cfg_args").read_text())
    assert cfg["model"]["num_random_points"] == 700  # --num_random_points reaches train.py
    for seed in (0, 1):  # each seed started from its own turned views
        frames = json.loads((out / "coverage" / f"seed{seed}" / "data" / "transforms_train.json").read_text())["frames"]
        centres = torch.tensor([[f["transform_matrix"][i][3] for i in range(3)] for f in frames[:3]],
                               dtype=torch.float64)
        assert torch.allclose(centres, start_positions("random", seed), atol=1e-5)
    loop = json.loads((out / "coverage" / "seed0" / "loop.json").read_text())
    assert [r["views"] for r in loop["rounds"]] == [3, 5]
    assert loop["settings"]["plot"] is None and loop["settings"]["budget"] == 5
    rec = json.loads((out / "coverage" / "seed0" / "recommend_03" / "recommendations.json").read_text())
    for pick in rec["picks"]:  # the built-in scene: up = +z, centred at the origin
        x, y, z = pick["c2w"][0][3], pick["c2w"][1][3], pick["c2w"][2][3]
        assert 10 - 1e-3 <= math.degrees(math.atan2(z, math.hypot(x, y))) <= 75 + 1e-3
    assert "| coverage | 2 |" in (out / "summary.md").read_text()
    notes = [line for line in (r.stdout + r.stderr).splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and "geometric" in notes[0], notes  # the advice once per method, not once per round
    assert (tmp_path / "psnr.png").is_file()


def test_first_note_only_passes_one_note_and_every_warning(caplog):
    logger = logging.getLogger("test_first_note_only")
    logger.addFilter(FirstNoteOnly())
    with caplog.at_level(logging.WARNING, logger="test_first_note_only"):
        for message in ("note: 3 captured views", "warning: 1 candidate sees no Gaussian", "note: 5 captured views",
                        "warning: 2 candidates see no Gaussian"):
            logger.warning(message)
    assert [r.getMessage() for r in caplog.records] == ["note: 3 captured views", "warning: 1 candidate sees no Gaussian",
                                                        "warning: 2 candidates see no Gaussian"]
