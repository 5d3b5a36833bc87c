"""Selector registry: `@register_selector("name", config=Config)` at the definition site, `build_selector`.

A selector with options declares them as a frozen dataclass (`config=`) whose `__post_init__` validates them;
`build_selector(name, **options)` builds that config from the options and passes it to the selector's constructor.
A selector without `config` takes no options.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable

from active.base import Selector
from utils.errors import UserError

_SELECTORS: dict[str, tuple[type[Selector], type | None]] = {}


def register_selector(name: str, config: type | None = None) -> Callable[[type[Selector]], type[Selector]]:
    """Class decorator registering a selector under `name` (a second registration of a name is refused)."""
    if config is not None and not dataclasses.is_dataclass(config):
        raise TypeError(f"selector {name!r}: config must be a dataclass, got {config!r}")

    def decorate(cls: type[Selector]) -> type[Selector]:
        if name in _SELECTORS:
            raise ValueError(f"selector {name!r} is already registered by {_SELECTORS[name][0].__name__}")
        _SELECTORS[name] = (cls, config)
        cls.name = name
        return cls
    return decorate


def list_selectors() -> list[str]:
    """Registered selector names, sorted."""
    return sorted(_SELECTORS)


def selector_options(name: str) -> list[str]:
    """Option names `build_selector(name, ...)` accepts (the fields of its config)."""
    _, config = _lookup(name)
    return [f.name for f in dataclasses.fields(config)] if config is not None else []


def build_selector(name: str, **options: Any) -> Selector:
    """Instantiate a registered selector; an unknown name or option is a `UserError` listing the valid ones."""
    cls, config = _lookup(name)
    valid = selector_options(name)
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise UserError(f"selector {name!r} has no option {', '.join(unknown)}; "
                        f"valid options: {', '.join(valid) or 'none'}")
    return cls(config(**options)) if config is not None else cls()


def _lookup(name: str) -> tuple[type[Selector], type | None]:
    if name not in _SELECTORS:
        raise UserError(f"unknown selector {name!r}; choose one of: {', '.join(list_selectors())}")
    return _SELECTORS[name]
