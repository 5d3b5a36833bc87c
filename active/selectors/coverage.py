"""`coverage`: farthest-point sampling of the cameras from the current training set (as in "NeRF Director").

Each pick is the candidate whose point is farthest from its nearest neighbour among the training views and the
picks so far; ties go to the lowest view id. The points are the camera centres (`--coverage_space centers`) or the
viewing directions on the unit sphere around the scene centre, (c - o) / |c - o| with o the point the cameras look
at (`--coverage_space directions`; it ignores how far a camera stands). `--coverage_objective pool` replaces
farthest-point sampling by greedy facility location over the pool (captured views and candidates): each pick
minimises the summed distance from every pool view to its nearest chosen one (`active.facility_location`), so the
picks stand for many pool views rather than the pool's extremes. No oracle: the count is 0.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import torch

from active.base import Selection, SelectionContext, Selector, check_k, unscored_selection
from active.facility_location import facility_location_picks
from active.farthest_point import farthest_point_picks
from active.registry import register_selector
from utils.errors import UserError

SPACES = ("centers", "directions")
OBJECTIVES = ("none", "pool")  # none: farthest-point sampling, the selector's original criterion
COVERAGE_SPACE_HELP = ("farthest-point sampling of camera centres, or of viewing directions on the unit sphere around "
                       "the scene centre ('directions')")


def coverage_points(ctx: SelectionContext, space: str) -> torch.Tensor:
    """The points farthest-point sampling works on, one row per view id. [V, 3]"""
    if ctx.camera_centers is None or (space == "directions" and ctx.scene_center is None):
        raise ValueError("the coverage selector needs camera_centers (and scene_center for directions) "
                         "in the SelectionContext")
    centers = ctx.camera_centers.double()
    if space == "centers":
        return centers
    offsets = centers - ctx.scene_center.double()
    return offsets / offsets.norm(dim=-1, keepdim=True).clamp_min(1e-12)


@dataclass(frozen=True)
class CoverageConfig:
    coverage_space: str = field(default="centers", metadata={"help": COVERAGE_SPACE_HELP})
    coverage_objective: str = field(default="none", metadata={
        "help": "none (farthest-point sampling: the view farthest from those chosen) or pool (facility location: "
                "the view after which the pool's views lie nearest, in sum, to a chosen one)"})

    def __post_init__(self) -> None:
        if self.coverage_space not in SPACES:
            raise UserError(f"--coverage_space must be one of {', '.join(SPACES)}, got {self.coverage_space!r}")
        if self.coverage_objective not in OBJECTIVES:
            raise UserError(f"--coverage_objective must be one of {', '.join(OBJECTIVES)}, "
                            f"got {self.coverage_objective!r}")


@register_selector("coverage", config=CoverageConfig)
class CoverageSelector(Selector):
    """Camera coverage: the candidate farthest from the training views, K times."""

    uses_oracle = False

    def __init__(self, config: CoverageConfig = CoverageConfig()):
        self.config = config

    def conservative_count(self, m: int, k: int) -> int:
        return 0

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        points = coverage_points(ctx, self.config.coverage_space)
        if self.config.coverage_objective == "pool":
            ids = facility_location_picks(points, list(ctx.train_ids), ctx.candidate_ids, k, self.config.coverage_space)
        else:
            ids = farthest_point_picks(points, list(ctx.train_ids), ctx.candidate_ids, k)
        return unscored_selection(ctx, ids)
