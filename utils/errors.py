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


def parse_distinct_choices(text: str, valid, flag: str, noun: str) -> tuple[str, ...]:
    """Comma-separated choices of `flag` -> a tuple; an empty, repeated or unknown one is a one-line UserError that
    lists the valid `noun` (e.g. "groups", "kinds")."""
    choices = tuple(c.strip() for c in text.split(",") if c.strip())
    bad = [c for c in choices if c not in valid]
    if bad or not choices or len(set(choices)) != len(choices):
        raise UserError(f"{flag} {text!r}: give distinct comma-separated {noun} from "
                        f"{', '.join(valid)}" + (f" (unknown: {', '.join(bad)})" if bad else ""))
    return choices
