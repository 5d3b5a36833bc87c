"""recommend.py / recommender: same picks as train.py, foreign PLYs, pose files, generated poses, bad input."""
from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest
import torch
from plyfile import PlyData, PlyElement

from active import build_selector
from recommender.candidates import generate
from recommender.pipeline import load_model, make_pool, recommend
from scene.cameras import Camera, look_at
from scene.pose_files import read_pose_file
from scene.trained import load_trained
from tests.conftest import run_cli

FOCAL = 40.0  # px, for 32 x 32 test cameras


def _cameras_json(path, eyes, size=32):
    """A 3DGS cameras.json of cameras at `eyes` looking at the origin (z up), written from look_at directly."""
    entries = []
    for i, eye in enumerate(eyes):
        c2w = torch.linalg.inv(look_at(eye))
        entries.append({"id": i, "img_name": f"cap_{i}", "width": size, "height": size,
                        "position": c2w[:3, 3].tolist(), "rotation": c2w[:3, :3].tolist(), "fx": FOCAL, "fy": FOCAL})
    path.write_text(json.dumps(entries))
    return path


def _graphdeco_ply(path, n=300, degree=1, drop=(), order_seed=0):
    """A graphdeco-layout PLY written by hand: properties shuffled, normals included. Returns the columns."""
    g = np.random.default_rng(order_seed)
    cols = {"x": g.uniform(-0.6, 0.6, n), "y": g.uniform(-0.6, 0.6, n), "z": g.uniform(0.0, 0.8, n),
            "nx": np.zeros(n), "ny": np.zeros(n), "nz": np.ones(n), "opacity": g.uniform(-1, 2, n)}
    for i in range(3):
        cols[f"f_dc_{i}"] = g.uniform(-1, 1, n)
        cols[f"scale_{i}"] = np.full(n, math.log(0.05))
    for i in range(4):
        cols[f"rot_{i}"] = np.full(n, 1.0 if i == 0 else 0.0)
    for i in range(3 * ((degree + 1) ** 2 - 1) if degree >= 0 else 5):
        cols[f"f_rest_{i}"] = g.normal(0, 0.05, n)
    names = [k for k in cols if k not in drop]
    names = [names[i] for i in g.permutation(len(names))]
    data = np.empty(n, dtype=[(k, "f4") for k in names])
    for k in names:
        data[k] = cols[k]
    PlyData([PlyElement.describe(data, "vertex")]).write(str(path))
    return cols


EYES = [(4.0, 0.0, 1.5), (0.0, 4.0, 1.5), (-4.0, 0.5, 2.0)]


def test_same_picks_as_train_py_and_no_image_is_read(tiny_scene, tmp_path):
    data = tmp_path / "data"
    shutil.copytree(tiny_scene, data)
    model = tmp_path / "model"
    r = run_cli("train.py", "-s", str(data), "-m", str(model), "--method", "lite_gs", "--num_init_views", "2",
                "--views_per_step", "3", "--max_views", "5", "--iters_per_view", "10", "--iterations", "40",
                "--save_iterations", "20", "--seed", "3", "--quiet")
    assert r.returncode == 0, r.stderr
    stage = json.loads((model / "selection.json").read_text())["stages"][0]
    assert stage["iteration"] == 20
    shutil.rmtree(data)  # recommend reads poses only: no dataset, no image
    trained = load_trained(model, 20, cameras_only=True)  # what recommend.py reads the model directory with
    assert trained.scene is None and len(trained.train_cameras) == 14 and trained.record["dataset"]["num_test"] == 4
    out = tmp_path / "next"
    r = run_cli("recommend.py", "-m", str(model), "--iteration", "20", "--candidates", "unused", "-k", "3",
                "--method", "lite_gs", "--seed", "3", "-o", str(out), "--quiet")  # train.py's selector, not the default
    assert r.returncode == 0, r.stderr
    rec = json.loads((out / "recommendations.json").read_text())
    assert len(stage["selected"]) == 3 and [p["candidate"] for p in rec["picks"]] == stage["selected"]
    assert [p["gain"] for p in rec["picks"]] == pytest.approx(stage["gains"], rel=1e-9)
    assert rec["prior"]["view_ids"] == stage["train_views"]
    assert rec["oracle_calls"] == stage["oracle_calls"]
    assert rec["provenance"]["code"] == json.loads((model / "selection.json").read_text())["sessions"][0]["code"]
    assert len(r.stdout.splitlines()) == 4 and r.stdout.startswith("pick 1: ")
    for p in rec["picks"]:
        assert (out / p["preview"]).is_file() and (out / p["uncertainty_map"]).is_file()
    assert (out / "topdown.png").is_file()
    evaluated = [c for c in rec["candidate_gains"] if c["evaluated"]]
    assert len(evaluated) <= rec["oracle_calls"]["evaluated"] and len(rec["candidate_gains"]) == 12
    # The picks' transforms.json is one train.py's nerfstudio reader takes once the images are captured.
    frames = json.loads((out / "transforms.json").read_text())["frames"]
    assert len(frames) == len(rec["picks"])
    for p, f in zip(rec["picks"], frames):
        assert f["transform_matrix"] == p["transform_matrix"]
        c2w_cv = torch.tensor(p["c2w"], dtype=torch.float64)
        flip = torch.diag(torch.tensor([1.0, -1.0, -1.0, 1.0], dtype=torch.float64))
        assert torch.allclose(torch.tensor(f["transform_matrix"], dtype=torch.float64), c2w_cv @ flip)


@pytest.mark.auto_backend
def test_foreign_graphdeco_ply_loads_and_is_ranked(tmp_path):
    ply = tmp_path / "splat.ply"
    cols = _graphdeco_ply(ply, degree=1)
    captured = _cameras_json(tmp_path / "cameras.json", EYES)
    model = load_model(ply, captured)
    assert torch.allclose(model.gaussians.means, torch.tensor(np.stack([cols["x"], cols["y"], cols["z"]], 1),
                                                              dtype=torch.float32))
    assert model.gaussians.active_sh_degree == 1
    assert torch.allclose(model.gaussians.params["sh_rest"][:, 0, 1], torch.tensor(cols["f_rest_3"]).float())
    pool = make_pool(model, generate("orbit", 6, model.captured))
    rec = recommend(model, pool, build_selector("pop_gs"), 2)
    assert len(rec.picks) == 2 and all(g > 0 for g in rec.pick_gains)
    # pop_gs evaluates every candidate at every pick: the recorder holds each one's last gain, and the second pick
    # is the best of the second round (every candidate but the first pick).
    gains = rec.acquisition.evaluated_gains
    assert set(gains) == set(pool.candidate_ids)
    second_round = {v: g for v, g in gains.items() if v != rec.picks[0]}
    assert rec.picks[1] == max(second_round, key=second_round.get) and gains[rec.picks[1]] == rec.pick_gains[1]
    assert rec.acquisition.evaluated == 6 + 5 == rec.acquisition.selection.conservative


def test_pose_files_agree_with_look_at(tmp_path):
    eye = torch.tensor([3.0, -1.0, 2.0], dtype=torch.float64)
    w2c = look_at(eye)
    c2w_gl = torch.linalg.inv(w2c) @ torch.diag(torch.tensor([1.0, -1.0, -1.0, 1.0], dtype=torch.float64))
    (tmp_path / "t.json").write_text(json.dumps({"camera_angle_x": 0.8, "w": 64, "h": 48, "frames": [
        {"transform_matrix": c2w_gl.tolist()}]}))  # no file_path: allowed
    (tmp_path / "path.json").write_text(json.dumps({"render_width": 64, "render_height": 48, "camera_path": [
        {"camera_to_world": c2w_gl.flatten().tolist(), "fov": 50.0, "aspect": 4 / 3}]}))
    _cameras_json(tmp_path / "cams.json", [eye.tolist()])
    for name, fx in (("t.json", 32 / math.tan(0.4)), ("path.json", 24 / math.tan(math.radians(25))),
                     ("cams.json", FOCAL)):
        (cam,) = read_pose_file(tmp_path / name)
        assert torch.allclose(cam.viewmat.double(), w2c, atol=1e-6), name
        assert cam.fx == pytest.approx(fx) and cam.image is None


def test_generated_orbit_and_hemisphere_look_at_the_centre():
    captured = [Camera(i, f"c{i}", look_at(e).float(), FOCAL, FOCAL, 16, 16, 32, 32) for i, e in enumerate(EYES)]
    for kind, elevation in (("orbit", (20.0, 20.0)), ("hemisphere", (0.0, 80.0))):
        cams = generate(kind, 12, captured, elevation=elevation, radius=3.0)
        centre = torch.zeros(3)  # every captured camera looks at the origin
        for c in cams:
            pos = c.camera_center
            assert float(pos.norm()) == pytest.approx(3.0, abs=1e-3)
            p = c.viewmat[:3, :3] @ centre + c.viewmat[:3, 3]  # the centre in camera coordinates
            assert abs(float(p[0])) < 1e-3 and abs(float(p[1])) < 1e-3 and float(p[2]) > 0
            elev = math.degrees(math.asin(float(pos[2]) / 3.0))  # z is up for these cameras
            assert elevation[0] - 1e-3 <= elev <= elevation[1] + 1e-3
        if kind == "orbit":
            assert {round(math.degrees(math.asin(float(c.camera_center[2]) / 3.0)), 3) for c in cams} == {20.0}


@pytest.mark.auto_backend
def test_invisible_candidates_come_last_with_gain_zero(tmp_path):
    ply = tmp_path / "splat.ply"
    _graphdeco_ply(ply, degree=0)
    model = load_model(ply, _cameras_json(tmp_path / "cameras.json", EYES))
    seeing = [Camera(0, "a", look_at((0.0, -4.0, 1.0)).float(), FOCAL, FOCAL, 16, 16, 32, 32),
              Camera(1, "b", look_at((3.0, 3.0, 2.0)).float(), FOCAL, FOCAL, 16, 16, 32, 32)]
    away = look_at((0.0, 0.0, 20.0), (0.0, 0.0, 40.0), (0.0, 1.0, 0.0)).float()  # looks away from the scene
    blind = Camera(2, "blind", away, FOCAL, FOCAL, 16, 16, 32, 32)
    for method in ("lite_gs", "random", "coverage"):
        pool = make_pool(model, [blind] + seeing)  # the blind one has the lowest id
        rec = recommend(model, pool, build_selector(method), 3)
        assert [pool.names[v] for v in rec.picks][-1] == "blind" and rec.pick_gains[-1] == 0.0, method
        assert any("see no Gaussian" in n and "blind" in n for n in rec.notes)
        rec = recommend(model, pool, build_selector(method), 2)
        assert "blind" not in [pool.names[v] for v in rec.picks], method
    rec = recommend(model, make_pool(model, seeing), build_selector("pop_gs"), 5)
    assert len(rec.picks) == 2 and any("K=5 exceeds the 2 candidates" in n for n in rec.notes)


def _cli_error(tmp_path, *args):
    out = tmp_path / "out"
    r = run_cli("recommend.py", *args, "-o", str(out), "--quiet")
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in r.stderr, r.stderr
    assert not out.exists() and not list(tmp_path.glob(".out.*"))  # nothing half-written
    return lines[0]


def test_bad_input_is_one_error_line(tmp_path):
    captured = _cameras_json(tmp_path / "cameras.json", EYES)
    missing = tmp_path / "missing.ply"
    _graphdeco_ply(missing, drop=("opacity", "rot_2"))
    assert "opacity" in (line := _cli_error(tmp_path, "-m", str(missing), "--captured", str(captured))) and \
        "rot_2" in line
    bad_sh = tmp_path / "sh.ply"
    _graphdeco_ply(bad_sh, degree=-1)  # 5 f_rest coefficients
    assert "5 f_rest" in _cli_error(tmp_path, "-m", str(bad_sh), "--captured", str(captured))
    ply = tmp_path / "splat.ply"
    _graphdeco_ply(ply)
    assert "--captured" in _cli_error(tmp_path, "-m", str(ply), "--candidates", "orbit:4")
    good = torch.linalg.inv(look_at((3.0, 0.0, 1.0))).tolist()
    nan = [row[:] for row in good]
    nan[1][3] = float("nan")
    skew = [row[:] for row in good]
    skew[0][0] += 0.5
    for frames, expected in (([{"transform_matrix": good}, {"transform_matrix": nan}], "frame 1: the pose holds "
                                                                                         "a non-finite value"),
                             ([{"transform_matrix": skew}], "frame 0: the rotation part of the pose is not a rotation"),
                             ([], "lists no cameras")):
        cand = tmp_path / "cand.json"
        cand.write_text(json.dumps({"camera_angle_x": 0.7, "frames": frames}))
        assert expected in _cli_error(tmp_path, "-m", str(ply), "--captured", str(captured), "--candidates",
                                      str(cand))
    assert "N must be positive" in _cli_error(tmp_path, "-m", str(ply), "--captured", str(captured),
                                              "--candidates", "orbit:0")


def test_same_picks_as_train_py_on_a_model_continued_from_a_ply(tiny_scene, tmp_path):
    """A run continued with --init_ply trains with every SH band from its first iteration; recommend.py must
    rebuild that degree (not one band per 1,000 iterations) to give the run's own gains."""
    base = tmp_path / "base"
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(base), "--iterations", "30", "--seed", "1", "--quiet")
    assert r.returncode == 0, r.stderr
    model = tmp_path / "continued"
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(model), "--init_ply",
                str(base / "point_cloud" / "iteration_30" / "point_cloud.ply"), "--method", "pop_gs",
                "--num_init_views", "2", "--views_per_step", "3", "--max_views", "5", "--iters_per_view", "10",
                "--iterations", "40", "--save_iterations", "20", "--seed", "3", "--quiet")
    assert r.returncode == 0, r.stderr
    stage = json.loads((model / "selection.json").read_text())["stages"][0]
    out = tmp_path / "rec"
    r = run_cli("recommend.py", "-m", str(model), "--iteration", "20", "--candidates", "unused", "-k", "3",
                "--method", "pop_gs", "-o", str(out), "--no_previews", "--quiet")
    assert r.returncode == 0, r.stderr
    rec = json.loads((out / "recommendations.json").read_text())
    assert [p["gain"] for p in rec["picks"]] == pytest.approx(stage["gains"], rel=1e-9)
