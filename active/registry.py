"""Selector registry: `@register_selector("name", config=Config)` at the definition site, `build_selector`.

A selector with options declares them as a frozen dataclass (`config=`) whose fields carry a default and a
`metadata={"help": ...}` line and whose `__post_init__` validates them. `build_selector(name, **options)` builds
that config and passes it to the selector's constructor; a selector without `config` takes no options.
The CLIs get one flag per option name (`selector_options_dataclass`): an option such as `--eps` reaches every
selector that declares it through this one path and is validated once, by the selector's config.
"""
from __future__ import annotations

import dataclasses
import typing
from typing import Any, Callable, Mapping

from active.base import Selector
from utils.errors import UserError

_SELECTORS: dict[str, tuple[type[Selector], type | None]] = {}


def register_selector(name: str, config: type | None = None) -> Callable[[type[Selector]], type[Selector]]:
    """Class decorator registering a selector under `name` (a second registration of a name is refused, and so is
    an option that another selector declares with a different type or default)."""
    if config is not None and not dataclasses.is_dataclass(config):
        raise TypeError(f"selector {name!r}: config must be a dataclass, got {config!r}")

    def decorate(cls: type[Selector]) -> type[Selector]:
        if name in _SELECTORS:
            raise ValueError(f"selector {name!r} is already registered by {_SELECTORS[name][0].__name__}")
        if config is not None:
            _check_shared_options(name, config)
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


def options_read_by(names: list[str]) -> set[str]:
    """The selector options that at least one of the selectors `names` reads."""
    return {option for name in names for option in selector_options(name)}


def build_selector(name: str, **options: Any) -> Selector:
    """Instantiate a registered selector; an unknown name or option is a `UserError` listing the valid ones."""
    cls, config = _lookup(name)
    valid = selector_options(name)
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise UserError(f"selector {name!r} has no option {', '.join(unknown)}; "
                        f"valid options: {', '.join(valid) or 'none'}")
    return cls(config(**options)) if config is not None else cls()


def build_selector_from(name: str, values: Mapping[str, Any]) -> Selector:
    """`build_selector` with the options `name` accepts taken from `values` (e.g. every parsed selector flag)."""
    return build_selector(name, **{option: values[option] for option in selector_options(name) if option in values})


def check_selector_options(values: Mapping[str, Any], names: list[str]) -> list[str]:
    """Validate every selector option in `values` by the config of each selector that declares it, so a bad value
    is a `UserError` whichever selector runs; return the options set away from their default that none of `names`
    reads (sorted), for a one-line note."""
    defaults: dict[str, Any] = {}
    for _, config in _SELECTORS.values():
        if config is None:
            continue
        fields = [f for f in dataclasses.fields(config) if f.name in values]
        config(**{f.name: values[f.name] for f in fields})  # its __post_init__ raises the one-line UserError
        defaults.update((f.name, list(f.default) if isinstance(f.default, tuple) else f.default) for f in fields)
    read = options_read_by(names)
    return sorted(o for o, default in defaults.items() if o not in read and values[o] != default)


def unread_options_note(values: Mapping[str, Any], names: list[str], runs: str) -> str | None:
    """`check_selector_options(values, names)`, then one line naming the unread options that `runs` (e.g. "--method
    lazy_pop") ignores and who reads each; None when every option set is read."""
    unread = check_selector_options(values, names)
    if not unread:
        return None
    readers = {o: [name for name in list_selectors() if o in selector_options(name)] for o in unread}
    return "note: ignored by " + runs + ": " + "; ".join(f"--{o} (read by {', '.join(readers[o])})" for o in unread)


def selector_options_dataclass() -> type:
    """A frozen dataclass with one field per option name over all registered selectors (for `add_config_args`);
    each field's help names the selectors that use it."""
    fields: dict[str, tuple[Any, dataclasses.Field, list[str]]] = {}
    for name in list_selectors():
        config = _SELECTORS[name][1]
        if config is None:
            continue
        hints = typing.get_type_hints(config)
        for f in dataclasses.fields(config):
            fields.setdefault(f.name, (hints[f.name], f, []))[2].append(name)
    spec = []
    for option, (tp, f, users) in fields.items():
        help_text = f"[{', '.join(users)}] {(f.metadata or {}).get('help', '')}".rstrip()
        spec.append((option, tp, dataclasses.field(default=f.default, metadata={"help": help_text})))
    options = dataclasses.make_dataclass("SelectorOptions", spec, frozen=True)
    options.__doc__ = "Options declared by the selectors' own configs; a selector reads only those it declares."
    return options


def _check_shared_options(name: str, config: type) -> None:
    hints = typing.get_type_hints(config)
    for other, (_, other_config) in _SELECTORS.items():
        if other_config is None:
            continue
        other_hints = typing.get_type_hints(other_config)
        for f in dataclasses.fields(other_config):
            mine = {g.name: g for g in dataclasses.fields(config)}.get(f.name)
            if mine is not None and (hints[f.name] != other_hints[f.name] or mine.default != f.default):
                raise ValueError(f"selector {name!r}: option {f.name!r} clashes with selector {other!r} "
                                 "(same name, different type or default); rename it")


def _lookup(name: str) -> tuple[type[Selector], type | None]:
    if name not in _SELECTORS:
        raise UserError(f"unknown selector {name!r}; choose one of: {', '.join(list_selectors())}")
    return _SELECTORS[name]
