"""The README's results table is the one scripts/results_table.py generates from the committed summary.csv files, and
every result section of docs/results.md starts with the provenance line it generates from the committed data."""
import os
import re
import shutil

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


# docs/results.md sections that hold no result of their own (an introduction to the sections after it)
NO_RESULT_SECTIONS = {"Experiments at reduced scale (CPU)"}


def _results_md():
    with open(results_table.RESULTS_MD) as f:
        return f.read()


def _sections(text):
    """{### heading: the lines after it, up to the next heading}."""
    sections, current = {}, None
    for line in text.split("\n"):
        if line.startswith("#"):
            current = line[4:] if line.startswith("### ") else None
            if current is not None:
                sections[current] = []
        elif current is not None:
            sections[current].append(line)
    return sections


def test_every_result_section_starts_with_one_provenance_line():
    for heading, lines in _sections(_results_md()).items():
        provenance = [l for l in lines if results_table.is_provenance_line(l)]
        if heading in NO_RESULT_SECTIONS:
            assert not provenance, heading
            continue
        first = next(l for l in lines if l.strip())
        assert results_table.is_provenance_line(first), f"section '{heading}' does not start with its provenance line"
        assert len(provenance) == 1, f"section '{heading}' has {len(provenance)} provenance lines"
        names, command = results_table.parse_provenance_line(first)
        if re.match(r"commands? below", command):  # an indented code block follows in the section
            rest = lines[lines.index(first) + 1:]
            assert any(l.startswith("    ") and l.strip() for l in rest), f"section '{heading}': no command below"
        for name in names:
            assert os.path.isdir(os.path.join(results_table.RESULTS_DIR, name)), name


def test_provenance_lines_match_committed_data():
    stale, unknown = [], []
    for line in _results_md().split("\n"):
        if not results_table.is_provenance_line(line):
            continue
        names, command = results_table.parse_provenance_line(line)
        if not names:  # a section whose figures are not in docs/results (written by hand)
            continue
        try:
            expected = results_table.provenance_line(names, command)
        except results_table.NoHistory:  # data without a recorded commit, in a checkout without its history
            unknown.append(line)
            continue
        if line != expected:
            stale.append(f"{line}\n  expected: {expected}")
    assert not stale, ("docs/results.md's provenance lines are stale: run `python scripts/results_table.py --write`\n"
                       + "\n".join(stale))
    if unknown:
        pytest.skip(f"{len(unknown)} provenance line(s) need git history to check")


def test_recorded_provenance_is_read_from_the_summary():
    line = results_table.provenance_line(["setup2_nerf400_3seeds"])
    assert line == ("<sub>Data: [setup2_nerf400_3seeds](results/setup2_nerf400_3seeds/summary.md) · code 907f2bc "
                    "(26 runs), 94e007f (2), ad8f878 (8) · 2 × Intel(R) Xeon(R) Processor, cpu, torch 2.14.1, "
                    "1 thread per process · trained 2026-12-03 · command below</sub>")


def test_provenance_line_changes_when_its_data_changes(tmp_path):
    """The check can fail: another code commit in a summary's Provenance section changes the generated line, and
    regenerating docs/results.md against the changed data changes that section's line."""
    name = "fisherrf20_360_bonsai_3seeds"
    shutil.copytree(os.path.join(results_table.RESULTS_DIR, name), tmp_path / name)
    summary = tmp_path / name / "summary.md"
    text = summary.read_text()
    assert "- code: 908a1eb (15 runs)" in text
    summary.write_text(text.replace("- code: 908a1eb (15 runs)", "- code: 908a1eb (13 runs); 0abcdef (2 runs)")
                       .replace("and 2026-12-03 14:19:46", "and 2026-12-04 01:02:03"))
    changed = results_table.provenance_line([name], results_dir=str(tmp_path))
    assert " · code 908a1eb (13 runs), 0abcdef (2) · " in changed
    assert " · trained 2026-12-03 to 2026-12-04 · " in changed
    assert changed != results_table.provenance_line([name])
    md = _results_md()
    line = next(l for l in md.split("\n") if results_table.is_provenance_line(l) and f"results/{name}/" in l)
    names, command = results_table.parse_provenance_line(line)
    assert results_table.provenance_line(names, command, str(tmp_path)) != line


def test_unrecorded_provenance_falls_back_to_the_data_commit(tmp_path):
    """A summary without a Provenance section: code not recorded, the last commit of the folder and its date."""
    try:
        commit, date = results_table.data_commit(os.path.join(results_table.RESULTS_DIR, "setup1_lego"))
    except results_table.NoHistory:
        pytest.skip("no git history")
    assert re.fullmatch(r"[0-9a-f]{7}", commit) and re.fullmatch(r"\d{4}-\d{2}-\d{2}", date)
    line = results_table.provenance_line(["setup1_lego"])
    assert f"code not recorded (data committed in {commit}) · 2-core VM (24 GiB, no GPU) · committed {date}" in line
    with pytest.raises(results_table.NoHistory):  # a folder outside any git checkout
        shutil.copytree(os.path.join(results_table.RESULTS_DIR, "setup1_lego"), tmp_path / "setup1_lego")
        results_table.data_commit(str(tmp_path / "setup1_lego"))


def test_recommend_tables_match_committed_results():
    from scripts import recommend_tables
    with open(recommend_tables.DOC) as f:
        doc = f.read()
    blocks = recommend_tables.generated_blocks()
    assert set(blocks) <= set(re.findall(r"<!-- generated: (\S+) -->", doc))
    assert recommend_tables.splice(doc, blocks) == doc, (
        "docs/recommend.md's recommend-then-train tables are stale: run `python scripts/recommend_tables.py --write`")


def test_recommend_tables_change_when_a_result_changes(tmp_path):
    """The comparison can fail: one changed test PSNR in a copy of the results changes its table and the comparison."""
    import json
    from scripts import recommend_tables
    src = os.path.join(ROOT, "docs", "results")
    for folder in recommend_tables.FOLDERS:
        shutil.copytree(os.path.join(src, folder), tmp_path / folder)
    path = tmp_path / "rtt_bonsai" / "results.json"
    results = json.loads(path.read_text())
    results["coverage/seed0"]["test_psnr"] = 12.5
    path.write_text(json.dumps(results))
    changed, committed = recommend_tables.generated_blocks(tmp_path), recommend_tables.generated_blocks()
    assert changed["rtt_bonsai"] != committed["rtt_bonsai"] and "| coverage | 12.50 |" in changed["rtt_bonsai"]
    assert changed["rtt_compare"] != committed["rtt_compare"]
    assert changed["rtt_lego_official"] == committed["rtt_lego_official"]
    assert changed["rtt_compare_heldout"] == committed["rtt_compare_heldout"]
    assert changed["rtt_clutter4"] == committed["rtt_clutter4"]
    assert changed["rtt_compare_rstart"] == committed["rtt_compare_rstart"]


def test_recommend_tables_refuse_an_unfinished_run(tmp_path):
    """A results.json caught mid-run (a method's row without its test PSNR, or absent for a seed) is one error naming
    the folder and the runs, not a table with a hole."""
    import json
    from scripts import recommend_tables
    from utils.errors import UserError
    folder = tmp_path / "rtt_bonsai"
    shutil.copytree(os.path.join(ROOT, "docs", "results", "rtt_bonsai"), folder)
    results = json.loads((folder / "results.json").read_text())
    del results["coverage/seed1"]["test_psnr"]
    del results["random/seed2"]
    (folder / "results.json").write_text(json.dumps(results))
    with pytest.raises(UserError, match=r"rtt_bonsai/results.json has no finished run for coverage/seed1, "
                                        r"random/seed2"):
        recommend_tables.scene_results(tmp_path, "rtt_bonsai")


def test_modes_table_rows_and_ratio_to_pop_gs(tmp_path):
    """The cached-vs-streaming table: one row per recommendations.json, ordered by mode then selector, each total
    over pop_gs's in the same mode."""
    import json
    from scripts import recommend_tables

    def write(name, mode, selector, total, options=None):
        rec = {"settings": {"fisher": {"fisher_mode": mode}}, "selector": selector, "selector_options": options or {},
               "oracle_calls": {"evaluated": 10, "conservative": 12}, "fisher_views_computed": 7,
               "seconds": {"fisher": 1.0, "gain": 0.5, "total": total}, "picks": [{"candidate": 3}, {"candidate": 9}]}
        (tmp_path / name).write_text(json.dumps(rec))
    write("a.json", "streaming", "pop_gs", 40.0)
    write("b.json", "streaming", "lite_gs", 10.0, {"eps": 0.1, "gain_weight": "none"})
    write("c.json", "cached", "pop_gs", 20.0)
    write("d.json", "cached", "lazy_pop", 15.0)
    rows = recommend_tables.modes_table(tmp_path).splitlines()[2:]
    assert [r.split(" | ")[:2] for r in rows] == [["| cached", "lazy_pop"], ["| cached", "pop_gs"],
                                                  ["| streaming", "lite_gs eps = 0.1"], ["| streaming", "pop_gs"]]
    assert "| **15.0** | 0.75× | 3, 9 |" in rows[0] and "| **10.0** | 0.25× |" in rows[2]
    assert rows[1].endswith("| **20.0** |  | 3, 9 |")
