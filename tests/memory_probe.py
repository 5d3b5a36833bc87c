"""The peak resident memory of Fisher passes next to `active.memory_budget.estimate`, for tests/test_memory_budget.py.

    python -m tests.memory_probe KIND:N:PARAMS ...     # one JSON line per pass: measured and estimated bytes

Each pass runs in this process after a warm-up on 500 Gaussians (numba kernels loaded), on a model whose Gaussians
every view sees (small, faint splats: no pixel saturates), four 320 x 240 views (two for the prior, two
candidates, cached). The peak is VmHWM after resetting it (/proc/self/clear_refs, 5) less VmRSS before the pass,
with glibc's mmap threshold fixed (`fixed_mmap_threshold`) so that it is the peak of the live buffers.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import gc
import json
import math
import sys

import torch

from active.fisher import FISHER_PARAM_GROUPS, build_oracle
from active.memory_budget import FisherWork, block_size, estimate
from active.uncertainty import gaussian_uncertainty
from arguments import FisherSettings
from gaussian_renderer import RasterSettings
from gaussian_renderer.fisher_partials import RAW_PARAMETER_GROUPS
from scene.cameras import Camera, look_at
from scene.gaussian_model import GaussianModel

WIDTH, HEIGHT, VIEWS = 320, 240, 4
CACHE_MB = 4096  # holds both candidates


def faint_model(n: int, seed: int = 0, sh_degree: int = 3) -> GaussianModel:
    """`n` small, faint Gaussians in a 0.5-wide cube: every view sees nearly all of them."""
    g = torch.Generator().manual_seed(seed)
    params = {"means": (torch.rand(n, 3, generator=g) * 2 - 1) * 0.25,
              "quats": torch.randn(n, 4, generator=g),
              "log_scales": torch.log(0.005 * (0.5 + torch.rand(n, 3, generator=g))),
              "logit_opacities": torch.randn(n, generator=g) - 4,
              "sh_dc": torch.randn(n, 1, 3, generator=g) * 0.5,
              "sh_rest": torch.randn(n, (sh_degree + 1) ** 2 - 1, 3, generator=g) * 0.1}
    model = GaussianModel(sh_degree, params)
    model.active_sh_degree = sh_degree
    return model


def ring_cameras() -> list[Camera]:
    """`VIEWS` cameras on a ring around the cube, 30 degrees wide."""
    f = 0.5 * WIDTH / math.tan(math.radians(15))
    return [Camera(i, f"c{i}", look_at(torch.tensor([3 * math.cos(a), 3 * math.sin(a), 1.0])), f, f, WIDTH / 2,
                   HEIGHT / 2, WIDTH, HEIGHT) for i, a in enumerate(2 * math.pi * k / VIEWS for k in range(VIEWS))]


def run_pass(kind: str, gaussians: GaussianModel, params: str) -> None:
    """The pass of `kind` (`memory_budget.PASS_KINDS`) over `ring_cameras`: prior of views 0, 1, candidates 2, 3."""
    cameras, background, settings = ring_cameras(), torch.zeros(3), RasterSettings(backend="compiled")
    if kind == "uncertainty":
        gaussian_uncertainty(gaussians, cameras, [0, 1], background, settings,
                             fisher=FisherSettings(fisher_params=params))
        return
    oracle = build_oracle(kind, gaussians, cameras, [0, 1], background, settings,
                          fisher=FisherSettings(fisher_params=params, fisher_cache_mb=CACHE_MB))
    for view in (2, 3):
        oracle.gain(view) if kind == "logdet" else oracle.diagonal(view)
    oracle.commit(2)


def fixed_mmap_threshold(limit: int = 1 << 17) -> None:
    """Serve every block above `limit` bytes by its own mmap and give it back at free (glibc `mallopt`).

    glibc raises its mmap threshold after a large block is freed, after which freed large blocks stay in the heap
    and a later pass reuses them without its resident size growing: the measured peak then depends on what ran
    before (511-608 MB for the same diagonal pass). A fixed threshold turns that adaptation off.
    """
    libc = ctypes.CDLL(ctypes.util.find_library("c"))
    m_trim_threshold, m_mmap_threshold = -1, -3
    libc.mallopt(m_mmap_threshold, limit)
    libc.mallopt(m_trim_threshold, limit)


def status_bytes(field: str) -> int:
    """A /proc/self/status memory field (kB) in bytes."""
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) * 1024 for line in fh if line.startswith(field + ":"))


def measure(kind: str, n: int, params: str) -> dict:
    """Measured peak and estimate of one pass, in bytes."""
    run_pass(kind, faint_model(500, seed=1), params)  # warm-up
    gaussians = faint_model(n)
    gc.collect()
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")
    before = status_bytes("VmRSS")
    run_pass(kind, gaussians, params)
    measured = status_bytes("VmHWM") - before
    groups = RAW_PARAMETER_GROUPS if kind == "diagonal" else FISHER_PARAM_GROUPS[params]
    work = FisherWork(kind, n, block_size(gaussians, groups), WIDTH * HEIGHT, VIEWS - 2)
    return {"kind": kind, "n": n, "params": params, "measured": measured,
            "estimate": estimate(work, CACHE_MB << 20).peak}


if __name__ == "__main__":
    torch.set_num_threads(1)
    fixed_mmap_threshold()
    for spec in sys.argv[1:]:
        kind, n, params = spec.split(":")
        print(json.dumps(measure(kind, int(n), params)), flush=True)
