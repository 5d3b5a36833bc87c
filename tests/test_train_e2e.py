"""End to end: train -> render -> metrics on a tiny built-in scene, and an active run's selection.json."""
import json

from tests.conftest import run_cli

ACTIVE = ["--eval", "--num_init_views", "2", "--views_per_step", "3", "--max_views", "8", "--iters_per_view", "4",
          "--iterations", "70", "--num_random_points", "600", "--quiet", "--sh_degree", "1"]


def test_train_render_metrics(tiny_scene, tmp_path):
    model = tmp_path / "model"
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(model), "--eval", "--iterations", "40",
                "--num_random_points", "500", "--quiet")
    assert r.returncode == 0, r.stderr
    for rel in ("cfg_args", "cameras.json", "input.ply", "point_cloud/iteration_40/point_cloud.ply"):
        assert (model / rel).is_file(), rel
    assert json.loads((model / "run_status.json").read_text())["status"] == "complete"
    cameras = json.loads((model / "cameras.json").read_text())
    assert [c["id"] for c in cameras] == list(range(4 + 14))  # 3DGS order: the 4 test cameras, then 14 training
    assert [c["img_name"] for c in cameras[:5]] == ["r_0", "r_1", "r_2", "r_3", "r_0"]
    cfg = json.loads((model / "cfg_args").read_text())
    assert cfg["dataset"] == {"kind": "blender", "num_train": 14, "num_test": 4, "dropped_images": []}
    assert cfg["model"]["skip_missing_images"] is False
    r = run_cli("render.py", "-m", str(model), "--quiet")
    assert r.returncode == 0, r.stderr
    assert len(list((model / "test" / "ours_40" / "renders").glob("*.png"))) == 4
    assert len(list((model / "train" / "ours_40" / "gt").glob("*.png"))) == 14
    r = run_cli("metrics.py", "-m", str(tmp_path), "--quiet")
    assert r.returncode == 0, r.stderr
    results = json.loads((model / "results.json").read_text())["ours_40"]
    assert 5 < results["PSNR"] < 60 and 0 < results["SSIM"] <= 1
    per_view = json.loads((model / "per_view.json").read_text())["ours_40"]
    assert sorted(per_view["PSNR"]) == [f"{i:05d}.png" for i in range(4)]
    assert "ours_40" in r.stdout and "PSNR" in r.stdout


def test_active_run_is_deterministic_and_counts_exactly(tiny_scene, tmp_path):
    runs = []
    for name in ("a", "b"):
        r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(tmp_path / name), "--method", "pop_gs", *ACTIVE)
        assert r.returncode == 0, r.stderr
        runs.append(json.loads((tmp_path / name / "selection.json").read_text()))
    a, b = runs
    assert [s["selected"] for s in a["stages"]] == [s["selected"] for s in b["stages"]]
    assert a["final"]["test_psnr"] == b["final"]["test_psnr"]
    assert [s["train_psnr"] for s in a["stages"]] == [s["train_psnr"] for s in b["stages"]]  # the fit when choosing
    assert all(5 < s["train_psnr"] < 60 for s in a["stages"])
    assert [len(s["train_views"]) for s in a["stages"]] == [2, 5]
    assert a["final"]["train_views"][:2] == a["stages"][0]["train_views"]
    for stage in a["stages"]:
        m, k = stage["candidates"], len(stage["selected"])
        assert stage["oracle_calls"]["conservative"] == stage["oracle_calls"]["evaluated"] == sum(m - j for j in range(k))
        assert all(g > 0 for g in stage["gains"])
        assert not set(stage["selected"]) & set(stage["train_views"])
    # The second step adds the remainder (8 - 5 = 3 views); rerunning a finished run leaves it untouched.
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(tmp_path / "a"), "--method", "pop_gs", *ACTIVE)
    assert r.returncode == 0 and "already finished" in r.stdout


def test_iterations_shorter_than_the_schedule_are_raised_with_one_note(tiny_scene, tmp_path):
    args = [a if a != "70" else "10" for a in ACTIVE]  # stages of 2 x 4 + 5 x 4 = 28 iterations > 10
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(tmp_path / "m"), "--method", "random", *args)
    assert r.returncode == 0, r.stderr
    notes = [line for line in r.stdout.splitlines() if "shorter than the acquisition schedule" in line]
    assert len(notes) == 1 and "stages of 8 + 20 = 28 iterations" in notes[0] and "training 28" in notes[0]
    cfg = json.loads((tmp_path / "m" / "cfg_args").read_text())
    assert cfg["run"]["iterations"] == 10 and cfg["total_iterations"] == 28
    assert json.loads((tmp_path / "m" / "run_status.json").read_text())["iteration"] == 28
