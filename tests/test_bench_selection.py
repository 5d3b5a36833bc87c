"""benchmarks/bench_selection.py with its default arguments (every oracle selector: the log-det and the diagonal
kind each get their own oracle) completes on a tiny trained model; --compare_dense agrees with the dense twin."""
import json

from tests.conftest import run_cli


def test_default_arguments_complete_on_a_tiny_model(tiny_scene, tmp_path):
    model = tmp_path / "model"
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(model), "--iterations", "30", "--num_random_points",
                "300", "--quiet", "--sh_degree", "1")
    assert r.returncode == 0, r.stderr
    out = tmp_path / "bench.json"
    r = run_cli("benchmarks/bench_selection.py", "--model", str(model), "--json", str(out), "--compare_dense",
                timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = json.loads(out.read_text())["rows"]
    assert {r["method"] for r in rows} >= {"pop_gs", "lite_gs", "ssg", "fisherrf"}
    for dense in (r for r in rows if r["oracle"] == "dense"):
        sparse = next(s for s in rows if s["oracle"] == "sparse" and (s["K"], s["method"], s["options"]) ==
                      (dense["K"], dense["method"], dense["options"]))
        assert sparse["ids"] == dense["ids"] and sparse["evaluated"] == dense["evaluated"]


def test_selection_cost_synthetic_old_and_new_agree(tmp_path):
    out = tmp_path / "cost.json"
    r = run_cli("benchmarks/selection_cost.py", "--synthetic", "300", "--visible", "0.3", "--threads", "1",
                "--repeats", "1", "--json", str(out))
    assert r.returncode == 0, r.stderr[-2000:]
    row = json.loads(out.read_text())["synthetic"][0]
    assert row["visible"] == 90 and row["gain_rel_diff"] < 1e-10 and row["f32_rel_diff"] < 1e-6
