"""Two checkouts that share one package virtualenv each run their own code: scripts/setup_env.sh gives every checkout
its own .venv (its root first on the path, then the shared packages; no editable install shared between checkouts),
so each clone's scripts/ and benchmarks/ import that clone's packages, whichever clone was set up last."""
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from tests.conftest import ROOT

MARKER = "run_cli edited in clone b"

pytestmark = pytest.mark.skipif(
    shutil.which("git") is None or shutil.which("flock") is None
    or subprocess.run(["git", "-C", str(ROOT), "rev-parse"], capture_output=True).returncode != 0,
    reason="needs git, flock (util-linux) and a git checkout of the project")


def _clone(dest: Path) -> None:
    """`git clone` this repository into dest, then carry over its uncommitted changes (the test checks the working
    tree, not the last commit)."""
    subprocess.run(["git", "clone", "-q", str(ROOT), str(dest)], check=True, timeout=60)
    changed = subprocess.run(["git", "ls-files", "-z", "--modified", "--others", "--exclude-standard"], cwd=ROOT,
                             check=True, capture_output=True, text=True).stdout.split("\0")
    for rel in filter(None, changed):
        if (ROOT / rel).is_file():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, dest / rel)
        else:  # deleted in the working tree
            (dest / rel).unlink(missing_ok=True)


def _package_venv(venvs: Path) -> Path:
    """A stand-in for the cached package virtualenv in venvs/, keyed as setup_env.sh keys it: an empty virtualenv
    whose .pth file reads this interpreter's packages (no download, and the real one is left alone)."""
    venv = venvs / hashlib.sha256((ROOT / "requirements.txt").read_bytes()).hexdigest()[:16]
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=60)
    purelib = "import sysconfig; print(sysconfig.get_path('purelib'))"
    site = subprocess.run([str(venv / "bin" / "python"), "-c", purelib], check=True, capture_output=True,
                          text=True).stdout.strip()
    packages = {str(Path(module.__file__).resolve().parents[1]) for module in (torch, pytest)}
    Path(site, "packages.pth").write_text("".join(f"{p}\n" for p in sorted(packages)))
    (venv / ".complete").touch()
    return venv


def test_each_checkout_runs_its_own_scripts_and_benchmarks(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    _clone(a)
    _clone(b)
    errors = b / "utils" / "errors.py"
    text = errors.read_text()
    body = "    try:\n        code = main()"
    edited = text.replace(body, f"    print({MARKER!r})\n{body}", 1)
    assert edited != text, "utils/errors.py's run_cli changed; update this test's edit"
    errors.write_text(edited)
    venv = _package_venv(tmp_path / "venvs")
    (a / ".venv").symlink_to(venv)  # what older set-ups left: .venv linked to the shared virtualenv
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"LITEGS_VENV_ROOT": str(tmp_path / "venvs")}
    for clone in (a, b):  # b last: with one editable install in the shared venv, a would now run b's code
        r = subprocess.run(["bash", "scripts/setup_env.sh"], cwd=clone, env=env, capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 0, r.stderr
        assert r.stdout.splitlines()[-1] == str(clone / ".venv" / "bin" / "python")
    assert not (a / ".venv").is_symlink()
    for clone, edited_here in ((a, False), (b, True)):
        for cli in ("scripts/report_screenshots.py", "benchmarks/selection_cost.py"):
            r = subprocess.run([str(clone / ".venv" / "bin" / "python"), cli, "--help"], cwd=clone, env=env,
                               capture_output=True, text=True, timeout=120)
            assert r.returncode == 0, r.stderr
            assert (MARKER in r.stdout) == edited_here, f"{clone.name}/{cli} ran the other clone's utils/errors.py"
