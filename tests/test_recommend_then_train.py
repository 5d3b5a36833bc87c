"""scripts/recommend_then_train.py: the seed-view dataset holds no candidate image; end to end on the tiny scene
(recommend from poses alone, continue the seed model with --init_ply)."""
import json

import pytest

from active.schedule import farthest_point_views
from experiments.seed_dataset import make_seed_dataset, training_centers
from scene.dataset_readers import load_scene_info
from scene.pose_files import read_pose_file
from tests.conftest import ROOT, run_cli
from tests.test_colmap_io import write_colmap_scene
from utils.errors import UserError

SCRIPT = ROOT / "scripts" / "recommend_then_train.py"


def test_seed_dataset_links_seed_and_test_images_only(tiny_scene, tmp_path):
    made = make_seed_dataset(tiny_scene, tmp_path, 5)
    seeds, candidates = made.seeds, made.candidates
    assert made.candidate_poses == tmp_path / "data" / "candidates.json"
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


def test_colmap_seed_dataset_keeps_seed_images_test_split_and_seed_points(tmp_path):
    """COLMAP: the seed folder links the seed and --eval test images only, keeps the SfM points a seed view
    observes, and lists the candidates' poses (without images) in a COLMAP model of their own."""
    data = tmp_path / "colmap"
    images = write_colmap_scene(data, 10, fmt="text")  # ids 10..19; sorted by name, indices 0 and 8 are test
    names = sorted(name for *_, name in images)
    id_of = {name: iid for iid, *_, name in images}
    ids = [id_of[n] for n in names]
    train = [n for i, n in enumerate(names) if i % 8]
    seeds = farthest_point_views(training_centers(data), 3)  # the seeds it will take (train.py's seeding)
    seed_id, candidate_ids = id_of[train[seeds[0]]], [id_of[n] for v, n in enumerate(train) if v not in seeds]
    (data / "sparse" / "0" / "points3D.txt").write_text(
        "1 0 0 0 255 0 0 0.5 " + " ".join(f"{i} 0" for i in ids) + "\n"  # seen by every view: kept
        f"2 1 1 1 0 255 0 0.5 {ids[0]} 0 {ids[8]} 0\n"  # seen by the test views only: dropped
        "3 2 2 2 0 0 255 0.5\n"  # seen by none: dropped
        f"4 3 3 3 9 9 9 0.5 {seed_id} 0 {candidate_ids[0]} 0\n"  # seen by one seed view: kept
        "5 4 4 4 9 9 9 0.5 " + " ".join(f"{i} 0" for i in candidate_ids) + "\n")  # candidates only: dropped
    made = make_seed_dataset(data, tmp_path / "out", 3)
    assert made.seeds == seeds
    assert len(made.seeds) == 3 and sorted(made.seeds + made.candidates) == list(range(len(train)))
    folder = made.folder
    linked = sorted(p.name for p in (folder / "images").iterdir())
    assert linked == sorted([train[v] for v in made.seeds] + [names[0], names[8]])
    assert "2 of 5 SfM points" in made.note
    info = load_scene_info(str(folder), eval=True, skip_missing_images=True)
    assert [c.image_name for c in info.train_cameras] == [train[v].rsplit(".", 1)[0] for v in sorted(made.seeds)]
    assert len(info.test_cameras) == 2 and info.point_cloud.points.tolist() == [[0, 0, 0], [3, 3, 3]]
    listed = [c.image_name for c in read_pose_file(made.candidate_poses)]
    assert listed == [train[v].rsplit(".", 1)[0] for v in made.candidates]
    assert made.seed_flags == ["-i", "images", "--skip_missing_images"] and made.full_flags == ["-i", "images"]
    every = make_seed_dataset(data, tmp_path / "all", 3, seed_points="all")  # the diagnosis: every point kept
    assert "5 of 5 SfM points" in every.note and every.seeds == made.seeds
    with pytest.raises(UserError, match="--seed_points must be one of observed, all"):
        make_seed_dataset(data, tmp_path / "bad", 3, seed_points="some")


def test_seed_dataset_starts_farthest_point_seeding_from_the_given_view(tiny_scene, tmp_path):
    made = make_seed_dataset(tiny_scene, tmp_path / "from5", 4, start=5)
    assert made.seeds[0] == 5 and made.seeds == farthest_point_views(training_centers(tiny_scene), 4, 5)
    assert made.seeds != make_seed_dataset(tiny_scene, tmp_path / "from0", 4).seeds
    with pytest.raises(UserError, match=r"first seed view must be a training view id in \[0, 13\], got 14"):
        make_seed_dataset(tiny_scene, tmp_path / "bad", 4, start=14)
    with pytest.raises(UserError, match=r"--num_seed_views must lie in \[1, 14\]"):
        make_seed_dataset(tiny_scene, tmp_path / "bad", 15)


def test_seed_dataset_refuses_other_layouts(tmp_path):
    with pytest.raises(UserError, match="neither a Blender dataset .* nor a COLMAP one"):
        make_seed_dataset(tmp_path, tmp_path / "out", 3)


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


@pytest.mark.slow
def test_seed_start_random_gives_each_seed_its_own_seed_views_and_base_model(tiny_scene, tmp_path):
    """--seed_start random: seed s seeds farthest-point from the view random.Random(s) draws (train.py's draw), trains
    its own base model in OUT/seedS, and continues from it; the summary lists every seed's seed views."""
    out = tmp_path / "rtt"
    flags = ["--data", str(tiny_scene), "-o", str(out), "--methods", "coverage", "--num_seed_views", "3", "-k", "2",
             "-r", "32", "--base_iterations", "20", "--iterations", "20", "--seed_start", "random",
             "--train_args=--num_random_points 300 --densify_from_iter 10", "--threads", "1"]
    r = run_cli(str(SCRIPT), *flags, "--seeds", "0", "1", timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    results = json.loads((out / "results.json").read_text())
    drawn = results["settings"]["seed_views"]
    centers = training_centers(tiny_scene)
    for seed, start in ((0, 13), (1, 2)):  # random.Random(0).randrange(14) = 13, random.Random(1)... = 2
        assert drawn[str(seed)] == farthest_point_views(centers, 3, start)
        picks = results[f"coverage/seed{seed}"]["picks"]
        status = json.loads((out / "continue" / f"coverage_seed{seed}" / "run_status.json").read_text())
        assert status["train_views"] == drawn[str(seed)] + picks
        cfg = json.loads((out / "continue" / f"coverage_seed{seed}" / "cfg_args").read_text())
        assert cfg["model"]["init_ply"].startswith(str(out / f"seed{seed}" / "base"))
    assert drawn["0"] != drawn["1"] and not (out / "base").exists()
    r = run_cli(str(SCRIPT), *flags, "--seeds", "2", timeout=600)  # a later call adds a seed, keeping the others
    assert r.returncode == 0, r.stdout + r.stderr
    settings = json.loads((out / "results.json").read_text())["settings"]
    assert sorted(settings["seed_views"]) == sorted(settings["base_test_psnr"]) == ["0", "1", "2"]
    assert "Seed views drawn per seed" in (out / "summary.md").read_text()


def test_an_output_folder_keeps_one_seed_start(tiny_scene, tmp_path):
    """Results of the shared seed views are never reused as a drawn seed's (or the other way), before any training."""
    out = tmp_path / "rtt"
    out.mkdir()
    (out / "results.json").write_text(json.dumps({"settings": {}, "coverage/seed0": {"picks": [1, 2]}}))
    r = run_cli(str(SCRIPT), "--data", str(tiny_scene), "-o", str(out), "--seed_start", "random")
    assert r.returncode == 2 and r.stderr.strip().splitlines() == [
        f"error: {out / 'results.json'} holds runs with --seed_start first; use a new -o for --seed_start random"]
    assert sorted(p.name for p in out.iterdir()) == ["results.json"]


@pytest.mark.parametrize("flag, value, recorded", [("-k", "6", "--k 4"), ("--iterations", "900", "--iterations 1200"),
                                                   ("--train_args=--num_random_points 10000", None,
                                                    "--train_args --num_random_points 3000")])
def test_an_output_folder_keeps_one_protocol(tiny_scene, tmp_path, flag, value, recorded):
    """A later call into the same folder with another value of a flag that decides the results is one error line
    before any training, so a table never mixes two protocols; methods and seeds may differ."""
    out = tmp_path / "rtt"
    out.mkdir()
    settings = {"data": str(tiny_scene), "images": "images", "seed_points": "observed", "num_seed_views": 5,
                "seed_start": "first", "k": 4, "resolution": "8", "base_iterations": 1000, "iterations": 1200,
                "select_iteration": None, "methods": ["random"], "seeds": [5], "threads": 2,
                "train_args": "--num_random_points 3000 --densify_from_iter 100 --densification_interval 50 "
                              "--max_gaussians 20000"}
    (out / "results.json").write_text(json.dumps({"settings": settings, "random/seed5": {"picks": [1, 2, 3, 4]}}))
    r = run_cli(str(SCRIPT), "--data", str(tiny_scene), "-o", str(out), "--methods", "coverage", "--seeds", "0",
                flag, *([value] if value else []))
    assert r.returncode == 2 and r.stderr.strip().splitlines()[-1].startswith(
        f"error: {out / 'results.json'} holds runs with {recorded}"), r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["results.json"]


@pytest.mark.slow
def test_select_iteration_recommends_on_the_earlier_model_and_continues_from_the_last(tiny_scene, tmp_path):
    out = tmp_path / "rtt"
    flags = ["--data", str(tiny_scene), "-o", str(out), "--methods", "cover", "--seeds", "0", "--num_seed_views", "3",
             "-k", "2", "-r", "32", "--base_iterations", "30", "--iterations", "20",
             "--train_args=--num_random_points 300 --densify_from_iter 10", "--threads", "1"]
    r = run_cli(str(SCRIPT), *flags, "--select_iteration", "10", timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    rec = json.loads((out / "recommend" / "cover_seed0" / "recommendations.json").read_text())
    assert rec["iteration"] == 10
    cfg = json.loads((out / "continue" / "cover_seed0" / "cfg_args").read_text())
    assert cfg["model"]["init_ply"].endswith("iteration_30/point_cloud.ply")
    r = run_cli(str(SCRIPT), *flags, "--select_iteration", "31")
    assert r.returncode == 2 and r.stderr.strip().splitlines() == [
        "error: --select_iteration must lie in [1, --base_iterations = 30], got 31"]


def _results(values: dict[str, list[float]]) -> dict:
    return {"settings": {}, **{f"{m}/seed{s}": {"test_psnr": v} for m, vs in values.items() for s, v in enumerate(vs)}}


def test_compare_table_differences_worst_cases_and_last_places(tmp_path):
    lego = _results({"coverage": [18.0, 18.2], "random": [17.0, 19.0], "pop_gs": [17.5, 17.9], "none": [15.0, 15.0]})
    mic = _results({"coverage": [22.0, 22.0], "random": [22.5, 22.1], "pop_gs": [22.6, 22.4]})
    for scene, data in (("lego", lego), ("mic", mic)):
        (tmp_path / f"{scene}.json").write_text(json.dumps(data))
    r = run_cli(str(ROOT / "scripts" / "compare_recommend_then_train.py"), f"lego={tmp_path / 'lego.json'}",
                f"mic={tmp_path / 'mic.json'}")
    assert r.returncode == 0, r.stderr
    rows = {line.split(" | ")[0].strip("| "): line for line in r.stdout.splitlines()[2:]}
    assert set(rows) == {"coverage", "random", "pop_gs"}  # "none" is not compared
    # pop_gs: lego 17.70 - 18.00 (random) / - 18.10 (coverage); mic 22.50 - 22.30 / - 22.00; last in lego seed 1
    assert rows["pop_gs"] == "| pop_gs | -0.30 / -0.40 | +0.20 / +0.50 | -0.30 | -0.40 | 1 of 4 |"
    assert rows["coverage"] == "| coverage | +0.10 / +0.00 | -0.30 / +0.00 | -0.30 | +0.00 | 2 of 4 |"  # mic: both
    assert rows["random"].endswith("| +0.00 | -0.10 | 1 of 4 |")  # last in lego seed 0
    bad = run_cli(str(ROOT / "scripts" / "compare_recommend_then_train.py"), "lego")
    assert bad.returncode == 2 and bad.stderr.strip().splitlines()[-1].startswith("error: each argument is SCENE=PATH")
