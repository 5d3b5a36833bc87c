"""train.py's device-related bad input: --device cuda without CUDA, and a Fisher cache budget too small to cache."""
import json

import pytest
import torch

from tests import device_compare as dc
from tests.conftest import run_cli


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
def test_device_cuda_without_cuda_is_one_error_line(tiny_scene, tmp_path):
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(tmp_path / "m"), "--device", "cuda", "--iterations", "5")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --device cuda") and "--device cpu" in lines[0]
    assert "Traceback" not in r.stderr and not (tmp_path / "m").exists()


def test_tiny_fisher_cache_budget_caches_part_of_the_pool_with_one_message(tiny_scene, tmp_path):
    """The candidates' factors need more than 1 MB per stage and one view less: the cache keeps part of the pool
    (same selection as --fisher_mode streaming) and says so once per acquisition step."""
    cached = run_cli("train.py", "-s", str(tiny_scene), "-m", str(tmp_path / "cached"), "--method", "pop_gs",
                     "--fisher_cache_mb", "1", *dc.ACTIVE_ARGS)
    assert cached.returncode == 0, cached.stderr[-2000:]
    messages = [line for line in cached.stderr.splitlines() if "caching part of them" in line]
    assert len(messages) == 2 and "--fisher_cache_mb" in messages[0] and "budget 1 MB" in messages[0]
    assert "switching the Fisher oracle to streaming" not in cached.stderr and "Traceback" not in cached.stderr
    streaming = dc.active_selection(tiny_scene, tmp_path / "streaming", "cpu", extra=("--fisher_mode", "streaming"))
    fallback = (tmp_path / "cached" / "selection.json").read_text()
    assert [s["selected"] for s in json.loads(fallback)["stages"]] == [s["selected"] for s in streaming["stages"]]
