"""Active view selection: selectors (registered by name), the Fisher information oracle and the schedule."""
from active.registry import build_selector, list_selectors, register_selector
from active.selectors import lite_gs, pop_gs, random, ssg  # noqa: F401  (registers the selectors)

__all__ = ["build_selector", "list_selectors", "register_selector"]
