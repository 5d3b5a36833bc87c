"""The provenance train.py records: the code's commit (and whether tracked files differ), machine and versions."""
import shutil
import subprocess

import pytest

from utils.provenance import UNKNOWN_CODE, code_version, session_record

needs_git = pytest.mark.skipif(shutil.which("git") is None, reason="git is not on PATH")


def _git(root, *args):
    subprocess.run(["git", "-C", str(root), "-c", "user.name=t", "-c", "user.email=t@t", *args], check=True,
                   capture_output=True)


@needs_git
def test_code_version_names_the_commit_and_local_changes(tmp_path):
    _git(tmp_path, "init", "-q")
    (tmp_path / "a.py").write_text("x = 1\n")
    _git(tmp_path, "add", "a.py")
    _git(tmp_path, "commit", "-q", "-m", "first")
    head = subprocess.run(["git", "-C", str(tmp_path), "rev-parse", "HEAD"], capture_output=True, text=True).stdout
    assert code_version(tmp_path) == head[:7]
    (tmp_path / "untracked.txt").write_text("not code of the commit, not counted\n")
    assert code_version(tmp_path) == head[:7]
    (tmp_path / "a.py").write_text("x = 2\n")
    assert code_version(tmp_path) == head[:7] + "+changes"


def test_code_version_outside_git(tmp_path):
    assert code_version(tmp_path) == UNKNOWN_CODE


def test_session_record_fields(tmp_path):
    record = session_record(iteration=120, device="cpu", root=tmp_path)
    assert record["from_iteration"] == 120 and record["device"] == "cpu" and record["code"] == UNKNOWN_CODE
    assert record["threads"] >= 1 and record["machine"] and record["torch"]
