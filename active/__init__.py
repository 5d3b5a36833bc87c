"""Active view selection: selectors (registered by name), the Fisher information oracle and the schedule.

Public API: `Selector` (subclass it), `SelectionContext` (what `select` receives), `Selection` (what it returns),
`register_selector` (class decorator), `list_selectors`, `build_selector`. A new selector is one module under
`active/selectors/` plus its import line below.
"""
from active.base import GainOracle, Selection, SelectionContext, Selector
from active.registry import build_selector, build_selector_from, list_selectors, register_selector, selector_options
# importing a selector's module registers it
from active.selectors import coverage, fisherrf, lazy_pop, lite_gs, pop_gs, random, ssg  # noqa: F401

__all__ = ["GainOracle", "Selection", "SelectionContext", "Selector", "build_selector", "build_selector_from",
           "list_selectors", "register_selector", "selector_options"]
