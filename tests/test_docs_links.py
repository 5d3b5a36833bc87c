"""The README and the docs pages: every relative link resolves (file, folder or heading anchor) and the README stays
short (at most 250 lines), so that a newcomer can read it and every page it points to exists."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.conftest import ROOT

README_MAX_LINES = 250
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")  # [text](target) and ![alt](target)
CODE_SPAN = re.compile(r"`+[^`]*`+")


def doc_files(root: Path) -> list[Path]:
    """README.md and every docs/*.md below `root`."""
    return [root / "README.md"] + sorted((root / "docs").glob("*.md"))


def outside_code(text: str) -> list[tuple[int, str]]:
    """(line number, line) for the lines outside fenced and 4-space-indented code blocks."""
    out, fenced = [], False
    for number, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
        elif not (fenced or line.startswith("    ") or line.startswith("\t")):
            out.append((number, line))
    return out


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: link and code markup dropped, lower case, punctuation removed, spaces -> '-'."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).replace("`", "").strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """The heading anchors of a markdown file (a repeated heading gets -1, -2, ... as on GitHub)."""
    seen: dict[str, int] = {}
    result = set()
    for _, line in outside_code(path.read_text()):
        match = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if match:
            base = slug(match.group(1))
            count = seen.get(base, 0)
            seen[base] = count + 1
            result.add(base if count == 0 else f"{base}-{count}")
    return result


def broken_links(path: Path) -> list[str]:
    """'file:line: target (why)' for each relative link of `path` whose file, folder or anchor does not exist."""
    problems = []
    for number, line in outside_code(path.read_text()):
        for target in LINK.findall(CODE_SPAN.sub("code", line)):
            if re.match(r"[a-z][a-z0-9+.-]*:", target, re.I):  # http:, https:, mailto:
                continue
            file_part, _, anchor = target.partition("#")
            dest = (path.parent / file_part).resolve() if file_part else path
            where = f"{path.name}:{number}: {target}"
            if not dest.exists():
                problems.append(f"{where} (no such file or folder)")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                problems.append(f"{where} (no heading with anchor #{anchor} in {dest.name})")
    return problems


def test_slug_follows_github():
    assert slug("Setup 1 on lego at 200 px with the paper's iteration count (one seed)") == \
        "setup-1-on-lego-at-200-px-with-the-papers-iteration-count-one-seed"
    assert slug("The main job (`scripts/quickstart.sh`)") == "the-main-job-scriptsquickstartsh"
    assert slug("Measurement log (2-core CPU, 24 GiB; 2026-11-24)") == "measurement-log-2-core-cpu-24-gib-2026-11-24"
    assert slug("A [linked](x.md) heading") == "a-linked-heading"


def test_checker_finds_broken_files_and_anchors(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "page.md").write_text("# Page\n\n## Real part\n\n## Real part\n")
    (tmp_path / "README.md").write_text(
        "# Title\n\n[ok](docs/page.md) [ok](docs/page.md#real-part) [ok](docs/page.md#real-part-1) [ok](docs/)\n"
        "[ok](#title) [web](https://example.org/x) `[in code](missing.md)`\n\n    [indented code](missing.md)\n\n"
        "```\n[fenced](missing.md)\n```\n"
        "[bad file](docs/nope.md) ![bad image](img/x.png) [bad anchor](docs/page.md#unreal) [bad local](#nothing)\n")
    found = [p for f in doc_files(tmp_path) for p in broken_links(f)]
    assert [p.split(": ", 1)[1] for p in found] == [
        "docs/nope.md (no such file or folder)", "img/x.png (no such file or folder)",
        "docs/page.md#unreal (no heading with anchor #unreal in page.md)",
        "#nothing (no heading with anchor #nothing in README.md)"]


@pytest.mark.parametrize("path", doc_files(ROOT), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(path):
    assert broken_links(path) == []


def test_readme_is_short():
    lines = len((ROOT / "README.md").read_text().splitlines())
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines; move detail to docs/ (limit {README_MAX_LINES})"


def test_readme_links_every_docs_page():
    readme = (ROOT / "README.md").read_text()
    linked = {(ROOT / t.partition("#")[0]).resolve() for t in LINK.findall(readme) if t.startswith("docs/")}
    missing = [p.name for p in sorted((ROOT / "docs").glob("*.md")) if p.resolve() not in linked]
    assert missing == [], f"docs pages the README does not link: {missing}"
