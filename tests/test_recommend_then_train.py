"""scripts/recommend_then_train.py: the seed-view dataset holds no candidate image; end to end on the tiny scene
(recommend from poses alone, continue the seed model with --init_ply)."""
import json

import pytest

from experiments.recommend_train_loop import make_seed_dataset
from tests.conftest import ROOT, run_cli

SCRIPT = ROOT / "scripts" / "recommend_then_train.py"


def test_seed_dataset_links_seed_and_test_images_only(tiny_scene, tmp_path):
    seeds, candidates = make_seed_dataset(tiny_scene, tmp_path, 5)
    frames = json.loads((tiny_scene / "transforms_train.json").read_text())["frames"]
    assert len(seeds) == 5 and candidates and sorted(seeds + candidates) == list(range(len(frames)))
    folder = tmp_path / "data"
    kept = json.loads((folder / "transforms_train.json").read_text())["frames"]
    assert [f["file_path"] for f in kept] == [frames[v]["file_path"] for v in seeds]
    listed = json.loads((folder / "candidates.json").read_text())["frames"]
    assert [f["file_path"] for f in listed] == [frames[v]["file_path"] for v in candidates]
    assert all((folder / (frames[v]["file_path"] + ".png")).is_file() for v in seeds)
    assert not any((folder / (frames[v]["file_path"] + ".png")).exists() for v in candidates)
    test = json.loads((folder / "transforms_test.json").read_text())["frames"]
    assert test and all((folder / (f["file_path"] + ".png")).is_file() for f in test)


@pytest.mark.slow
def test_end_to_end_on_the_tiny_scene(tiny_scene, tmp_path):
    out = tmp_path / "rtt"
    r = run_cli(str(SCRIPT), "--data", str(tiny_scene), "-o", str(out), "--methods", "coverage", "none", "--seeds", "0",
                "--num_seed_views", "3", "-k", "2", "-r", "32", "--base_iterations", "30", "--iterations", "40",
                "--train_args=--num_random_points 300 --densify_from_iter 10", "--threads", "1", timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    results = json.loads((out / "results.json").read_text())
    seeds = results["settings"]["seed_views"]
    picks = results["coverage/seed0"]["picks"]
    assert len(picks) == 2 and not set(picks) & set(seeds)
    for key, views in (("coverage/seed0", seeds + picks), ("none/seed0", seeds)):
        status = json.loads((out / "continue" / key.replace("/", "_") / "run_status.json").read_text())
        assert status["status"] == "complete" and status["train_views"] == views
        assert results[key]["test_psnr"] == status["test_psnr"]
        cfg = json.loads((out / "continue" / key.replace("/", "_") / "cfg_args").read_text())
        assert cfg["model"]["init_ply"].endswith("point_cloud.ply")  # continued from the seed model
    assert "| coverage |" in (out / "summary.md").read_text()
