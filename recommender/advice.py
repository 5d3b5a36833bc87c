"""What the measurements say about a selector's picks, as one line for recommendations.json and stdout.

The measured facts behind it (recommend-then-train, docs/recommend.md; 5 captured views, 4 picks, 3 seeds): the
Fisher selectors' picks were above coverage on the official mic (pop_gs 22.51 against 22.05 dB), below it on lego
(18.57 against 18.63), on the built-in scene (26.17 against 27.16) and on the held-out Mip-NeRF 360 bonsai (16.72
against 17.73, below random's 17.15, with a pick beside a seed view). Coverage was never more than 0.05 dB below
random's mean, so it is recommend.py's default. No statistic of the model is known that tells the Fisher's good
cases apart, so the line states the evidence rather than a rule. With models trained on the paper's stage lengths
the Fisher selectors led on lego, mic and bonsai (docs/results.md, Setup 1).
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
        return (f"note: {selector_name}'s picks are geometric (what the captured views covered poorly), not Fisher "
                "information: from 5 captured views coverage measured level with or above random on lego, mic, "
                "bonsai and the built-in scene, Fisher picks above it on mic only (docs/recommend.md); --method "
                "pop_gs for the Fisher")
    if num_captured <= FEW_VIEWS:
        return (f"note: {num_captured} captured views: from 5 captured views {selector_name}-style Fisher picks "
                "measured above coverage on mic and below it on lego, bonsai and the built-in scene (bonsai: 1 dB, "
                "below random; docs/recommend.md); no rule is known that tells which case this model is in; "
                "--method coverage gives the geometric picks")
    return None
