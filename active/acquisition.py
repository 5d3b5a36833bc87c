"""One acquisition step as a library call: build the selector's oracle over a pool of cameras, run the selector.

`run_selection` is the single place where a `SelectionContext` is assembled; `train.py`'s acquisition stage and
`recommender.pipeline` (recommend.py) both call it, so the same model, prior, candidates and seed give the same picks
from either entry point. Candidate cameras need a pose, intrinsics and a size only: no image is read.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import torch
from tqdm import tqdm

from active.base import Selection, SelectionContext, Selector
from active.fisher import build_oracle
from arguments import FisherSettings
from gaussian_renderer import RasterSettings
from gaussian_renderer.projection import camera_centers, look_at_point
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel

SEED_STRIDE = 100_003  # the generator of stage s of a run with seed r is seeded with r * SEED_STRIDE + s


@dataclass
class Acquisition:
    """What one step produced: the selection and the oracle's counts and times."""

    selection: Selection
    evaluated: int  # oracle evaluations actually computed (0 without an oracle)
    fisher_views_computed: int  # distinct candidate views whose Fisher blocks were computed
    fisher_seconds: float  # time computing Fisher blocks (prior included)
    seconds: float  # the whole step: oracle set-up (prior) + selection
    evaluated_gains: dict[int, float]  # candidate id -> its gain at its last evaluation (log-det oracles only)

    @property
    def gain_seconds(self) -> float:
        """Time outside the Fisher blocks: log-det gains, commits, bookkeeping."""
        return max(0.0, self.seconds - self.fisher_seconds)


class _RecordingOracle:
    """The oracle, recording the last gain it returned per view and ticking a progress bar at each evaluation; every
    other attribute (commit, counts, a diagonal oracle's information and columns) is the oracle's own."""

    def __init__(self, oracle: Any, bar: tqdm):
        self._oracle, self._bar = oracle, bar
        self.gains: dict[int, float] = {}  # view id -> its gain at its last evaluation

    def gain(self, view_id: int) -> float:
        self._bar.update(1)
        value = self._oracle.gain(view_id)
        self.gains[view_id] = float(value)
        return value

    def diagonal(self, view_id: int) -> torch.Tensor:
        self._bar.update(1)
        return self._oracle.diagonal(view_id)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._oracle, name)


def run_selection(selector: Selector, gaussians: GaussianModel, cameras: list[Camera], train_ids: list[int],
                  candidate_ids: list[int], k: int, background: torch.Tensor, settings: RasterSettings, *,
                  seed: int = 0, stage: int = 0, fisher: FisherSettings = FisherSettings(),
                  progress: bool = False) -> Acquisition:
    """Choose `k` of `candidate_ids` (indices into `cameras`) given the prior of `train_ids` (indices too).

    The generator is seeded with `seed * SEED_STRIDE + stage`; the camera centres and the scene centre (the point
    the pool's cameras look at) are those of all of `cameras`. `progress` shows a bar over oracle evaluations
    (its total is the selector's conservative count, an upper bound). The selector sees the oracle through a
    transparent recorder (`Acquisition.evaluated_gains`).
    """
    t0 = time.perf_counter()
    oracle = None
    if selector.uses_oracle:
        oracle = build_oracle(selector.oracle_kind, gaussians, cameras, list(train_ids), background, settings,
                              fisher=fisher)
    generator = torch.Generator().manual_seed(seed * SEED_STRIDE + stage)
    viewmats = torch.stack([c.viewmat.cpu() for c in cameras])  # [V, 4, 4]
    bar = tqdm(total=selector.conservative_count(len(candidate_ids), k) if candidate_ids else 0,
               desc=f"{selector.name} oracle evaluations", disable=not progress or oracle is None,
               dynamic_ncols=True, leave=False)
    recorder = _RecordingOracle(oracle, bar) if oracle is not None else None
    with bar:
        ctx = SelectionContext(candidate_ids=list(candidate_ids), oracle=recorder, generator=generator,
                               stage=stage, train_ids=tuple(train_ids),
                               camera_centers=camera_centers(viewmats), scene_center=look_at_point(viewmats))
        selection = selector.select(ctx, k)
    return Acquisition(selection, oracle.evaluated if oracle else 0, oracle.views_computed if oracle else 0,
                       oracle.fisher_seconds if oracle else 0.0, time.perf_counter() - t0,
                       dict(recorder.gains) if recorder else {})
