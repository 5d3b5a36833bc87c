"""Shared test set-up: repository root on sys.path, the shared data directory, tiny generated datasets."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

SHARED = Path(os.environ.get("LITEGS_SHARED", ROOT.parent / "shared"))


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)
    yield


@pytest.fixture
def shared_dir() -> Path:
    """The ../shared directory (or $LITEGS_SHARED); skips the test when it is absent."""
    if not SHARED.is_dir():
        pytest.skip(f"shared data not found at {SHARED} (set LITEGS_SHARED)")
    return SHARED


@pytest.fixture(scope="session")
def tiny_scene(tmp_path_factory) -> Path:
    """A 32 px built-in scene with 14 training and 4 test views (generated once per session)."""
    from scene.builtin import make_builtin_scene
    return make_builtin_scene(tmp_path_factory.mktemp("data") / "tiny", seed=0, resolution=32, num_train=14,
                              num_test=4)


def run_cli(*args: str, cwd: Path = ROOT, timeout: int = 240) -> subprocess.CompletedProcess:
    """Run one of the project's CLIs with the test interpreter; returns the completed process."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)


@pytest.fixture(scope="session")
def active_model(tiny_scene, tmp_path_factory) -> Path:
    """A finished pop_gs run on the tiny scene (2 seed views, 2 stages, 8 views), rendered with uncertainty maps
    and evaluated (metrics.py --report also writes its report.html): a model directory with everything a run report
    reads (made once per session)."""
    model = tmp_path_factory.mktemp("active") / "model"
    for args in (("train.py", "-s", str(tiny_scene), "-m", str(model), "--method", "pop_gs", "--eval",
                  "--num_init_views", "2", "--views_per_step", "3", "--max_views", "8", "--iters_per_view", "4",
                  "--iterations", "70", "--num_random_points", "600", "--quiet", "--sh_degree", "1"),
                 ("render.py", "-m", str(model), "--quiet", "--uncertainty"),
                 ("metrics.py", "-m", str(model), "--quiet", "--report")):
        r = run_cli(*args)
        assert r.returncode == 0, r.stderr
    return model
