"""Shared test set-up: the shared data directory, tiny generated datasets, running the CLIs (the repository root is
on the import path through pytest.ini's `pythonpath`, and through the checkout's .venv for everything else), and a
guard that fails any test reaching the rasterizer with backend="auto" unless it opts in."""
from __future__ import annotations

import importlib
import os
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]

SHARED = Path(os.environ.get("LITEGS_SHARED", ROOT.parent / "shared"))


def _modules_binding(function) -> list:
    """Every gaussian_renderer module that holds `function` under its own name (imports them all once)."""
    import gaussian_renderer
    for info in pkgutil.walk_packages(gaussian_renderer.__path__, "gaussian_renderer."):
        importlib.import_module(info.name)
    return [module for name, module in sorted(sys.modules.items())
            if name.startswith("gaussian_renderer") and getattr(module, function.__name__, None) is function]


_BACKEND_BINDINGS: list = []


@pytest.fixture(autouse=True)
def _no_implicit_auto_backend(request, monkeypatch):
    """Fail loudly when a CPU rasterizer or Fisher-partials call resolves backend="auto".

    "auto" silently picks one backend (compiled when numba imports), so a test relying on it checks only that one;
    tests pass backend="torch" / "compiled" explicitly (usually parametrized over both). Tests about "auto" itself,
    or that run the user's default end to end in-process, opt in with @pytest.mark.auto_backend.
    """
    if request.node.get_closest_marker("auto_backend"):
        yield
        return
    from gaussian_renderer import compiled
    real = compiled.use_compiled
    if not _BACKEND_BINDINGS:
        _BACKEND_BINDINGS.extend(_modules_binding(real))

    def guarded(backend: str, tensor: torch.Tensor) -> bool:
        if backend == "auto" and tensor.device.type == "cpu":
            raise AssertionError('test reached the rasterizer with backend="auto" (the compiled path only); pass '
                                 'backend="torch" or "compiled" explicitly, or mark the test @pytest.mark.auto_backend')
        return real(backend, tensor)

    for module in _BACKEND_BINDINGS:
        monkeypatch.setattr(module, "use_compiled", guarded)
    yield


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
def tiny_model(tiny_scene, tmp_path_factory) -> Path:
    """A passive model trained for 30 iterations on the tiny scene (300 random points, SH degree 1), shared read-only
    by the benchmark tests (made once per session)."""
    model = tmp_path_factory.mktemp("tiny_model") / "model"
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(model), "--iterations", "30", "--num_random_points",
                "300", "--quiet", "--sh_degree", "1")
    assert r.returncode == 0, r.stderr
    return model


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


@pytest.fixture(scope="module")
def single_torch_thread():
    """Tiny batched linear algebra: one torch thread avoids ~ms of thread-pool hand-off per call on a busy machine
    (a module opts in with `pytestmark = pytest.mark.usefixtures("single_torch_thread")`)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
