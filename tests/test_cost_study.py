"""benchmarks/cost_study.py --preset smoke on a tiny trained model: every configuration finishes, lazy_pop makes
pop_gs's picks with no more oracles, the counts are consistent, the exact selectors' rows after pick K equal a run
with that K (what lets them run once with the largest K), and --report rebuilds the same report from the JSON."""
import json
import math

import pytest

from benchmarks.cost_study import run_config
from tests.conftest import run_cli

pytestmark = pytest.mark.usefixtures("single_torch_thread")  # run_config sets one thread, as the children


@pytest.fixture(scope="module")
def study(tiny_model, tmp_path_factory):
    """(model directory, results JSON path, its rows) of the smoke preset."""
    tmp = tmp_path_factory.mktemp("cost_study")
    out = tmp / "study.json"
    r = run_cli("benchmarks/cost_study.py", "--preset", "smoke", "--model", str(tiny_model), "--threads", "1", "--json",
                str(out), timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return tiny_model, out, json.loads(out.read_text())["rows"]


def test_every_configuration_finishes_with_consistent_counts(study):
    _, _, rows = study
    assert {(r["setting"], r["cache"], r["K"]) for r in rows} == {
        (s, c, k) for s in ("pop_gs", "lazy_pop", "lite_gs eps=0.3") for c in ("unlimited", "quarter", "quarter_lru")
        for k in (1, 3)}
    for r in rows:
        assert r["status"] == "ok" and r["M"] == 8 and len(r["picks"]) == r["K"], r
        assert r["views_computed"] <= r["fisher_passes"] <= r["evaluated"] <= r["conservative"], r
        assert 0 < r["fisher_s"] <= r["wall_s"] and r["peak_rss_mb"] > 0 and r["rho"] > 0 and r["rho_ratio"] > 0
        if r["cache"] == "unlimited":
            assert r["recomputes"] == 0 and r["cache_mb"] is None
    quarter = {r["cache_mb"] for r in rows if r["cache"] != "unlimited"}
    assert len(quarter) == 1 and quarter.pop() > 0  # one budget: a quarter of the pool, for both evictions


def test_lazy_pop_makes_pop_gs_picks_with_no_more_oracles(study):
    _, _, rows = study
    by = {(r["setting"], r["cache"], r["K"]): r for r in rows}
    for cache in ("unlimited", "quarter", "quarter_lru"):
        for k in (1, 3):
            pop, lazy = by["pop_gs", cache, k], by["lazy_pop", cache, k]
            assert lazy["picks"] == pop["picks"] and lazy["identical"] and lazy["rho_ratio"] == pytest.approx(1.0)
            assert lazy["evaluated"] <= pop["evaluated"] == pop["conservative"] == sum(8 - j for j in range(k))
            assert lazy["conservative"] == pop["conservative"]


@pytest.mark.auto_backend  # the model's own settings, as the children run them
def test_exact_rows_after_pick_k_equal_a_run_with_that_k(study):
    model, _, rows = study
    firsts = [r for r in rows
              if r["selector"] in ("pop_gs", "lazy_pop") and r["K"] == 1 and r["cache"] != "quarter_lru"]
    for r in firsts:
        budget = None if r["cache_mb"] is None else round(r["cache_mb"] * 2**20)
        alone = run_config({"source": {"model": str(model)}, "candidates": "hemisphere", "M": 8, "k_run": 1,
                            "selector": r["selector"], "eps": None, "cache": r["cache"], "cache_bytes": budget,
                            "threads": 1, "seed": 0, "timeout_s": 120, "reserve_mb": 0})
        step = alone["trace"][0]
        # picks and counts exactly; rho to float32 rounding (a run in another process once differed by 6e-10)
        assert [step["view"]] == r["picks"] and math.isclose(step["rho"], r["rho"], rel_tol=1e-6)
        assert (step["evaluated"], step["fisher_passes"], step["views_computed"]) == (
            r["evaluated"], r["fisher_passes"], r["views_computed"])


def test_report_rebuilds_the_same_markdown_and_a_plot(study, tmp_path):
    _, out, _ = study
    r = run_cli("benchmarks/cost_study.py", "--report", str(out), "--out_dir", str(tmp_path))
    assert r.returncode == 0, r.stderr[-2000:]
    text = (tmp_path / "study.md").read_text()
    assert text == out.with_suffix(".md").read_text()
    assert "lazy_pop's picks equal pop_gs's in 6 of 6 configurations where both finished: **met**" in text
    assert "## Where lite_gs takes <= 0.5x the faster exact method" in text and "| lite_gs eps=0.3 |" in text
    assert (tmp_path / "study.png").stat().st_size > 10_000


def test_without_a_model_one_error_line():
    r = run_cli("benchmarks/cost_study.py", "--preset", "smoke")
    assert r.returncode == 2 and r.stderr.strip().splitlines() == [
        "error: give at least one model: --model DIR (a train.py model directory) or --garden WxH"]


def test_selectors_and_caches_narrow_the_preset_and_bad_values_get_one_line():
    from benchmarks.cost_study import PRESETS, narrowed, selector_setting
    from utils.errors import UserError
    full = PRESETS["full"]
    small = narrowed(full, ["lazy_pop", "lite_gs:0.3"], ["unlimited"])
    assert small.settings == (("lazy_pop", None), ("lite_gs", 0.3)) and small.caches == ("unlimited",)
    assert small.ms == full.ms and narrowed(full, None, None) == full
    assert narrowed(full, None, ["quarter_lru", "unlimited"]).caches == ("unlimited", "quarter_lru")  # run order
    for bad, message in (("greedy", "unknown selector 'greedy'"), ("pop_gs:0.1", "take no eps"),
                         ("lite_gs", "needs an eps"), ("lite_gs:x", "must be a number"), ("ssg:1.5", "in \\(0, 1\\)")):
        with pytest.raises(UserError, match=message):
            selector_setting(bad)
    with pytest.raises(UserError, match="include unlimited"):
        narrowed(full, None, ["quarter"])


def test_resume_runs_only_the_configurations_the_json_lacks(study, tmp_path):
    model, out, rows = study
    partial = tmp_path / "partial.json"
    doc = json.loads(out.read_text())
    dropped = ("lite_gs eps=0.3", "quarter")
    doc["rows"] = [r for r in rows if (r["setting"], r["cache"]) != dropped]
    partial.write_text(json.dumps(doc))
    r = run_cli("benchmarks/cost_study.py", "--preset", "smoke", "--model", str(model), "--threads", "1", "--json",
                str(partial), "--resume", timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    ran = [line for line in r.stdout.splitlines() if line.startswith("[") and "kept from" not in line]
    assert len(ran) == 2 and all("lite_gs eps=0.3" in line and " quarter:" in line for line in ran), ran
    resumed = json.loads(partial.read_text())["rows"]
    key = lambda row: (row["setting"], row["cache"], row["K"])  # noqa: E731
    assert sorted(map(key, resumed)) == sorted(map(key, rows))
    kept = {key(row): row for row in resumed if (row["setting"], row["cache"]) != dropped}
    assert all(kept[key(row)] == row for row in rows if (row["setting"], row["cache"]) != dropped)
    r = run_cli("benchmarks/cost_study.py", "--preset", "smoke", "--model", str(model), "--json", str(partial),
                "--resume", "--timeout_s", "5")
    assert r.returncode == 2 and r.stderr.strip().splitlines()[-1].startswith("error: --resume:")


def test_ratio_curves_follow_m_or_k():
    """The plot's lite_gs curves: over M (several pools) one per (setting, K), unlimited cache only; over K (one pool)
    one per (setting, cache), points sorted along the axis."""
    from benchmarks.cost_study import _ratio_lines

    def ratio(m, k, cache, value):
        return {"row": {"model": "a", "setting": "lite_gs eps=0.1", "M": m, "K": k, "cache": cache}, "ratio": value}
    sweep_k = [ratio(100, 20, "unlimited", 0.5), ratio(100, 3, "unlimited", 0.9), ratio(100, 20, "quarter", 0.3)]
    assert _ratio_lines(sweep_k, "a", over_m=False) == [
        ([(3, 0.9), (20, 0.5)], "-o", "lite_gs eps=0.1, unlimited"), ([(20, 0.3)], "--s", "lite_gs eps=0.1, quarter")]
    sweep_m = [ratio(300, 6, "unlimited", 0.7), ratio(100, 6, "unlimited", 0.8), ratio(100, 6, "quarter", 0.4),
               ratio(100, 3, "unlimited", 0.9)]
    assert _ratio_lines(sweep_m, "a", over_m=True) == [([(100, 0.8), (300, 0.7)], "-o", "lite_gs eps=0.1, K = 6"),
                                                        ([(100, 0.9)], "-o", "lite_gs eps=0.1, K = 3")]
    assert _ratio_lines(sweep_m, "b", over_m=True) == []
