"""Types shared by the selectors: the context a selector receives, what it returns, the oracle it may call."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import torch

from utils.errors import UserError


class GainOracle(Protocol):
    """Marginal information gain of a view given the views committed so far; counts its own evaluations."""

    evaluated: int

    def gain(self, view_id: int) -> float:
        """rho(v | S): one oracle evaluation."""

    def commit(self, view_id: int) -> None:
        """Add view `view_id` to S (not an oracle evaluation)."""


@dataclass(frozen=True)
class OracleCalls:
    conservative: int  # every sampled candidate counts (the count the paper reports)
    evaluated: int  # gains actually computed (lazy evaluation saves some)


@dataclass(frozen=True)
class Selection:
    ids: list[int]  # chosen view ids, in pick order
    gains: list[float]  # the marginal gain of each pick when it was chosen (0.0 for selectors without an oracle)
    oracle_calls: OracleCalls


@dataclass(frozen=True)
class SelectionContext:
    candidate_ids: list[int]  # the pool V_c (views not yet in training)
    oracle: GainOracle | None  # None for selectors with uses_oracle = False
    generator: torch.Generator  # seeded per stage
    stage: int


class Selector:
    """Base class: choose `k` of the candidates. Selectors never change training state."""

    uses_oracle: bool = True

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        raise NotImplementedError


def check_k(k: int) -> None:
    """K must be positive (one clear line otherwise)."""
    if k <= 0:
        raise UserError(f"--views_per_step (K) must be positive, got {k}")
