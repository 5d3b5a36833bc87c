"""benchmarks/bench_selection.py with its default arguments (every oracle selector, each on the oracle its
`oracle_kind` declares) completes on a tiny trained model; --compare_dense agrees with the dense twin."""
import json

from tests.conftest import run_cli


def test_default_arguments_complete_on_a_tiny_model(tiny_model, tmp_path):
    out = tmp_path / "bench.json"
    r = run_cli("benchmarks/bench_selection.py", "--model", str(tiny_model), "--json", str(out), "--compare_dense",
                timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = json.loads(out.read_text())["rows"]
    assert {r["method"] for r in rows} >= {"pop_gs", "lite_gs", "ssg", "fisherrf"}
    first_k = {r["method"]: r for r in rows if r["K"] == 3}
    # cover scores geometry (no Fisher pass) and render_variance its own criterion: neither is the shared log-det
    assert first_k["cover"]["oracle"] == "own" and first_k["cover"]["views_computed"] == 0
    assert first_k["render_variance"]["oracle"] == "own" and first_k["render_variance"]["views_computed"] > 0
    assert first_k["cover"]["ids"] != first_k["pop_gs"]["ids"] or first_k["cover"]["gains"] != first_k["pop_gs"]["gains"]
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
