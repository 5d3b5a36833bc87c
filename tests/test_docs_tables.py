"""The README's results table is the one scripts/results_table.py generates from the committed summary.csv files."""
import os

import pytest

from scripts import results_table

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _readme():
    with open(os.path.join(ROOT, "README.md")) as f:
        return f.read()


def test_readme_table_matches_committed_summaries():
    assert results_table.readme_table(_readme()) == results_table.generated_table(), (
        "README.md's results table is stale: run `python scripts/results_table.py --write`")


def test_table_changes_when_a_summary_changes(tmp_path):
    """The comparison can fail: a changed PSNR in one summary.csv changes the generated table."""
    src = os.path.join(ROOT, "docs", "results")
    for name, _ in results_table.SOURCES:
        os.makedirs(tmp_path / name)
        with open(os.path.join(src, name, "summary.csv")) as f:
            text = f.read()
        if name == "setup2_nerf400_3seeds":
            lines = text.split("\n")
            i = next(i for i, l in enumerate(lines) if l.startswith("per_seed,setup2,random"))
            fields = lines[i].split(",")
            fields[6] = "12.5"
            lines[i] = ",".join(fields)
            text = "\n".join(lines)
        (tmp_path / name / "summary.csv").write_text(text)
    changed = results_table.generated_table(str(tmp_path))
    assert changed != results_table.generated_table()
    assert "12.50 ± 0.56" in changed
    with pytest.raises(AssertionError):
        assert results_table.readme_table(_readme()) == changed


def test_best_mean_of_each_row_is_bold():
    for line in results_table.generated_table().split("\n")[2:]:
        cells = [c.strip() for c in line.strip("|").split("|")[2:]]
        means = [float(c.strip("*").split()[0]) for c in cells if c != "–"]
        bold = [float(c.strip("*").split()[0]) for c in cells if c.startswith("**")]
        assert bold == [max(means)]
