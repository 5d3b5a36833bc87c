"""`fisherrf`: FisherRF's batch acquisition (Jiang et al., ECCV 2024) with a diagonal Fisher per parameter.

A view's information is the diagonal of its Fisher, h_v = sigma^-2 sum over pixels and channels of (dI/dtheta)^2 per
raw parameter theta (the diagonal of the per-view blocks `fisher_view_blocks`, from the "diagonal" oracle), over the
parameter groups of `--fisherrf_params` (FisherRF leaves the rotation out; here the default drops `quats`). With h the
training views' diagonal, a candidate scores

    score(c) = sum_theta h_c / (h + lambda),

and the batch is built greedily: the best candidate is picked, h <- h + h_pick, and the rest are scored again.
Scale convention: h is in the units of the rendered image (colours in [0, 1]) summed over pixels and channels with
the run's `--sigma` (1 by default, as FisherRF, whose lambda = 1e-6 is the default here); lambda is added to h as is,
so it is not rescaled with the resolution or sigma. Counts: every candidate scored at every pick is one oracle
evaluation, conservative = evaluated = sum_{j < min(K, M)} (M - j); ties go to the lowest view id.

`--fisherrf_variant`: "exact" (default) scores the exact diagonal above; "reference" scores the diagonal FisherRF's
public code computes (`active.fisher.fisher_view_diagonals_reference`: channel-summed squares for geometry and
opacity, the exp / sigmoid derivative applied once after squaring; rotation cannot be scored), see docs/deviations.md.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import torch

from active.base import Selection, SelectionContext, Selector, check_k
from active.oracle_counts import exhaustive_count
from active.registry import register_selector
from gaussian_renderer.fisher_partials import RAW_PARAMETER_GROUPS
from utils.errors import UserError, parse_distinct_choices

DEFAULT_GROUPS = "means,log_scales,logit_opacities,sh_dc,sh_rest"  # FisherRF's set: every parameter but rotation
VARIANTS = {"exact": "diagonal", "reference": "diagonal_reference"}  # --fisherrf_variant -> the oracle kind


def parse_groups(text: str) -> tuple[str, ...]:
    """Comma-separated raw parameter groups -> a tuple; an empty, repeated or unknown group is one UserError line."""
    return parse_distinct_choices(text, RAW_PARAMETER_GROUPS, "--fisherrf_params", "groups")


@dataclass(frozen=True)
class FisherRFConfig:
    fisherrf_lambda: float = field(default=1e-6, metadata={"help": "regulariser lambda > 0 in h_c / (h_train + "
                                                                   "lambda), in units of the diagonal Fisher"})
    fisherrf_params: str = field(default=DEFAULT_GROUPS, metadata={"help": "comma-separated raw parameter groups "
                                                                           "scored (default: all but quats)"})
    fisherrf_variant: str = field(default="exact", metadata={"help": "Fisher diagonal: exact (per-channel squares, "
                                                                     "full chain rule) or reference (FisherRF's code)"})

    def __post_init__(self) -> None:
        if not self.fisherrf_lambda > 0:
            raise UserError(f"--fisherrf_lambda must be positive, got {self.fisherrf_lambda}")
        if self.fisherrf_variant not in VARIANTS:
            raise UserError(f"--fisherrf_variant {self.fisherrf_variant!r}: choose one of {', '.join(VARIANTS)}")
        if self.fisherrf_variant == "reference" and "quats" in parse_groups(self.fisherrf_params):
            raise UserError("--fisherrf_variant reference cannot score quats (FisherRF's code leaves rotation out); "
                            "drop quats from --fisherrf_params")


@register_selector("fisherrf", config=FisherRFConfig)
class FisherRFSelector(Selector):
    """Greedy batch of the highest diagonal-Fisher scores, the information updated after each pick."""

    oracle_kind = "diagonal"

    def __init__(self, config: FisherRFConfig = FisherRFConfig()):
        self.config = config
        self.groups = parse_groups(config.fisherrf_params)
        self.oracle_kind = VARIANTS[config.fisherrf_variant]

    def conservative_count(self, m: int, k: int) -> int:
        return exhaustive_count(m, k)

    def columns(self, ctx: SelectionContext) -> torch.Tensor:
        """The oracle's columns of the scored groups. [P']"""
        cols = ctx.oracle.columns
        missing = [g for g in self.groups if g not in cols]
        if missing:
            raise ValueError(f"the diagonal oracle has no columns for {', '.join(missing)} (it has {', '.join(cols)})")
        return torch.cat([torch.arange(cols[g].start, cols[g].stop) for g in self.groups])

    def score(self, h_view: torch.Tensor, h_train: torch.Tensor) -> float:
        """sum h_c / (h_train + lambda) over the given columns. [N, P'], [N, P'] -> float"""
        return float((h_view / (h_train + self.config.fisherrf_lambda)).sum())

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        check_k(k)
        cols = self.columns(ctx)
        remaining = sorted(ctx.candidate_ids)
        ids, gains, calls = [], [], 0
        for _ in range(min(k, len(remaining))):
            h_train = ctx.oracle.information[:, cols]  # [N, P']
            best, best_score = remaining[0], float("-inf")
            for view in remaining:  # ascending ids and a strict '>': ties go to the lowest id
                value = self.score(ctx.oracle.diagonal(view)[:, cols], h_train)
                calls += 1
                if value > best_score:
                    best, best_score = view, value
            ctx.oracle.commit(best)  # h <- h + h_pick
            remaining.remove(best)
            ids.append(best)
            gains.append(best_score)
        return Selection(ids, gains, calls)
