"""The bad-input catalogue: every case exits non-zero with one `error:` line on stderr that names the problem,
no traceback, and no output directory that looks complete.

A few cases (one per CLI, one failing mid-run) run as subprocesses and check that contract end to end; the rest
call the CLI's `main` in-process and check the `UserError` it raises (`utils.errors.run_cli` turns exactly that
into the one `error:` line and exit status 2). Both check that nothing complete-looking was written.
"""
from __future__ import annotations

import importlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image

from scene.gaussian_model import GaussianModel
from tests.conftest import ROOT, run_cli
from tests.scenes import random_gaussians
from utils.errors import UserError

TRAIN_FAST = ["--iterations", "5", "--num_random_points", "200", "--quiet"]
ACTIVE = ["--method", "lite_gs", "--num_init_views", "2", "--views_per_step", "2", "--max_views", "6",
          "--iters_per_view", "1"]


def copy_scene(tiny_scene: Path, dest: Path) -> Path:
    shutil.copytree(tiny_scene, dest)
    return dest


def setup_missing_source(tiny_scene, tmp):
    return ["train.py", "-s", str(tmp / "nope"), "-m", str(tmp / "m")], "does not exist"


def setup_empty_source(tiny_scene, tmp):
    (tmp / "empty").mkdir()
    return ["train.py", "-s", str(tmp / "empty"), "-m", str(tmp / "m")], "empty"


def setup_unknown_layout(tiny_scene, tmp):
    (tmp / "junk").mkdir()
    (tmp / "junk" / "notes.txt").write_text("hello")
    return ["train.py", "-s", str(tmp / "junk"), "-m", str(tmp / "m")], "neither a Blender"


def setup_malformed_json(tiny_scene, tmp):
    scene = copy_scene(tiny_scene, tmp / "s")
    (scene / "transforms_train.json").write_text('{"frames": [')
    return ["train.py", "-s", str(scene), "-m", str(tmp / "m")], "not valid JSON"


def setup_missing_key(tiny_scene, tmp):
    scene = copy_scene(tiny_scene, tmp / "s")
    data = json.loads((scene / "transforms_train.json").read_text())
    del data["frames"][3]["transform_matrix"]
    (scene / "transforms_train.json").write_text(json.dumps(data))
    return ["train.py", "-s", str(scene), "-m", str(tmp / "m")], "frame 3"


def setup_missing_image(tiny_scene, tmp):
    scene = copy_scene(tiny_scene, tmp / "s")
    (scene / "train" / "r_5.png").unlink()
    return (["train.py", "-s", str(scene), "-m", str(tmp / "m")],
            "train/r_5.png; first listed at transforms_train.json frame 5")


def setup_mixed_sizes(tiny_scene, tmp):
    scene = copy_scene(tiny_scene, tmp / "s")
    Image.new("RGBA", (20, 20)).save(scene / "train" / "r_2.png")
    return ["train.py", "-s", str(scene), "-m", str(tmp / "m")], "one size"


def setup_negative_random_points(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), "--num_random_points", "-5"], \
        "--num_random_points must be at least 1, got -5"


def setup_bad_resolution(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), "-r", "0"], "--resolution"


def setup_eps(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--eps", "1.5"], "--eps"


def setup_k_zero(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--views_per_step", "0"], "--views_per_step"


def setup_budget_over_pool(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--max_views", "50"], "--max_views"


def setup_seed_set_over_pool(tiny_scene, tmp):
    return (["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--num_init_views", "14",
             "--max_views", "14"], "--num_init_views")


def setup_excluded_view_outside_pool(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--exclude_views", "3", "99"], \
        "--exclude_views must be distinct view ids"


def setup_excluded_seed_view(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--init_views", "0", "5",
            "--exclude_views", "5"], "also in --exclude_views"


def setup_stage_method_malformed(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--stage_method", "coverage"], \
        "--stage_method takes STAGE:NAME"


def setup_stage_method_unknown_selector(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--stage_method", "0:greedy"], \
        "unknown selector 'greedy' in --stage_method"


def setup_stage_method_beyond_the_plan(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--stage_method", "2:coverage"], \
        "this run makes 2 (0 to 1"


def setup_stage_method_without_method(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), "--stage_method", "0:coverage"], \
        "pass --method too"


def setup_negative_keep_checkpoints(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--keep_checkpoints", "-1"], \
        "--keep_checkpoints must be >= 0"


def setup_unknown_method(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), "--method", "greedy"], "choose one of"


def setup_non_finite_loss(tiny_scene, tmp):
    # An infinite colour learning rate turns the SH coefficients into inf/NaN after the first Adam step.
    return (["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *TRAIN_FAST, "--feature_lr", "inf"],
            "non-finite at iteration")


def setup_unwritable_output(tiny_scene, tmp):
    (tmp / "a_file").write_text("x")
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "a_file" / "m"), *TRAIN_FAST], "cannot write"


def setup_corrupt_checkpoint(tiny_scene, tmp):
    model = tmp / "m"
    (model / "checkpoints").mkdir(parents=True)
    (model / "run_status.json").write_text('{"status": "running"}')
    (model / "checkpoints" / "chkpnt_0000010.pt").write_bytes(b"PK\x03\x04 truncated")
    return ["train.py", "-s", str(tiny_scene), "-m", str(model), *TRAIN_FAST], "corrupt or truncated"


def setup_corrupt_ply(tiny_scene, tmp):
    model = tmp / "m"
    (model / "point_cloud" / "iteration_5").mkdir(parents=True)
    (model / "point_cloud" / "iteration_5" / "point_cloud.ply").write_bytes(b"ply\nformat ascii 1.0\nelement")
    (model / "cfg_args").write_text(json.dumps({"model": {"source_path": str(tiny_scene), "eval": True},
                                                "pipeline": {}}))
    return ["render.py", "-m", str(model), "--quiet"], "cannot read PLY"


def setup_fisherrf_lambda(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--method", "fisherrf",
            "--fisherrf_lambda", "0"], "--fisherrf_lambda must be positive"


def setup_fisherrf_params(tiny_scene, tmp):
    return ["train.py", "-s", str(tiny_scene), "-m", str(tmp / "m"), *ACTIVE, "--method", "fisherrf",
            "--fisherrf_params", "means,rotation"], "unknown: rotation"


def setup_uncertainty_without_views(tiny_scene, tmp):
    model = tmp / "m"  # an active run's model without selection.json
    (model / "point_cloud" / "iteration_5").mkdir(parents=True)
    p = random_gaussians(4, seed=0, sh_degree=0)
    gaussians = GaussianModel(0, {"means": p["means"], "quats": p["quats"], "log_scales": p["log_scales"],
                                  "logit_opacities": p["logit_opacities"], "sh_dc": p["sh_coeffs"][:, :1],
                                  "sh_rest": p["sh_coeffs"][:, 1:]})
    gaussians.save_ply(model / "point_cloud" / "iteration_5" / "point_cloud.ply")
    (model / "cfg_args").write_text(json.dumps({"model": {"source_path": str(tiny_scene), "eval": True},
                                                "pipeline": {}, "active": {"method": "lite_gs"}}))
    return ["render.py", "-m", str(model), "--uncertainty", "--quiet"], "no training views recorded"


def setup_metrics_no_renders(tiny_scene, tmp):
    (tmp / "m").mkdir()
    return ["metrics.py", "-m", str(tmp / "m")], "no rendered test views"


def setup_truncated_selection(tiny_scene, tmp):
    run = tmp / "out" / "setup1" / "lego" / "lite_gs" / "seed0"
    run.mkdir(parents=True)
    (run / "selection.json").write_text('{"config": {"method": "lite_gs"}, "stages": [{"stage": 0, ')
    return ["scripts/summarize.py", str(tmp / "out")], "truncated"


def setup_script_missing_scene(tiny_scene, tmp):
    (tmp / "data" / "ship").mkdir(parents=True)
    return ["bash", "scripts/setup1.sh", "--data", str(tmp / "data"), "--scenes", "lego", "--out",
            str(tmp / "out")], "scenes in"


def tiny_capture(tmp: Path, change=None) -> Path:
    """A 27x48 phone capture (transforms.json with k1 k2 p1 p2, no aabb_scale so nothing is logged).
    The other transforms.json errors (no intrinsics, unknown camera_model, unreadable points) are checked at the
    loader in tests/test_transforms_json.py."""
    from scene.phone_capture import make_phone_capture
    root = make_phone_capture(tmp / "cap", 27, 48, num_frames=6, missing=0)
    data = json.loads((root / "transforms.json").read_text())
    del data["aabb_scale"]
    if change:
        change(data)
    (root / "transforms.json").write_text(json.dumps(data))
    return root


def setup_ns_size_mismatch(tiny_scene, tmp):
    root = tiny_capture(tmp, lambda d: d.update(w=30))
    return (["train.py", "-s", str(root), "-m", str(tmp / "m")],
            "frame_00001.jpg is 27x48 but the intrinsics are for 30x48")


def setup_ns_bad_distortion(tiny_scene, tmp):
    root = tiny_capture(tmp, lambda d: d.update(k1=-1.0))
    return ["train.py", "-s", str(root), "-m", str(tmp / "m")], "undistortion failed"


def setup_ns_truncated_jpeg(tiny_scene, tmp):
    root = tiny_capture(tmp)
    image = root / "images" / "frame_00003.jpg"
    image.write_bytes(image.read_bytes()[:300])
    return ["train.py", "-s", str(root), "-m", str(tmp / "m")], "truncated or corrupt"


def setup_ns_missing_images(tiny_scene, tmp):
    root = tiny_capture(tmp)
    (root / "images" / "frame_00002.jpg").unlink()
    return ["train.py", "-s", str(root), "-m", str(tmp / "m")], "1 of 6 listed images are missing"


def setup_truncated_png(tiny_scene, tmp):
    scene = copy_scene(tiny_scene, tmp / "s")
    image = scene / "train" / "r_4.png"
    image.write_bytes(image.read_bytes()[:-200])
    return ["train.py", "-s", str(scene), "-m", str(tmp / "m")], "truncated or corrupt"


CASES = {name[len("setup_"):]: fn for name, fn in globals().items() if name.startswith("setup_")}


SUBPROCESS_CASES = {"missing_source", "non_finite_loss", "corrupt_ply", "metrics_no_renders", "truncated_selection",
                    "script_missing_scene"}  # train.py, train.py mid-run, render.py, metrics.py, a script, bash


def assert_nothing_complete(tmp_path: Path) -> None:
    for status in tmp_path.rglob("run_status.json"):
        assert json.loads(status.read_text())["status"] != "complete"
    assert not list(tmp_path.rglob("results.json"))


@pytest.mark.auto_backend  # the CLIs' default backend, as a user runs them
@pytest.mark.parametrize("case", sorted(SUBPROCESS_CASES))
def test_bad_input_fails_cleanly(case, tiny_scene, tmp_path):
    args, needle = CASES[case](tiny_scene, tmp_path)
    if args[0] == "bash":
        r = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=120)
    else:
        r = run_cli(*args)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2, f"{case}: exit {r.returncode}\n{r.stdout}\n{r.stderr}"
    assert "Traceback" not in r.stderr, r.stderr
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert needle in lines[0], lines[0]
    assert_nothing_complete(tmp_path)


@pytest.mark.auto_backend  # the CLIs' default backend, as a user runs them
@pytest.mark.parametrize("case", sorted(set(CASES) - SUBPROCESS_CASES))
def test_bad_input_raises_one_line_user_error(case, tiny_scene, tmp_path, monkeypatch):
    args, needle = CASES[case](tiny_scene, tmp_path)
    assert args[0] in ("train.py", "render.py", "metrics.py"), args[0]
    cli = importlib.import_module(args[0][:-len(".py")])
    monkeypatch.setattr(sys, "argv", args)
    monkeypatch.chdir(ROOT)
    with pytest.raises(UserError) as err:
        cli.main()
    message = str(err.value)
    assert "\n" not in message and needle in message, message
    assert_nothing_complete(tmp_path)
