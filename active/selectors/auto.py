"""`auto`: cover_pool's geometric picks from a model trained on few views, the Fisher's (lite_gs) from a trained one.

The rule, fixed from the measurements in docs/recommend.md ("auto") before auto's own runs: at an acquisition step
with n captured views on a model trained for `it` iterations (since the last acquisition under train.py's
--stage_reset, which starts the model afresh there), lite_gs picks when n >= `auto_min_views` (8) and
it / n >= `auto_min_iters_per_view` (100); cover_pool picks otherwise. A model of unknown training length (a PLY from
another trainer) counts as trained. The step runs the chosen selector with its own oracle and its own oracle counts
(`for_step`), with the one line that says which and why, printed by recommend.py and train.py and recorded in
recommendations.json and selection.json.

Where the thresholds come from (docs/recommend.md, "auto"): from 5 captured views trained 1,000 iterations
(recommend-then-train) cover_pool was above coverage on lego, mic and bonsai and the Fisher last on lego and bonsai;
with the paper's stage lengths (Setup 1: picks at 2, 5 and 8 views after 200, 700 and 1,500 iterations) the Fisher
selectors ended above cover_pool on most scenes while cover_pool's runs were ahead after its first picks on lego and
the clutter scenes; at the default stage lengths (10-20 iterations per view before a pick) the geometry led. Those
runs shared one seed-view set per scene; with seed views drawn per seed (`--seed_start random`) cover_pool's picks
from 5 views are above random and level with camera-centre coverage on average, which the geometric branch's line says
(`GEOMETRIC_EVIDENCE`). `--auto_coverage_from V` puts coverage's picks on the geometric steps from V captured views;
with V = 5 auto kept its Setup 1 lead on lego and mic (its 2-view pick carries it) but not on bonsai, so the default
is 0 (never).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from active.base import Selection, SelectionContext, Selector, StepChoice, check_eps
from active.registry import register_selector
from active.selectors.cover_pool import (POOL_COMPARE_HELP, CoverPoolConfig, CoverPoolSelector,
                                        check_pool_compare)
from active.selectors.coverage import CoverageSelector
from active.selectors.lite_gs import LiteGSConfig, LiteGSSelector
from utils.errors import UserError

DEFAULT_MIN_VIEWS = 8
DEFAULT_MIN_ITERS_PER_VIEW = 100
GEOMETRIC_SELECTORS = ("cover_pool", "coverage")
# What the geometric branch's picks measured from few views (docs/recommend.md, "Seed views drawn per seed")
GEOMETRIC_EVIDENCE = ("from 5 captured views with seed views drawn per seed (recommend-then-train) cover_pool's picks "
                      "measured above random and level with camera-centre coverage on average (lego -0.27, mic -0.03, "
                      "bonsai -0.13 and +0.21 dB on two reconstructions; 9, 9, 3 and 6 seeds): --method coverage is "
                      "as good")


@dataclass(frozen=True)
class AutoConfig:
    auto_min_views: int = field(default=DEFAULT_MIN_VIEWS, metadata={
        "help": f"auto: the Fisher (lite_gs) picks from this many captured views on, an integer >= 1 (default "
                f"{DEFAULT_MIN_VIEWS}); fewer: cover_pool"})
    auto_min_iters_per_view: int = field(default=DEFAULT_MIN_ITERS_PER_VIEW, metadata={
        "help": f"auto: the Fisher also needs at least this many training iterations per captured view, an "
                f"integer >= 0 (default {DEFAULT_MIN_ITERS_PER_VIEW})"})
    eps: float = field(default=0.1, metadata={"help": "accuracy parameter in (0, 1): guarantee 1 - exp(-(1 - eps)), "
                                                      "about M ln(1/eps) oracles per step"})
    pool_compare: str = field(default="none", metadata={"help": POOL_COMPARE_HELP})
    auto_geometric: str = field(default="cover_pool", metadata={
        "help": "auto: the selector of the geometric steps, cover_pool (default) or coverage (camera centres, "
                "farthest point: level with cover_pool from 5 views with drawn seed views; in Setup 1 0.36 dB below "
                "it on lego and 0.64 on mic)"})
    auto_coverage_from: int = field(default=0, metadata={
        "help": "auto: geometric steps with at least this many captured views take coverage's picks (camera centres, "
                "farthest point), fewer take --auto_geometric's; an integer >= 0, 0 (default): never. 5 measured in "
                "Setup 1 (paper stage lengths, drawn seed views): level with auto on lego and mic, 0.53 dB below it "
                "on bonsai"})

    def __post_init__(self) -> None:
        if not isinstance(self.auto_min_views, int) or self.auto_min_views < 1:
            raise UserError(f"--auto_min_views must be an integer >= 1, got {self.auto_min_views!r}")
        if not isinstance(self.auto_min_iters_per_view, int) or self.auto_min_iters_per_view < 0:
            raise UserError(f"--auto_min_iters_per_view must be an integer >= 0, got {self.auto_min_iters_per_view!r}")
        check_eps(self.eps)
        check_pool_compare(self.pool_compare)
        if self.auto_geometric not in GEOMETRIC_SELECTORS:
            raise UserError(f"--auto_geometric must be one of {', '.join(GEOMETRIC_SELECTORS)}, got "
                            f"{self.auto_geometric!r}")
        if not isinstance(self.auto_coverage_from, int) or self.auto_coverage_from < 0:
            raise UserError(f"--auto_coverage_from must be an integer >= 0 (0: never), got {self.auto_coverage_from!r}")
        if self.auto_geometric == "coverage" and self.pool_compare != "none":
            raise UserError("--pool_compare applies to cover_pool's steps; with --auto_geometric coverage leave it "
                            "at none")


@register_selector("auto", config=AutoConfig)
class AutoSelector(Selector):
    """cover_pool or lite_gs, chosen per step by the number of captured views and the training length."""

    oracle_kind = "logdet"  # the heavier branch's, for memory checks made before the step is known
    delegates = True

    def __init__(self, config: AutoConfig | None = None):
        self.config = config if config is not None else AutoConfig()
        self.coverage = CoverageSelector()
        self.geometric = (self.coverage if self.config.auto_geometric == "coverage"
                          else CoverPoolSelector(CoverPoolConfig(pool_compare=self.config.pool_compare)))
        self.fisher = LiteGSSelector(LiteGSConfig(eps=self.config.eps))

    def uses_fisher(self, num_captured: int, iterations: int | None) -> bool:
        """The rule: enough captured views, each trained on long enough (unknown training length counts as long)."""
        trained = iterations is None or iterations >= self.config.auto_min_iters_per_view * num_captured
        return num_captured >= self.config.auto_min_views and trained

    def for_step(self, num_captured: int, iterations: int | None) -> StepChoice:
        c = self.config
        trained = "training length unknown, taken as trained" if iterations is None else (
            f"{iterations} iterations, {iterations / max(num_captured, 1):.0f} per view")
        if self.uses_fisher(num_captured, iterations):
            return StepChoice(self.fisher, f"auto: {num_captured} captured views, {trained}: the Fisher's picks "
                                           f"(lite_gs, eps {c.eps}), as from {c.auto_min_views} views trained "
                                           f"{c.auto_min_iters_per_view} iterations each (measured: above coverage "
                                           f"on 7 of 8 scenes and 0.3 dB below it on mic with fixed seed views; "
                                           f"0.8 dB above it on mic with seed views drawn per seed)")
        name, selector = self.geometric_for(num_captured)
        compared = ", compared with coverage's" if name == "cover_pool" and c.pool_compare == "coverage" else ""
        switch = (f", coverage's from {c.auto_coverage_from} captured views"
                  if c.auto_coverage_from and c.auto_geometric != "coverage" else "")
        evidence = f"; {GEOMETRIC_EVIDENCE}" if name == "cover_pool" else ""
        return StepChoice(selector, f"auto: {num_captured} captured views, {trained}: at this stage of training "
                                    f"the picks are geometric ({name}{compared}{switch}); the Fisher "
                                    f"(lite_gs) from {c.auto_min_views} views trained "
                                    f"{c.auto_min_iters_per_view} iterations each{evidence}")

    def geometric_for(self, num_captured: int) -> tuple[str, Selector]:
        """The geometric step's selector: coverage from `auto_coverage_from` captured views on, --auto_geometric's
        before."""
        c = self.config
        if c.auto_coverage_from and num_captured >= c.auto_coverage_from:
            return "coverage", self.coverage
        return c.auto_geometric, self.geometric

    def conservative_count(self, m: int, k: int) -> int:
        """The larger of the two branches' worst cases (the step's branch is not known before it runs)."""
        return max(self.geometric.conservative_count(m, k), self.fisher.conservative_count(m, k))

    def select(self, ctx: SelectionContext, k: int) -> Selection:
        raise RuntimeError("auto chooses a selector per step: call for_step(num_captured, iterations) and run its "
                           "selector (active.acquisition.run_selection does)")
