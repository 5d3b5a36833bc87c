"""What the measurements say about a selector's picks, as one line for recommendations.json and stdout.

The measured facts behind it (docs/recommend.md, 2026-12-05; recommend-then-train: 5 captured views, 4 picks,
3 seeds, the official lego and mic and Mip-NeRF 360 bonsai; the closed capture loop on the built-in scene):
cover (the default) was above random and at least level with coverage on all three scenes (vs random / vs coverage:
+0.10 / +0.00, +0.07 / +0.12, +0.55 / +0.00 dB), coverage 0.05 dB below random on mic; pop_gs was 1.0 dB below
coverage on lego and bonsai (last in all six of their seeds) and 0.30 dB above it on mic; render_variance 0.19 below
coverage on lego, level on mic, 0.29 above on bonsai. In the capture loop (candidates at the test views' elevations)
coverage and cover led, random was 1.9 dB behind and pop_gs 7.7 dB.
No statistic of the model is known that tells the Fisher's good cases apart, so the line states the evidence rather
than a rule. Computed on the base model's 200-iteration snapshot instead of the trained model (same protocol,
2026-12-06), pop_gs was 0.21 and 0.39 dB above coverage on lego and mic, 0.49 dB below it on bonsai and 0.95 dB
below it on the built-in scene (held out). With models trained on the paper's stage lengths (Setup 1, docs/results.md) the Fisher selectors led
on lego and mic, and cover on bonsai (2026-12-06: 21.04 dB against pop_gs's 20.60 and coverage's 19.58, every seed).
"""
from __future__ import annotations

from active.base import Selector
from active.memory_budget import ORACLE_PASSES

FEW_VIEWS = 10  # the regime of the recommend-then-train measurements (5 captured views), with a margin
EVIDENCE = "docs/recommend.md#which-selector-from-few-captured-views"


def selection_advice(selector: Selector, num_captured: int) -> str | None:
    """One `note:` line on how far to trust `selector`'s picks for a model with `num_captured` views, or None."""
    selector_name = selector.name
    if selector_name == "random":
        return None
    if not selector.uses_oracle or ORACLE_PASSES[selector.oracle_kind] is None:  # coverage, cover, cover_pool: no Fisher
        return (f"note: {selector_name}'s picks are geometric (what the captured views covered poorly), not Fisher "
                "information: from 5 captured views cover was above random and level with or above coverage on lego, "
                f"mic and bonsai, and pop_gs last on lego and bonsai ({EVIDENCE}); --method pop_gs for the Fisher")
    if num_captured <= FEW_VIEWS:
        return (f"note: {num_captured} captured views: from 5 captured views pop_gs's Fisher picks measured 0.3 dB "
                "above coverage on mic and 1 dB below it on lego and bonsai (render_variance: -0.2, 0.0, +0.3 dB), "
                "pop_gs 7.7 dB below it in the capture loop; computed on the model's 200-iteration snapshot "
                "(--iteration 200, saved by train.py --save_iterations 200) pop_gs measured 0.2-0.4 dB above coverage "
                f"on lego and mic, 0.5 and 1.0 dB below it on bonsai and the built-in scene ({EVIDENCE}); --method cover "
                "gives the geometric picks")
    return None
