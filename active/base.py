"""Types shared by the selectors: the context a selector receives, what it returns, the oracle it may call.

A selector depends only on the protocol of the oracle kind it declares (`Selector.oracle_kind`): "logdet" gives a
`GainOracle` (gain, commit, evaluated), "diagonal" a `DiagonalOracle` (per-view diagonal Fisher, commit, evaluated).
It never depends on how the Fisher blocks are made, and never changes training state: it returns a `Selection` and
`train.py` moves the chosen views.
Evaluations are counted in one place, the oracle (`evaluated`); a selector reports only its `conservative` count,
which its own `conservative_count(m, k)` states in closed form.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Protocol

import torch

from utils.errors import UserError


class GainOracle(Protocol):
    """Marginal information gain of a view given the views committed so far; counts its own evaluations."""

    evaluated: int  # gains computed so far (every call of `gain`)

    def gain(self, view_id: int) -> float:
        """rho(v | S) for the current S: one oracle evaluation."""

    def commit(self, view_id: int) -> None:
        """S <- S + {v} (not an oracle evaluation)."""


class DiagonalOracle(Protocol):
    """Diagonal Fisher information per parameter: the prior of the training views plus the committed views, and any
    candidate view's diagonal; counts its own evaluations."""

    evaluated: int  # candidate diagonals returned so far (every call of `diagonal`)
    columns: dict[str, slice]  # parameter group (e.g. "means") -> its columns of P
    information: torch.Tensor  # h = diag of (prior of the training views + committed views), float64 [N, P]

    def diagonal(self, view_id: int) -> torch.Tensor:
        """diag(H_v) of one candidate view, float64 [N, P]: one oracle evaluation."""

    def commit(self, view_id: int) -> None:
        """h <- h + diag(H_v) (not an oracle evaluation)."""


@dataclass(frozen=True)
class Selection:
    """What a selector returns for one acquisition step."""

    ids: list[int]  # chosen view ids, in pick order
    gains: list[float]  # marginal gain of each pick when chosen (0.0 for selectors without an oracle)
    conservative: int  # oracle count the paper reports: every candidate offered at every pick counts once
    note: str | None = None  # one line on a choice the selector made inside the step (printed and recorded)


@dataclass(frozen=True)
class SelectionContext:
    """Everything a selector may use."""

    candidate_ids: list[int]  # the pool V_c (views not yet in training), distinct ids
    oracle: GainOracle | DiagonalOracle | None  # of the selector's `oracle_kind`; None only if uses_oracle = False
    generator: torch.Generator  # seeded per stage by the caller: a fresh draw per stage
    stage: int
    train_ids: tuple[int, ...] = ()  # the current training views (ids of the same pool)
    camera_centers: torch.Tensor | None = None  # world centres of every view of the pool, row = view id [V, 3]
    scene_center: torch.Tensor | None = None  # the point the pool's cameras look at (least squares) [3]


class Selector:
    """Base class: choose `k` of the candidates, committing each pick to `ctx.oracle` as it goes.

    A subclass sets `uses_oracle`, implements `select` and `conservative_count`, and is registered with
    `@register_selector("name", config=OptionsDataclass)`; with a config it takes it as its one constructor argument.
    Exact ties between gains go to the lowest view id. When k >= M (the number of candidates) every candidate is
    returned: the step is run with k = M.
    """

    name: str = ""  # set by `register_selector`
    uses_oracle: bool = True  # False: `select` calls no gains (it still commits its picks when given an oracle)
    oracle_kind: str = "logdet"  # which oracle `ctx.oracle` is: "logdet" (GainOracle) or "diagonal" (DiagonalOracle)
    config: Any = None  # the options dataclass instance, for selectors registered with one
    delegates: bool = False  # True: every step is run by the selector `for_step` chooses, never by `select` (auto)

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        """Choose min(k, M) views of `ctx.candidate_ids`."""
        raise NotImplementedError

    def conservative_count(self, m: int, k: int) -> int:
        """Closed-form conservative oracle count of one step choosing `k` of `m` candidates (what `select` reports)."""
        raise NotImplementedError

    def options(self) -> dict[str, Any]:
        """The selector's options as a JSON-ready dict (empty without a config)."""
        return dataclasses.asdict(self.config) if self.config is not None else {}

    def for_step(self, num_captured: int, iterations: int | None) -> StepChoice:
        """The selector that runs a step with `num_captured` views taken on a model trained for `iterations` (None:
        unknown), with the line saying why: itself and no line, except for a selector with a rule (`auto`)."""
        return StepChoice(self)


@dataclass(frozen=True)
class StepChoice:
    """What `Selector.for_step` returns: the selector that runs the step and, for a selector that chooses another by
    a rule, the one line saying which and why (printed by train.py and recommend.py, recorded in their JSON)."""

    selector: Selector
    rule: str | None = None


def unscored_selection(ctx: SelectionContext, ids: list[int]) -> Selection:
    """The `Selection` of a selector that calls no gains (`uses_oracle = False`): its picks are committed to
    `ctx.oracle` when there is one, so that the oracle's information state matches the chosen set; no gains, count 0."""
    if ctx.oracle is not None:
        for view in ids:
            ctx.oracle.commit(view)
    return Selection(ids, [0.0] * len(ids), 0)


def check_k(k: int) -> None:
    """K must be positive (one clear line otherwise)."""
    if k <= 0:
        raise UserError(f"--views_per_step (K) must be positive, got {k}")


GAIN_WEIGHTS = ("none", "opacity", "area")  # --gain_weight: how the log-det selectors weigh each Gaussian's term
GAIN_WEIGHT_HELP = (f"log-det selectors: weight of each Gaussian's term, one of {', '.join(GAIN_WEIGHTS)} ('opacity': "
                    "by its opacity, so Gaussians that barely change a pixel count little; 'area': by the surface area "
                    "it stands for, r_8^2, so isolated Gaussians weigh most)")


def check_gain_weight(gain_weight: str) -> str:
    """--gain_weight must name one of `GAIN_WEIGHTS`."""
    if gain_weight not in GAIN_WEIGHTS:
        raise UserError(f"--gain_weight must be one of {', '.join(GAIN_WEIGHTS)}, got {gain_weight!r}")
    return gain_weight


def logdet_oracle_kind(gain_weight: str) -> str:
    """The oracle kind of a log-det selector: "logdet", or "logdet_<weight>" (each Gaussian's log-det term weighted,
    `active.gain_weights`, `active.fisher.build_oracle`)."""
    return "logdet" if check_gain_weight(gain_weight) == "none" else f"logdet_{gain_weight}"


class LogDetSelector(Selector):
    """A selector on the log-det oracle whose options (`config_class`, default values when none are given) carry
    `gain_weight`: its oracle kind follows that weighting (`logdet_oracle_kind`)."""

    config_class: type

    def __init__(self, config: Any = None):
        self.config = config if config is not None else self.config_class()
        self.oracle_kind = logdet_oracle_kind(self.config.gain_weight)


def check_eps(eps: float) -> float:
    """The accuracy parameter of the stochastic selectors must lie in (0, 1)."""
    if not 0.0 < eps < 1.0:
        raise UserError(f"--eps must lie in (0, 1), got {eps}")
    return float(eps)
