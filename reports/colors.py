"""Camera colours shared by the HTML reports and the live viewer (view.py), so a camera looks the same in both."""
from __future__ import annotations

SEED = "#111111"        # seed (initial) views
TEST = "#ff7f0e"        # held-out test cameras
CANDIDATE = "#a8a8a8"   # candidates never picked (no gain recorded)
TRAIN = "#1f77b4"       # training views of a run without selection (trained on all views)
STAGES = ("#1f77b4", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#17becf", "#bcbd22", "#e377c2")
GAIN_SCALE = "Viridis"  # candidates coloured by their evaluated gain


def stage_color(stage: int) -> str:
    """The colour of the picks of acquisition stage `stage` (0-based; the palette repeats after 8 stages)."""
    return STAGES[stage % len(STAGES)]


def hex_to_rgb(color: str) -> tuple[int, int, int]:
    """'#rrggbb' -> (r, g, b) in 0..255."""
    return int(color[1:3], 16), int(color[3:5], 16), int(color[5:7], 16)
