"""Atomic file writes (a reader never sees a half-written JSON, checkpoint or PLY) and the one JSON reader.

Every file that marks progress or holds results (run_status.json, cfg_args, selection.json, results.json,
per_view.json, the PLYs, the checkpoints, reports) goes through `atomic_write`: it is written to a temporary name in
the same directory, fsynced, and renamed over the target (`os.replace`), so the target is either the old file or
the whole new one. A full disk or a permission error during the write is one `UserError` line naming the path, the
bytes being written and the free space; the temporary file is removed and the old file is left as it was.

The one JSON reader, `read_json`, takes an explicit policy for a missing and for a damaged file (unreadable, not valid
JSON, or the wrong type at the top): a one-line `UserError` naming the file and the fix, or None for a caller that
tolerates it (a grid summary skips a run it cannot read, with a warning).
"""
from __future__ import annotations

import errno
import json
import logging
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable

from utils.errors import UserError

log = logging.getLogger(__name__)

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


MISSING_POLICIES = ("error", "none")  # read_json's `missing`
DAMAGED_POLICIES = ("error", "warn", "none")  # read_json's `damaged`
_JSON_TYPES = {dict: "an object", list: "an array", str: "a string", int: "a number", float: "a number",
               bool: "a boolean", type(None): "null"}


def read_json(path: str | os.PathLike, *, missing: str = "error", damaged: str = "error", kind: type | None = dict,
              what: str = "", fix: str = "rerun the step that writes it") -> Any:
    """The parsed JSON file `path` (`what` names it in messages, e.g. "pose file"), by an explicit policy.

    Args:
        missing: when the file does not exist: "error" raises a `UserError` naming it; "none" returns None.
        damaged: when it cannot be read, is not valid JSON (e.g. truncated) or its top level is not `kind` (None: any):
            "error" raises a one-line `UserError` naming the file, what is wrong and `fix`; "warn" logs that line
            (the caller skips the file) and returns None; "none" returns None.
    """
    if missing not in MISSING_POLICIES or damaged not in DAMAGED_POLICIES:
        raise ValueError(f"read_json: missing must be one of {MISSING_POLICIES} and damaged one of "
                         f"{DAMAGED_POLICIES}, got {missing!r} and {damaged!r}")
    label = f"{what} {path}" if what else str(path)
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        if missing == "none":
            return None
        raise UserError(f"{label} does not exist; check the path") from None
    except OSError as exc:
        problem = f"cannot read {label} ({exc.strerror or type(exc).__name__}); {fix}"
    except ValueError as exc:  # invalid JSON, or bytes that are not UTF-8
        problem = f"{label} is not valid JSON ({exc}); {fix}"
    else:
        if kind is None or isinstance(data, kind):
            return data
        problem = (f"{label} holds {_JSON_TYPES.get(type(data), type(data).__name__)} where {_JSON_TYPES[kind]} "
                   f"belongs; {fix}")
    if damaged == "error":
        raise UserError(problem)
    if damaged == "warn":
        log.warning("skipping %s", problem)
    return None


def save_torch(path: str | os.PathLike, obj: Any) -> None:
    """`torch.save` atomically."""
    import torch  # here, so that JSON writers (report.py) do not pay for importing torch

    atomic_write(path, lambda tmp: torch.save(obj, tmp))
