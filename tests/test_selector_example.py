"""The "Adding a selector" example of docs/selectors.md, executed as written: it registers, takes its option through
the registry (validated by its config), appears among the CLI's selector options, and selects the K best scored
views."""
import re
import types

import pytest
import torch

from active import build_selector, list_selectors, registry
from active.base import SelectionContext
from active.logdet import BlockGainOracle, BlockInformation
from tests.conftest import ROOT
from tests.test_logdet import random_blocks
from utils.errors import UserError

pytestmark = pytest.mark.usefixtures("single_torch_thread")  # tiny batched linear algebra (tests/conftest.py)


def docs_example() -> str:
    text = (ROOT / "docs" / "selectors.md").read_text()
    match = re.search(r"<!-- example:add-a-selector -->\s*```python\n(.*?)```", text, re.S)
    assert match, "docs/selectors.md lost its add-a-selector example"
    return match.group(1)


@pytest.fixture
def example(monkeypatch):
    """The example module, registered in a copy of the registry that the test throws away."""
    monkeypatch.setattr(registry, "_SELECTORS", dict(registry._SELECTORS))
    module = types.ModuleType("top_gain_example")
    exec(compile(docs_example(), "docs/selectors.md:add-a-selector", "exec"), module.__dict__)
    return module


def test_docs_example_is_short():
    assert len(docs_example().strip().splitlines()) <= 40


def test_example_registers_and_takes_its_option(example):
    assert "top_gain" in list_selectors()
    assert build_selector("top_gain", fraction=0.5).config.fraction == 0.5
    with pytest.raises(UserError, match="fraction must lie in"):
        build_selector("top_gain", fraction=0.0)
    options = registry.selector_options_dataclass()
    assert "fraction" in {f.name for f in __import__("dataclasses").fields(options)}


def test_example_selects_the_best_scored_views(example):
    m, k = 12, 3
    blocks = random_blocks(m + 1, 3, 2, seed=11)
    info = BlockInformation(blocks[0])
    before = [info.gain(blocks[v + 1]) for v in range(m)]  # every candidate's gain before the step
    oracle = BlockGainOracle(BlockInformation(blocks[0]), lambda v: blocks[v + 1])
    sel = build_selector("top_gain", fraction=0.5).select(
        SelectionContext(list(range(m)), oracle, torch.Generator().manual_seed(0), 0), k)
    assert sel.conservative == oracle.evaluated == 6  # half of the pool, scored once each
    assert len(sel.ids) == k and sel.gains == sorted(sel.gains, reverse=True)
    for view, gain in zip(sel.ids, sel.gains):
        assert gain == pytest.approx(before[view], rel=1e-12)
    full = build_selector("top_gain").select(
        SelectionContext(list(range(m)), BlockGainOracle(BlockInformation(blocks[0]), lambda v: blocks[v + 1]),
                         torch.Generator().manual_seed(0), 0), k)
    assert full.ids == sorted(range(m), key=lambda v: (-before[v], v))[:k]
