"""Compiled CPU backend of the rasterizer (numba): which backend a call takes, and whether numba is there.

`RasterSettings.backend`: "torch" = the pure-torch path; "compiled" = these kernels (a `UserError` when numba
cannot be imported); "auto" = compiled when numba imports, else torch with one log line. CUDA tensors always take
the torch path. Kernels live in `kernels.py` and `row_kernels.py` (numba; the latter row-vectorised) and
`ops.py` (torch wrappers, autograd).

numba caches compiled kernels on disk (`cache=True`), keyed by the kernel source file's path and modification
time, so an edited kernel recompiles. The cache goes next to the source when that folder is writable, else to
$NUMBA_CACHE_DIR, which defaults here to ~/.cache/litegs-numba.

On a CPU with AVX-512, LLVM's default tuning still vectorises with 256-bit registers (`prefer-256-bit`, a guard
against the clock drop of early AVX-512 parts); the kernels here are arithmetic-bound, and 512-bit registers make
the Fisher moment sums 1.1-1.2x faster on the 2-core Xeon this project is measured on (docs/performance.md). So
importing this package sets $NUMBA_CPU_FEATURES to the host's features without that preference, before numba is
imported, unless $NUMBA_CPU_FEATURES is set already or $LITEGS_VECTOR_BITS is 256. numba's cache is keyed by the
features, so the two builds do not mix.
"""
from __future__ import annotations

import logging
import os
from functools import lru_cache
from pathlib import Path

import torch

log = logging.getLogger(__name__)

BACKENDS = ("auto", "compiled", "torch")
NUMBA_HINT = ("the compiled rasterizer backend needs the numba package (pip install numba, it is in "
              "requirements.txt); pass --raster_backend torch (or auto) to fall back to the pure-torch rasterizer")


VECTOR_BITS_ENV = "LITEGS_VECTOR_BITS"


def configure_numba_environment() -> None:
    """numba's settings that must precede its import (module docstring): the cache folder where the package folder
    is read-only, and 512-bit vectors on AVX-512 hosts. Leaves every variable the user has set alone."""
    if not os.access(Path(__file__).parent, os.W_OK):
        os.environ.setdefault("NUMBA_CACHE_DIR", str(Path.home() / ".cache" / "litegs-numba"))
    if "NUMBA_CPU_FEATURES" in os.environ or os.environ.get(VECTOR_BITS_ENV, "512") == "256":
        return
    try:
        import llvmlite.binding as llvm
        features = llvm.get_host_cpu_features().flatten()
    except Exception:  # no llvmlite (so no numba) or no feature query on this platform: numba's defaults
        return
    if "+avx512f" in features.split(","):
        os.environ["NUMBA_CPU_FEATURES"] = features + ",-prefer-256-bit"


configure_numba_environment()


@lru_cache(maxsize=1)
def numba_import_error() -> str | None:
    """None when numba imports, else the import error (checked once per process)."""
    try:
        import numba  # noqa: F401
    except ImportError as exc:
        return str(exc)
    return None


@lru_cache(maxsize=1)
def _log_fallback(reason: str) -> None:
    log.info("rasterizer backend auto: numba is not importable (%s); using the pure-torch rasterizer", reason)


def use_compiled(backend: str, tensor: torch.Tensor) -> bool:
    """Whether a call with these settings and inputs on `tensor`'s device runs the compiled kernels."""
    if backend == "torch" or tensor.device.type != "cpu":
        return False
    error = numba_import_error()
    if error is None:
        return True
    if backend == "compiled":
        from utils.errors import UserError
        raise UserError(NUMBA_HINT)
    _log_fallback(error)
    return False
