"""The log-det oracle with COVER's geometric score beside it, for selectors that gate the Fisher by geometry.

`CoverGatedOracle` is a `GainOracle` whose counted gain is the log-det gain (`FisherOracle`); `cover_gain` is COVER's
score (`CoverageOracle`, O(|S| N) per call, no Fisher pass), counted apart in `cover_evaluated`. A commit adds the
view to both, so each stays the marginal gain given the same S.
"""
from __future__ import annotations

from typing import Any


class CoverGatedOracle:
    """A log-det oracle (the counted one) and a COVER oracle (the gate), committed together."""

    def __init__(self, logdet: Any, cover: Any):
        """Args:
            logdet: a `FisherOracle` (gain, commit, evaluated, views_computed, fisher_seconds).
            cover: a `CoverageOracle` over the same cameras and training views.
        """
        self.logdet = logdet
        self.cover = cover

    def gain(self, view_id: int) -> float:
        """The log-det gain(v | S): one oracle evaluation."""
        return self.logdet.gain(view_id)

    def cover_gain(self, view_id: int) -> float:
        """COVER's gain(v | S): counted in `cover_evaluated`, not in `evaluated`."""
        return self.cover.gain(view_id)

    def commit(self, view_id: int) -> None:
        """S <- S + {v} in both oracles (not an oracle evaluation)."""
        self.logdet.commit(view_id)
        self.cover.commit(view_id)

    def reset_counts(self) -> None:
        self.logdet.reset_counts()
        self.cover.reset_counts()

    @property
    def evaluated(self) -> int:
        return self.logdet.evaluated

    @property
    def cover_evaluated(self) -> int:
        return self.cover.evaluated

    def __getattr__(self, name: str) -> Any:  # views_computed, fisher_seconds, set_priority, ... of the Fisher oracle
        if name in ("logdet", "cover"):
            raise AttributeError(name)
        return getattr(self.logdet, name)
