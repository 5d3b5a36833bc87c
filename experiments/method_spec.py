"""Method specs of the experiment scripts: a selector name with options, NAME[+OPTION=VALUE...] (e.g.
"cover_pool+pool_weight=pixels"); the spec itself labels the results."""
from __future__ import annotations

import ast
from typing import Any

from active import build_selector
from active.base import Selector
from utils.errors import UserError


def parse_method_spec(spec: str) -> tuple[str, dict[str, str]]:
    """(selector name, {option: value as written}) of a spec."""
    name, *options = spec.split("+")
    parsed = {}
    for option in options:
        key, sep, value = option.partition("=")
        if not sep or not key or not value:
            raise UserError(f"method {spec!r}: write selector options as NAME+OPTION=VALUE "
                            "(e.g. pop_gs+gain_weight=opacity)")
        parsed[key] = value
    return name, parsed


def method_flags(spec: str) -> list[str]:
    """The CLIs' selector flags of a spec: "pop_gs+gain_weight=opacity" -> --method pop_gs --gain_weight opacity."""
    name, options = parse_method_spec(spec)
    return ["--method", name, *(arg for key, value in options.items() for arg in (f"--{key}", value))]


def _literal(value: str) -> Any:
    """A number or boolean as written ("0.7" -> 0.7), any other value as the string."""
    try:
        return ast.literal_eval(value)
    except (ValueError, SyntaxError):
        return value


def selector_from_spec(spec: str) -> Selector:
    """The selector a spec names, built with its options (unknown ones: `build_selector`'s one-line error)."""
    name, options = parse_method_spec(spec)
    return build_selector(name, **{key: _literal(value) for key, value in options.items()})
