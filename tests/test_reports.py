"""HTML reports (reports/, report.py): contents of the run, grid and recommendation reports, frustum geometry,
mean ± std over seeds, bad input. The browser checks are in test_report_browser.py."""
from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest
import torch

from reports import write_grid_report, write_recommendation_report, write_run_report
from reports.cameras import CameraView, frustum_corners
from reports.figures import CAMERA_META, scene_figure
from reports.grid_data import find_runs, mean_curve
from reports.run_data import gather_run
from scene.cameras import look_at
from tests.conftest import run_cli
from tests.report_fixtures import make_grid, make_recommendation

NUM_CAMERAS = 4 + 14  # tiny scene: 4 test cameras, 14 training views


def markers(fig) -> int:
    return sum(len(t.x) for t in fig.data if t.meta == CAMERA_META)


def offline(html: str) -> None:
    """No element of the page loads anything from elsewhere."""
    assert not re.search(r"<(script|img|link|iframe)[^>]+(src|href)=['\"](?!data:)", html)
    assert "cdn.plot.ly" not in html.split("<body>")[1]


def test_frustum_corners_project_to_the_image_corners():
    viewmat = look_at([3.0, -2.0, 1.5], [0.2, 0.1, 0.0])  # [4, 4] world-to-camera
    c2w = torch.linalg.inv(viewmat).numpy()
    cam = CameraView("c", "g", "#000000", c2w[:3, 3], c2w[:3, :3], fx=50.0, fy=40.0, width=64, height=48)
    corners = frustum_corners(cam, depth=0.7)  # [4, 3]
    cam_pts = corners @ viewmat[:3, :3].numpy().T + viewmat[:3, 3].numpy()
    pixels = np.stack([50.0 * cam_pts[:, 0] / cam_pts[:, 2] + 32, 40.0 * cam_pts[:, 1] / cam_pts[:, 2] + 24], 1)
    np.testing.assert_allclose(cam_pts[:, 2], 0.7, atol=1e-12)
    np.testing.assert_allclose(pixels, [[0, 0], [64, 0], [64, 48], [0, 48]], atol=1e-9)


def test_run_report_shows_every_camera_stage_metric_and_view(active_model, tmp_path):
    sel = json.loads((active_model / "selection.json").read_text())
    run = gather_run(active_model)
    groups = [c.group for c in run.cameras]
    assert len(run.cameras) == NUM_CAMERAS and markers(scene_figure(run.points, run.point_colors, run.cameras)) == 18
    assert groups.count("test cameras") == 4 and groups.count("seed views") == 2
    assert groups.count("stage 0 picks") == 3 and groups.count("stage 1 picks") == 3
    assert groups.count("candidates not picked") == 14 - 8
    picks = [c for c in run.cameras if c.label]
    assert [c.label for c in picks] == [str(i) for i in range(1, 7)]
    assert [c.info["view"] for c in picks] == sel["stages"][0]["selected"] + sel["stages"][1]["selected"]
    assert [c.gain for c in picks] == sel["stages"][0]["gains"] + sel["stages"][1]["gains"]
    assert run.incomplete is None and not run.absent
    assert [p[0] for p in run.psnr_curve()] == [2, 5, 8]

    out = write_run_report(active_model, tmp_path / "r.html")
    html = out.read_text()
    offline(html)
    # render.py --uncertainty writes all 3 kinds: 4 test views x (gt, render, error, 3 maps) + 3 colour bars
    assert html.count("class='zoom'") == 4 * 6 + 3
    folder = active_model / "test" / "ours_70" / "uncertainty"
    for kind in ("fisherrf", "fisherrf_view", "position_variance"):
        assert f"<div class='head'>uncertainty: {kind}</div>" in html
        assert f"00001.png uncertainty: {kind}" in html and f"colour bar: {kind}" in html
        assert run.colorbars[kind] == folder / kind / "colorbar.png"
        assert [g.uncertainty[kind] for g in run.gallery] == [folder / kind / f"{i:05d}.png" for i in range(4)]
    results = json.loads((active_model / "results.json").read_text())["ours_70"]
    unc_keys = [k for k in results if k.startswith(("Spearman/", "AUSE_"))]
    assert len(unc_keys) >= 3 * 2 * 2  # Spearman and >= 1 AUSE variant x 3 kinds x (image, object)
    for key in unc_keys:
        metric, kind, region = key.split("/")
        assert f"<tr><td>{metric}</td><td>{kind}</td><td>{region}</td><td>{results[key]:.4f}</td></tr>" in html
    assert f"{results['PSNR']:.2f}" in html and "(squeeze)" in html
    for stage in sel["stages"]:
        assert f"{stage['gains'][0]:.3g}" in html
    assert "commit" in html and "pop_gs" in html and "-r " in html


def test_run_report_cli_defaults_to_the_model_dir(active_model, tmp_path):
    assert "Run report" in (active_model / "report.html").read_text()  # metrics.py --report wrote it
    model = tmp_path / "m"
    shutil.copytree(active_model, model)
    (model / "report.html").unlink()
    r = run_cli("report.py", "-m", str(model))
    assert r.returncode == 0, r.stderr
    assert (model / "report.html").is_file() and "wrote" in r.stdout


def test_run_without_selection_shows_what_exists(active_model, tmp_path):
    model = tmp_path / "m"
    shutil.copytree(active_model, model)
    (model / "selection.json").unlink()
    run = gather_run(model)
    assert {c.group for c in run.cameras} == {"test cameras", "training views"} and len(run.cameras) == 18
    assert any(a.startswith("selection.json") for a in run.absent)
    html = write_run_report(model).read_text()
    assert "absent: selection.json" in html and "Final metrics" in html


def test_killed_run_is_marked_incomplete(active_model, tmp_path):
    model = tmp_path / "m"
    shutil.copytree(active_model, model)
    sel = json.loads((model / "selection.json").read_text())
    sel["stages"], _ = sel["stages"][:1], sel.pop("final")
    (model / "selection.json").write_text(json.dumps(sel))
    (model / "run_status.json").write_text(json.dumps({"status": "running", "iteration": 30, "total_iterations": 70}))
    for d in ("point_cloud", "test", "results.json", "per_view.json"):
        shutil.rmtree(model / d) if (model / d).is_dir() else (model / d).unlink()
    run = gather_run(model)
    assert "at iteration 30 of 70" in run.incomplete and "1 acquisition stages" in run.incomplete
    assert [c.label for c in run.cameras if c.label] == ["1", "2", "3"] and len(run.cameras) == 18
    assert "initial points" in run.points_note
    html = write_run_report(model).read_text()
    assert "incomplete" in html and "absent: results.json" in html


def test_bad_input_is_one_error_line(active_model, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    for args, needle in ((["-m", str(active_model), "-o", str(blocker / "r.html")], "cannot write the report"),
                         (["-m", str(tmp_path / "none")], "not a directory"),
                         (["-m", str(tmp_path)], "neither cfg_args nor cameras.json"),
                         (["--grid", str(tmp_path)], "no runs under"),
                         (["--recommendation", str(tmp_path)], "recommendations.json")):
        r = run_cli("report.py", *args)
        assert r.returncode == 2, (args, r.stderr)
        assert r.stderr.startswith("error: ") and needle in r.stderr and r.stderr.count("\n") == 1, r.stderr


def test_mean_curve_over_seeds():
    x, mean, std = mean_curve([[(2, 10.0), (5, 14.0)], [(2, 12.0), (5, 18.0), (8, 20.0)]])
    np.testing.assert_array_equal(x, [2, 5, 8])
    np.testing.assert_allclose(mean, [11.0, 16.0, 20.0])
    np.testing.assert_allclose(std, [1.0, 2.0, 0.0])


def test_grid_report_compares_methods_and_links_runs(active_model, tmp_path):
    setup = tmp_path / "out" / "setup1"
    make_grid(setup, active_model)
    runs = find_runs(setup)
    assert [(r.tag, r.seed) for r in runs] == [("pop_gs", 0), ("pop_gs", 1), ("random", 0)]
    a, b = runs[0], runs[1]
    assert [p[1] - q[1] for p, q in zip(b.curve, a.curve)] == pytest.approx([1.0] * len(a.curve))
    assert b.oracle_evaluated - a.oracle_evaluated == 2 * 2  # two stages, + 2 each
    html = write_grid_report(setup).read_text()
    offline(html)
    psnr = json.loads((active_model / "results.json").read_text())["ours_70"]["PSNR"]
    assert f"{psnr + 0.5:.2f} ± {0.5:.2f}" in html  # mean and population std of PSNR and PSNR + 1
    for r in runs:
        assert (r.path / "report.html").is_file()
        assert f"href='tiny/{r.tag}/seed{r.seed}/report.html'" in html


@pytest.mark.parametrize("captured", [True, False])
def test_recommendation_report_draws_captured_candidates_and_picks(active_model, tmp_path, captured):
    from reports.recommendation_data import gather_recommendation

    folder = tmp_path / "next"
    record = make_recommendation(folder, active_model, captured)
    data = gather_recommendation(folder)
    groups = [c.group for c in data.cameras]
    assert groups.count("captured views") == (3 if captured else 2)
    assert groups.count("picks") == 2 and groups.count("candidates (by gain)") == 2
    assert groups.count("candidates not evaluated") == 2
    assert [c.label for c in data.cameras if c.label] == ["1", "2"]
    assert [c.gain for c in data.cameras if c.group == "candidates (by gain)"] == [0.5, 0.75]
    fig = scene_figure(data.points, data.point_colors, data.cameras)
    assert markers(fig) == len(record.get("captured", [0, 1])) + len(record["candidate_gains"])
    by_gain = [t for t in fig.data if t.name and t.name.startswith("candidates (by gain)")][0]
    assert list(by_gain.marker.color) == [0.5, 0.75] and by_gain.marker.cmax == 0.75
    html = write_recommendation_report(folder).read_text()
    offline(html)
    assert html.count("class='zoom'") == 2 and "absent</figure>" in html and "hand-made test fixture" in html
