"""Compiled CPU backend of the rasterizer (numba): which backend a call takes, and whether numba is there.

`RasterSettings.backend`: "torch" = the pure-torch path; "compiled" = these kernels (a `UserError` when numba
cannot be imported); "auto" = compiled when numba imports, else torch with one log line. CUDA tensors always take
the torch path. Kernels live in `kernels.py` and `row_kernels.py` (numba; the latter row-vectorised) and
`ops.py` (torch wrappers, autograd).

numba caches compiled kernels on disk (`cache=True`), keyed by the kernel source file's path and modification
time, so an edited kernel recompiles. The cache goes next to the source when that folder is writable, else to
$NUMBA_CACHE_DIR, which defaults here to ~/.cache/litegs-numba.
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


@lru_cache(maxsize=1)
def numba_import_error() -> str | None:
    """None when numba imports, else the import error (checked once per process)."""
    if not os.access(Path(__file__).parent, os.W_OK):
        os.environ.setdefault("NUMBA_CACHE_DIR", str(Path.home() / ".cache" / "litegs-numba"))
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
