"""The selection library: which candidate views to add, given a model and the views it was trained on.

- selectors registered by name (`selectors/`, `registry.py`, `base.py`: `Selector`, `SelectionContext`, `Selection`);
- the oracle: Fisher information of a view (`fisher.py`) and its log-det gain (`logdet.py`, `logdet_kernels.py`,
  `trapezoid.py`; `brute_force.py`, the exact optimum over small subsets, for the fidelity benchmark);
- one acquisition step as a call (`acquisition.run_selection`), the schedule (`schedule.py`: seed views and stage
  plan; `farthest_point.py`) and oracle counts (`oracle_counts.py`);
- per-Gaussian and per-pixel uncertainty from the same Fisher information (`uncertainty.py`).

It takes cameras, Gaussians and view ids, and neither reads model directories nor draws pictures: its applications
do (`training/` and train.py, `recommender/` and recommend.py, render.py; tests/test_layering.py checks it).

Public API: `Selector` (subclass it), `SelectionContext` (what `select` receives), `Selection` (what it returns),
`GainOracle`, `register_selector` (class decorator), `list_selectors`, `build_selector`, `build_selector_from`,
`selector_options`. A new selector is one module under `active/selectors/` plus its import line below.
"""
from active.base import GainOracle, Selection, SelectionContext, Selector
from active.registry import build_selector, build_selector_from, list_selectors, register_selector, selector_options
# importing a selector's module registers it
from active.selectors import (auto, cover, cover_pool, cover_pop, coverage, fisherrf, lazy_pop, lite_gs,  # noqa: F401
                              novel_pop, pop_gs, probe_pop, random, render_variance, ssg)

__all__ = ["GainOracle", "Selection", "SelectionContext", "Selector", "build_selector", "build_selector_from",
           "list_selectors", "register_selector", "selector_options"]
