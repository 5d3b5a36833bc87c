"""Method specs of the experiment scripts: a selector name with options, NAME[+OPTION=VALUE...] (e.g.
"cover_pool+pool_weight=pixels"); the spec itself labels the results."""
from __future__ import annotations

import typing

from active import build_selector
from active.base import Selector
from active.registry import selector_options_dataclass
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


def selector_from_spec(spec: str) -> Selector:
    """The selector a spec names, built with its options typed as the CLIs type the same flags (by the option's field
    type, `arguments.add_config_args`; every selector option is a str or a float); a value of the wrong type or an
    unknown option is one error line."""
    name, options = parse_method_spec(spec)
    types = typing.get_type_hints(selector_options_dataclass())  # option -> its type, over every registered selector
    typed = {}
    for key, value in options.items():
        try:
            typed[key] = types[key](value) if key in types else value  # unknown: build_selector names the valid ones
        except ValueError:
            raise UserError(f"method {spec!r}: --{key} takes a {types[key].__name__}, got {value!r}") from None
    return build_selector(name, **typed)
