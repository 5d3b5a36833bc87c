"""One writer per output folder: an exclusive `fcntl.flock` on a lock file that records the holder.

    with writer_lock(model_dir, ways_out="wait for it to finish, or pass a different -m"):
        ...  # write into model_dir

train.py, render.py, metrics.py and report.py lock a model directory through `model_dir/.lock`
(`utils.model_dir.LOCK_FILE`); recommend.py locks its output folder through a file beside it
(`utils.model_dir.folder_lock_file`), because it replaces that folder whole. A second writer gets one
`UserError` line naming the folder, the holder's pid and command line and `ways_out`. The kernel releases a flock
when its process dies, so the lock file a killed writer leaves is simply locked again, with a one-line note naming
the dead holder. A clean release deletes the lock file (while still holding it; an acquirer that locked the deleted
file sees that its inode is no longer the path's and tries again). The lock is re-entrant within one process (the
CLIs' in-process callers, metrics.py --report). Readers (view.py) take no lock.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Iterator

from utils.errors import UserError
from utils.model_dir import LOCK_FILE

# what each CLI's refusal suggests (--overwrite only where the CLI has it)
WAYS_OUT = {
    "train": ("wait for it to finish, or pass a different -m/--model_path (to restart that run, stop it first: "
              "rerunning the same command resumes it, --overwrite starts it again)"),
    "render": "wait for it to finish and render again, or pass a different -m/--model_path",
    "metrics": "wait for it to finish, or leave that directory out of -m/--model_paths",
    "report": "wait for it to finish, or pass -o to write the report elsewhere",
    "recommend": "wait for it to finish, or pass a different -o/--output",
}

_HELD: dict[str, list] = {}  # lock file (absolute) -> [fd, depth]: the locks this process holds
_RETRIES = 5  # a lock file deleted between our open and our flock (its holder released it): open again


def _holder(fd: int) -> dict:
    """The record in an open lock file ({} when empty or unreadable)."""
    try:
        data = json.loads(os.pread(fd, 65536, 0).decode("utf-8") or "{}")
    except (OSError, ValueError, UnicodeDecodeError):
        return {}
    return data if isinstance(data, dict) else {}


def _alive(pid: object) -> bool:
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def _describe(holder: dict) -> str:
    pid = holder.get("pid", "unknown")
    command = holder.get("command")
    since = f", since {holder['started']}" if holder.get("started") else ""
    return f"pid {pid} ({command}{since})" if command else f"pid {pid}{since}"


def _busy(folder: Path, holder: dict, lock_path: Path, ways_out: str) -> str:
    return f"{folder} is being written by another process, {_describe(holder)} (lock file {lock_path}); {ways_out}"


def _command_line() -> str:
    return shlex.join([Path(sys.executable).name, *sys.argv]) if sys.argv and sys.argv[0] else Path(sys.executable).name


def acquire(lock_path: Path, folder: Path, ways_out: str) -> int:
    """Lock `lock_path` (created, with its folder) and write our record into it; returns the open descriptor.

    Raises:
        UserError: another process holds it (naming `folder`, the holder and `ways_out`), or the folder cannot be
            written.
    """
    for _ in range(_RETRIES):
        try:
            lock_path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise UserError(f"cannot write to {folder} ({exc.strerror or exc}); choose a writable output folder "
                            "(-m/--model_path, -o)") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(fd)
            os.close(fd)
            raise UserError(_busy(folder, holder, lock_path, ways_out)) from None
        except OSError:
            os.close(fd)
            raise
        try:
            same = os.stat(lock_path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if not same:  # its holder released (deleted) it between our open and our flock
            os.close(fd)
            continue
        previous = _holder(fd)
        if previous:  # a holder that died without releasing: the kernel dropped its flock, its record stayed
            state = "is no longer running" if not _alive(previous.get("pid")) else "no longer holds it"
            print(f"note: {folder}: taking over the lock left by {_describe(previous)}, which {state}",
                  file=sys.stderr)
        record = {"pid": os.getpid(), "command": _command_line(), "started": time.strftime("%Y-%m-%d %H:%M:%S")}
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(record) + "\n").encode("utf-8"), 0)
        return fd
    raise UserError(f"{folder}: could not take the lock {lock_path} (other processes keep taking and releasing it); "
                    f"{ways_out}")


def release(lock_path: Path, fd: int) -> None:
    """Delete the lock file while still holding it, then unlock (close)."""
    try:
        os.unlink(lock_path)
    except OSError:
        pass
    os.close(fd)


@contextlib.contextmanager
def writer_lock(folder: str | os.PathLike, ways_out: str = "wait for it to finish, or choose another output folder",
                lock_path: str | os.PathLike | None = None, create: bool = True) -> Iterator[None]:
    """Hold the writer lock of `folder` (lock file `lock_path`, default `folder/.lock`) for the block.

    With `create=False` a folder that does not exist is not created and nothing is locked (a command that reads
    the folder first fails on its own with the right message).
    """
    folder = Path(folder)
    if not create and not folder.is_dir():
        yield
        return
    path = Path(os.path.abspath(lock_path if lock_path is not None else folder / LOCK_FILE))
    key = str(path)
    if key in _HELD:  # re-entrant: this process already holds it
        _HELD[key][1] += 1
        try:
            yield
        finally:
            _HELD[key][1] -= 1
        return
    created = _missing_folders(path.parent)  # made for the lock: removed again if the writer left them empty
    fd = acquire(path, folder, ways_out)
    _HELD[key] = [fd, 1]
    try:
        yield
    finally:
        depth = _HELD[key][1]
        if depth <= 1:
            del _HELD[key]
            release(path, fd)
            for made in created:  # innermost first; a folder the writer filled stays
                try:
                    made.rmdir()
                except OSError:
                    break
        else:
            _HELD[key][1] = depth - 1


def _missing_folders(folder: Path) -> list[Path]:
    """`folder` and its ancestors that do not exist yet, innermost first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def hold(folder: str | os.PathLike, ways_out: str, lock_path: str | os.PathLike | None = None) -> contextlib.ExitStack:
    """`writer_lock` taken now and held until the returned stack is closed (for a lock that outlives a block)."""
    stack = contextlib.ExitStack()
    stack.enter_context(writer_lock(folder, ways_out, lock_path))
    return stack


def _flag_value(argv: list[str], flags: tuple[str, ...]) -> str | None:
    """The last value given to one of `flags` ("-m DIR", "-mDIR", "--model_path DIR", "--model_path=DIR")."""
    value = None
    for i, arg in enumerate(argv):
        for flag in flags:
            if arg == flag and i + 1 < len(argv):
                value = argv[i + 1]
            elif flag.startswith("--") and arg.startswith(flag + "="):
                value = arg[len(flag) + 1:]
            elif not flag.startswith("--") and arg.startswith(flag) and len(arg) > len(flag) and arg[1] != "-":
                value = arg[len(flag):]
    return value


def refuse_if_locked(flags: tuple[str, ...], ways_out: str, argv: list[str] | None = None) -> None:
    """Before a CLI's slow imports (torch): when the folder its `flags` name on the command line is being written by
    another process, print the one `error:` line and exit with status 2, as `utils.errors.run_cli` does, so that a
    second writer is refused at once. Only a probe: the lock itself is taken later (`writer_lock`), when the
    command writes; anything unusual (no flag, no lock file, unreadable) is left to that."""
    folder = _flag_value(sys.argv[1:] if argv is None else argv, flags)
    if not folder:
        return
    lock_path = Path(folder) / LOCK_FILE
    try:
        fd = os.open(lock_path, os.O_RDONLY)
    except OSError:
        return
    try:
        holder = _holder(fd)
        if not _alive(holder.get("pid")):  # no live holder recorded: nothing to refuse (and no probe to race with)
            return
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)  # released at once by the close below
    except BlockingIOError:
        print(f"error: {_busy(Path(folder), holder, lock_path, ways_out)}", file=sys.stderr)
        sys.exit(2)
    except OSError:
        pass
    finally:
        os.close(fd)
