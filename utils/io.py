"""Atomic file writes: a reader never sees a half-written JSON, checkpoint or PLY.

Every file that marks progress or holds results (run_status.json, cfg_args, selection.json, results.json,
per_view.json, the PLYs, the checkpoints, reports) goes through `atomic_write`: it is written to a temporary name in
the same directory, fsynced, and renamed over the target (`os.replace`), so the target is either the old file or
the whole new one. A full disk or a permission error during the write is one `UserError` line naming the path, the
bytes being written and the free space; the temporary file is removed and the old file is left as it was.
"""
from __future__ import annotations

import errno
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable

from utils.errors import UserError

# errno values that are the user's disk or permissions, not a bug: reported as one line instead of a traceback
DISK_ERRNOS = {errno.ENOSPC: "no space left on device", errno.EDQUOT: "disk quota exceeded",
               errno.EACCES: "permission denied", errno.EPERM: "operation not permitted",
               errno.EROFS: "read-only file system"}


def _fsync(fd: int) -> None:
    """os.fsync (one name, so tests can inject a failure here)."""
    os.fsync(fd)


def _free_bytes(path: Path) -> int | None:
    for folder in (path.parent, *path.parents):
        try:
            return shutil.disk_usage(folder).free
        except OSError:
            continue
    return None


def _size(num: int | None) -> str:
    if num is None:
        return "unknown"
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if num >= scale:
            return f"{num / scale:.1f} {unit}"
    return f"{num} bytes"


def disk_write_error(path: str | os.PathLike, exc: OSError, nbytes: int | None = None,
                     written: int | None = None) -> UserError | None:
    """A one-line `UserError` for an OSError of the disk-full / permission kind while writing `path` (None for any
    other error): the path, the bytes being written (or written before the failure) and the free space."""
    reason = DISK_ERRNOS.get(exc.errno)
    if reason is None:
        return None
    path = Path(path)
    what = (f"writing {_size(nbytes)}" if nbytes is not None
            else f"failed after {_size(written)}" if written is not None else "writing")
    fix = ("free some space or choose an output folder on another disk" if exc.errno in (errno.ENOSPC, errno.EDQUOT)
           else "choose a writable output folder (or fix its permissions)")
    return UserError(f"cannot write {path}: {reason} ({what}, {_size(_free_bytes(path))} free there; an old file "
                     f"is left unchanged); {fix}")


def _new_file_mode(path: Path) -> int:
    """The mode `open(path, 'w')` would give (mkstemp makes 0600): the old file's, else 0666 minus the umask."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask


def atomic_write(path: str | os.PathLike, data: bytes | str | Callable[[str], None]) -> None:
    """Write `data` (bytes, text as UTF-8, or a callback `write(tmp_path)` that writes the temporary file) to a
    temporary file next to `path`, fsync it, and rename it over `path` (then fsync the directory).

    Raises:
        UserError: no space, quota, permission or read-only file system (`disk_write_error`); the temporary file is
            removed and an existing `path` is unchanged. Other errors propagate, also without a temporary file left.
    """
    path = Path(path)
    if isinstance(data, str):
        data = data.encode("utf-8")
    nbytes = len(data) if isinstance(data, bytes) else None
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            if isinstance(data, bytes):
                view = memoryview(data)
                while view:
                    view = view[os.write(fd, view):]
            else:
                os.close(fd)
                fd = -1
                data(tmp)
                fd = os.open(tmp, os.O_RDONLY)
            os.fchmod(fd, _new_file_mode(path))
            _fsync(fd)
        finally:
            if fd >= 0:
                os.close(fd)
        os.replace(tmp, path)
        tmp = None
        _fsync_dir(path.parent)
    except BaseException as exc:
        written = None
        if tmp is not None:
            try:
                written = os.path.getsize(tmp)
                os.unlink(tmp)
            except OSError:
                pass
        if isinstance(exc, OSError) and (err := disk_write_error(path, exc, nbytes, written)) is not None:
            raise err from None
        raise


def _fsync_dir(folder: Path) -> None:
    """Make the rename durable (best effort: some file systems do not fsync directories)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        _fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_json(path: str | os.PathLike, data: Any) -> None:
    """Write `data` as indented JSON, atomically."""
    atomic_write(path, json.dumps(data, indent=2) + "\n")


def save_torch(path: str | os.PathLike, obj: Any) -> None:
    """`torch.save` atomically."""
    import torch  # here, so that JSON writers (report.py) do not pay for importing torch

    atomic_write(path, lambda tmp: torch.save(obj, tmp))
