"""User-facing errors: one clear line that names the problem and the fix."""
from __future__ import annotations

import sys
from typing import Callable


class UserError(Exception):
    """An error caused by the user's input; its message is printed as one line, without a traceback."""


def run_cli(main: Callable[[], int | None]) -> None:
    """Run a CLI ``main``; turn a ``UserError`` into ``error: ...`` on stderr and exit status 2."""
    try:
        code = main()
    except UserError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        sys.exit(130)
    sys.exit(code or 0)
