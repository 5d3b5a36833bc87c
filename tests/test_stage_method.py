"""train.py --stage_method STAGE:NAME (another selector makes one acquisition's picks) and --keep_checkpoints 0
(every acquisition's checkpoint kept), on real runs of the tiny scene."""
import json

from tests.conftest import run_cli

COMMON = ["--num_init_views", "2", "--views_per_step", "2", "--max_views", "8", "--iters_per_view", "2",
          "--iterations", "5", "--num_random_points", "200", "--quiet", "--sh_degree", "1"]


def selection(model) -> dict:
    return json.loads((model / "selection.json").read_text())


def test_one_stage_picked_by_another_selector(tiny_scene, tmp_path):
    """Stage 1 by lite_gs in a coverage run: stage 0 is coverage's run's, stage 1 lite_gs's (a Fisher oracle ran),
    stage 2 coverage's again, and only stage 1 records the override."""
    runs = {name: tmp_path / name for name in ("coverage", "mixed")}
    for name, extra in (("coverage", []), ("mixed", ["--stage_method", "1:lite_gs"])):
        r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(runs[name]), "--method", "coverage", *COMMON, *extra)
        assert r.returncode == 0, r.stderr
    plain, mixed = selection(runs["coverage"])["stages"], selection(runs["mixed"])["stages"]
    assert len(mixed) == 3 and mixed[0]["selected"] == plain[0]["selected"]
    assert [s.get("stage_method") for s in mixed] == [None, "lite_gs", None]
    assert mixed[1]["oracle_calls"]["evaluated"] > 0 and plain[1]["oracle_calls"]["evaluated"] == 0
    assert mixed[1]["selected"] != plain[1]["selected"]  # else the test could not tell the selectors apart
    assert "selecting 2 of 10 candidates with lite_gs (--stage_method" in r.stdout + r.stderr


def test_keep_every_checkpoint(tiny_scene, tmp_path):
    model = tmp_path / "m"
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(model), "--method", "coverage", *COMMON,
                "--keep_checkpoints", "0")
    assert r.returncode == 0, r.stderr
    kept = sorted(p.name for p in (model / "checkpoints").iterdir())
    assert kept == [f"chkpnt_{s['iteration']:07d}.pt" for s in selection(model)["stages"]]  # one per acquisition
