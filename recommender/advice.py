"""What the measurements say about a selector's picks, as one line for recommendations.json and stdout.

The measured facts behind it (recommend-then-train, docs/recommend.md): from a model trained on 5 captured views,
the Fisher selectors' picks were below coverage on the official lego (pop_gs 18.57, lite_gs 18.35 against 18.63 dB)
and above it on mic (pop_gs 22.51 against 22.06 dB); `cover` was level with coverage on lego and above it on mic.
No statistic of the model is known that tells the two cases apart, so the line states the evidence rather than a
rule. With models trained on the paper's stage lengths the Fisher selectors led (docs/results.md, Setup 1).
"""
from __future__ import annotations

from active.base import Selector

FEW_VIEWS = 10  # the regime of the recommend-then-train measurements (5 captured views), with a margin



def selection_advice(selector: Selector, num_captured: int) -> str | None:
    """One `note:` line on how far to trust `selector`'s picks for a model with `num_captured` views, or None."""
    selector_name = selector.name
    if selector_name == "random":
        return None
    if not selector.uses_oracle or selector.oracle_kind == "coverage":  # coverage, cover: no Fisher information
        return (f"note: {selector_name}'s picks are geometric (what the captured views saw poorly), not Fisher "
                "information: from few captured views Fisher picks measured no better than coverage on lego and "
                "better on mic (docs/recommend.md); --method pop_gs for the Fisher")
    if num_captured <= FEW_VIEWS:
        return (f"note: {num_captured} captured views: from 5 captured views {selector_name}-style Fisher picks "
                "measured below coverage on lego and above it on mic (docs/recommend.md); no rule is known that "
                "tells which case this model is in; --method cover gives the geometric picks")
    return None
