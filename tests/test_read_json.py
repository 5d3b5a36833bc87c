"""The one JSON reader (utils.io.read_json): the policy for a missing and a damaged file (not valid JSON, not
readable, the wrong type at the top) is the caller's explicit choice, and every error is one line naming the file and
the fix; readers that tolerate a damaged file do so through it (the grid summary skips a truncated run, warning)."""
from __future__ import annotations

import logging

import pytest

from experiments import summary
from scene.trained import read_model_record
from utils.errors import UserError
from utils.io import read_json, write_json


def test_a_fine_file_is_returned_whatever_the_policy(tmp_path):
    write_json(tmp_path / "a.json", {"x": [1, 2]})
    write_json(tmp_path / "b.json", [{"x": 1}])
    for missing, damaged in (("error", "error"), ("none", "warn"), ("none", "none")):
        assert read_json(tmp_path / "a.json", missing=missing, damaged=damaged) == {"x": [1, 2]}
    assert read_json(tmp_path / "b.json", kind=list) == [{"x": 1}]
    assert read_json(str(tmp_path / "b.json"), kind=None) == [{"x": 1}]


def test_a_missing_file_raises_naming_it_or_is_none(tmp_path):
    path = tmp_path / "nothing.json"
    with pytest.raises(UserError, match=r"^pose file .*nothing\.json does not exist; check the path$"):
        read_json(path, what="pose file", damaged="none")  # the damaged policy does not cover a missing file
    assert read_json(path, missing="none") is None


@pytest.mark.parametrize("content, problem", [
    (b'{"config": {"meth', r"is not valid JSON \(Unterminated string"),  # cut off mid-write
    (b"\xff\xfe{}", r"is not valid JSON \("),  # not UTF-8
    (b"[1, 2]", r"holds an array where an object belongs"),  # the wrong type at the top
    (b'"text"', r"holds a string where an object belongs"),
])
def test_a_damaged_file_is_one_line_with_the_fix_or_skipped(tmp_path, caplog, content, problem):
    path = tmp_path / "run_status.json"
    path.write_bytes(content)
    with pytest.raises(UserError, match=rf"run_status\.json {problem}.*; restore it$") as err:
        read_json(path, missing="none", fix="restore it")  # the missing policy does not cover a damaged file
    assert "\n" not in str(err.value) and str(path) in str(err.value)
    with caplog.at_level(logging.WARNING, logger="utils.io"):
        assert read_json(path, damaged="none") is None
        assert not caplog.records
        assert read_json(path, damaged="warn", fix="restore it") is None
    assert [r.getMessage() for r in caplog.records] == [f"skipping {err.value}"]


def test_an_unreadable_path_is_damaged_and_bad_policies_are_refused(tmp_path):
    (tmp_path / "cfg_args").mkdir()  # a folder where the file belongs
    with pytest.raises(UserError, match=r"^cannot read .*cfg_args \(Is a directory\); rerun the step that writes it$"):
        read_json(tmp_path / "cfg_args")
    assert read_json(tmp_path / "cfg_args", damaged="none") is None
    with pytest.raises(ValueError, match="missing must be one of"):
        read_json(tmp_path / "cfg_args", missing="skip")
    with pytest.raises(ValueError, match="damaged one of"):
        read_json(tmp_path / "cfg_args", damaged="ignore")


def test_callers_state_their_policy(tmp_path, caplog):
    """A model directory's cfg_args: missing and damaged are errors with their own fixes. A grid summary: a truncated
    selection.json is a listed problem with one warning, not a crash."""
    with pytest.raises(UserError, match="has no cfg_args: it is not a model directory written by train.py"):
        read_model_record(tmp_path)
    (tmp_path / "cfg_args").write_text("[]")
    with pytest.raises(UserError, match=r"cfg_args holds an array where an object belongs; retrain the model"):
        read_model_record(tmp_path)
    run = tmp_path / "setup1" / "lego" / "lite_gs" / "seed0"
    run.mkdir(parents=True)
    (run / "selection.json").write_text('{"config": {"meth')
    with caplog.at_level(logging.WARNING, logger="utils.io"):
        loaded = summary.load_run(run)
    assert loaded.problem.startswith("no readable selection.json")
    assert len(caplog.records) == 1 and "skipping" in caplog.text and "selection.json is not valid JSON" in caplog.text
