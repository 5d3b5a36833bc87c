"""experiments/paired.py (paired per-seed differences, Student-t interval) and its CLI scripts/compare_seeds.py on
hand-computed values and summary.csv files written here."""
import csv
import math

import pytest

from experiments.paired import against_leader, paired_difference
from tests.conftest import run_cli

T_975_DF2 = 4.302652729911275  # Student t, 97.5 % quantile, 2 degrees of freedom (tables)


def test_difference_interval_and_counts_by_hand():
    a, b = {0: 25.0, 1: 24.0, 2: 26.0, 7: 1.0}, {0: 24.5, 1: 24.2, 2: 25.1}  # seed 7: a only, left out
    d = paired_difference(a, b)
    diffs = [0.5, -0.2, 0.9]
    centre = sum(diffs) / 3
    sd = math.sqrt(sum((x - centre) ** 2 for x in diffs) / 2)
    assert d.n == 3 and abs(d.mean - centre) < 1e-12
    assert abs(d.low - (centre - T_975_DF2 * sd / math.sqrt(3))) < 1e-9
    assert abs(d.high - (centre + T_975_DF2 * sd / math.sqrt(3))) < 1e-9
    assert (d.wins, d.losses) == (2, 1) and not d.resolved  # the interval spans zero


def test_resolved_only_when_the_interval_excludes_zero():
    steady = paired_difference({s: 20.0 + 0.5 + 0.01 * s for s in range(4)}, {s: 20.0 for s in range(4)})
    assert steady.resolved and steady.low > 0 and steady.wins == 4
    behind = paired_difference({s: 20.0 for s in range(4)}, {s: 20.5 + 0.01 * s for s in range(4)})
    assert behind.resolved and behind.high < 0 and behind.losses == 4
    flipping = paired_difference({0: 21.0, 1: 19.0, 2: 21.0}, {0: 20.0, 1: 20.0, 2: 20.0})
    assert not flipping.resolved
    single = paired_difference({0: 21.0}, {0: 20.0})
    assert single.n == 1 and math.isnan(single.low) and not single.resolved
    with pytest.raises(ValueError, match="share no seed"):
        paired_difference({0: 1.0}, {1: 1.0})


def test_against_leader_compares_every_other_setting_with_the_best_mean():
    rows = [{"setup": "s1", "scene": "lego", "method": m, "PSNR_mean": sum(v) / len(v),
             **{f"seed_{i}": x for i, x in enumerate(v)}}
            for m, v in [("a", [24.0, 25.0, 26.0]), ("b", [24.5, 25.5, 26.5]), ("c", [20.0, 30.0, 27.0])]]
    out = {r["method"]: r for r in against_leader(rows)}
    assert set(out) == {"a", "b"} and out["a"]["leader"] == "c"  # c has the best mean (25.67)
    assert abs(out["b"]["diff"] - (4.5 - 4.5 - 0.5) / 3) < 1e-12 and (out["b"]["wins"], out["b"]["losses"]) == (1, 2)


def write_summary(path, rows):
    """A summary.csv holding only per_seed rows, as experiments/summary.py writes them."""
    seeds = sorted({k for r in rows for k in r if k.startswith("seed_")})
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["table", "setup", "method", "PSNR_mean", "scene"] + seeds, restval="")
        w.writeheader()
        for r in rows:
            w.writerow({"table": "per_seed", "setup": "setup1", **r})


def test_cli_table_merges_files_and_names_selectors_by_method(tmp_path):
    write_summary(tmp_path / "one.csv", [
        {"scene": "lego", "method": "coverage K=3", "PSNR_mean": 24.0, "seed_0": 24.0, "seed_1": 24.0},
        {"scene": "lego", "method": "lite_gs K=3 eps=0.1", "PSNR_mean": 25.0, "seed_0": 24.8, "seed_1": 25.2}])
    write_summary(tmp_path / "two.csv", [
        {"scene": "lego", "method": "cover_pool K=3", "PSNR_mean": 24.5, "seed_0": 24.5, "seed_1": 24.5}])
    r = run_cli("scripts/compare_seeds.py", str(tmp_path / "one.csv"), str(tmp_path / "two.csv"),
                "--pairs", "lite_gs:coverage", "cover_pool:lite_gs")
    assert r.returncode == 0, r.stderr
    assert "| setup1 | lego | lite_gs K=3 eps=0.1 | coverage K=3 | 2 | +1.00 |" in r.stdout
    # differences 0.8 and 1.2 (sd 0.28, sem 0.2); half width t(0.975, 1) = 12.706 x 0.2 = 2.54
    assert "| +1.00 | [-1.54, +3.54] | 2 / 0 | no |" in r.stdout
    assert "| setup1 | lego | cover_pool K=3 | lite_gs K=3 eps=0.1 | 2 | -0.50 |" in r.stdout


@pytest.mark.parametrize("files, pairs, message", [
    (["one.csv"], ["lite_gs"], "write two different selectors as A:B"),
    (["one.csv"], ["ssg:coverage"], "no scene has both selectors"),
    (["one.csv", "missing.csv"], ["lite_gs:coverage"], "not found"),
])
def test_cli_bad_input_is_one_error_line(tmp_path, files, pairs, message):
    write_summary(tmp_path / "one.csv", [
        {"scene": "lego", "method": "coverage K=3", "PSNR_mean": 24.0, "seed_0": 24.0},
        {"scene": "lego", "method": "lite_gs K=3 eps=0.1", "PSNR_mean": 25.0, "seed_0": 25.0}])
    r = run_cli("scripts/compare_seeds.py", *[str(tmp_path / f) for f in files], "--pairs", *pairs)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and message in r.stderr, r.stderr


def test_cli_rejects_ambiguous_names_and_conflicting_seeds(tmp_path):
    write_summary(tmp_path / "one.csv", [
        {"scene": "lego", "method": "cover_pool K=3", "PSNR_mean": 24.0, "seed_0": 24.0},
        {"scene": "lego", "method": "cover_pool K=3 pool_weight=pixels", "PSNR_mean": 24.2, "seed_0": 24.2},
        {"scene": "lego", "method": "coverage K=3", "PSNR_mean": 23.0, "seed_0": 23.0}])
    r = run_cli("scripts/compare_seeds.py", str(tmp_path / "one.csv"), "--pairs", "cover_pool:coverage")
    assert r.returncode == 2 and "ambiguous" in r.stderr and "pool_weight=pixels" in r.stderr
    r = run_cli("scripts/compare_seeds.py", str(tmp_path / "one.csv"), "--pairs",
                "cover_pool K=3 pool_weight=pixels:coverage")
    assert r.returncode == 0 and "| +1.20 |" in r.stdout, r.stderr
    write_summary(tmp_path / "two.csv", [{"scene": "lego", "method": "coverage K=3", "PSNR_mean": 22.0,
                                          "seed_0": 22.0}])
    r = run_cli("scripts/compare_seeds.py", str(tmp_path / "one.csv"), str(tmp_path / "two.csv"), "--pairs",
                "cover_pool K=3 pool_weight=pixels:coverage")
    assert r.returncode == 2 and "two values" in r.stderr
