"""train.py --exclude_views: excluded views are never seeded nor picked, on a real run of each kind of selector
(a deterministic geometric one and a Fisher one); the seed set without exclusions is the one it always was."""
import json

import pytest

from tests.conftest import run_cli


@pytest.mark.parametrize("method", ["coverage", "lite_gs"])
def test_excluded_views_are_never_seeded_nor_picked(tiny_scene, tmp_path, method):
    common = ["-s", str(tiny_scene), "--method", method, "--num_init_views", "2", "--views_per_step", "3",
              "--max_views", "8", "--iters_per_view", "2", "--iterations", "5", "--num_random_points", "200",
              "--quiet", "--sh_degree", "1"]
    plain, excluding = tmp_path / "plain", tmp_path / "excluding"
    assert run_cli("train.py", *common, "-m", str(plain)).returncode == 0
    plain_views = json.loads((plain / "selection.json").read_text())["final"]["train_views"]
    excluded = plain_views[1:4]  # a seed view and picks the plain run made: the run must go round them
    r = run_cli("train.py", *common, "-m", str(excluding), "--exclude_views", *map(str, excluded))
    assert r.returncode == 0, r.stderr
    record = json.loads((excluding / "selection.json").read_text())
    views = record["final"]["train_views"]
    assert len(views) == 8 and not set(views) & set(excluded)
    assert all(s["candidates"] == 14 - 3 - len(s["train_views"]) for s in record["stages"])  # 14 views, 3 excluded
    assert record["config"]["exclude_views"] == excluded
    assert "[stage 0] selecting 3 of 9 candidates" in r.stdout + r.stderr  # 14 views, 3 excluded, 2 seeds
    assert plain_views[0] == views[0] == 0  # farthest-point seeding still starts from the first allowed view
