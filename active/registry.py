"""Selector registry: `@register_selector("name")` at the definition site, `build_selector(name, **options)`."""
from __future__ import annotations

from typing import Callable

from active.base import Selector
from utils.errors import UserError

_SELECTORS: dict[str, type[Selector]] = {}


def register_selector(name: str) -> Callable[[type[Selector]], type[Selector]]:
    """Class decorator registering a selector under `name` (duplicates are refused)."""
    def decorate(cls: type[Selector]) -> type[Selector]:
        if name in _SELECTORS:
            raise ValueError(f"selector {name!r} is already registered by {_SELECTORS[name].__name__}")
        _SELECTORS[name] = cls
        cls.name = name
        return cls
    return decorate


def list_selectors() -> list[str]:
    return sorted(_SELECTORS)


def build_selector(name: str, **options) -> Selector:
    """Instantiate a registered selector; an unknown name is a `UserError` listing the valid ones."""
    if name not in _SELECTORS:
        raise UserError(f"unknown selector {name!r}; choose one of: {', '.join(list_selectors())}")
    return _SELECTORS[name](**options)
