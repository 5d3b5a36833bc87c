"""A projection of a run's wall time from its first iterations, and the `-r` that would bring it under a limit.

After `MEASURE_UNTIL` iterations (the first `WARMUP` are not timed) the run knows its seconds per training step
and, for a selector that calls the Fisher oracle, the seconds of one view's Fisher blocks (timed once on the
current model). With the stage plan that gives

    total = remaining iterations x step + sum over the remaining acquisition steps of
            (prior views + candidate blocks) x fisher + conservative oracles x GAIN_FRACTION x fisher

Candidate blocks per step: cached mode computes each distinct candidate once (at most min(M, oracles)),
streaming mode once per oracle. Both unit costs grow linearly with the pixel count (the rasterizer's cost is
linear in pixels, see benchmarks/bench_rasterize.py --resolution_scaling), so a width w' projects to
total x (w'/w)^2. The estimate ignores how the cost per step changes during training (a fresh random initialisation
has large Gaussians that shrink: on lego at 200 px a step takes 0.55 s at first and 0.15 s by iteration 200;
densification grows the model) and the test-view renders. It tells hours from minutes, not to the minute, and
errs on the long side for a fresh model.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

from active.schedule import StagePlan
from arguments import FisherSettings

WARMUP = 5  # iterations not timed (first-call allocations)
MEASURE_UNTIL = 20  # iterations after the start (or resume) at which the estimate is made
REPORT_ABOVE_SECONDS = 30 * 60  # print the estimate only for runs longer than this
GAIN_FRACTION = 0.15  # one log-det gain on given blocks / one view's Fisher blocks (measured 0.11-0.18, README)
SUGGESTED_FACTORS = (2, 4, 8)  # `-r` downscale factors tried before a target width


@dataclass(frozen=True)
class SelectionWork:
    """How an active run selects: its selector's conservative oracle count of a step choosing k of m
    (`Selector.conservative_count`; None for no selector or one that calls no oracle) and the Fisher mode."""

    conservative_count: Callable[[int, int], int] | None = None
    streaming: bool = False

    @property
    def uses_oracle(self) -> bool:
        return self.conservative_count is not None


def fisher_blocks_per_step(plan: StagePlan, pool: int, work: SelectionWork) -> list[tuple[int, int]]:
    """(Fisher view blocks, conservative oracles) of each acquisition step of `plan` (zeros without the oracle)."""
    out = []
    for views, k in zip(plan.views_in_stage, plan.adds):
        if not work.uses_oracle:
            out.append((0, 0))
            continue
        m = pool - views
        oracles = work.conservative_count(m, k)
        candidates = oracles if work.streaming else min(m, oracles)
        out.append((views + candidates, oracles))
    return out


def projected_seconds(plan: StagePlan, pool: int, work: SelectionWork, iteration: int, step_seconds: float,
                      fisher_seconds: float) -> float:
    """Projected wall time of the rest of the run from `iteration` on (training + remaining selections)."""
    training = max(plan.total_iterations - iteration, 0) * step_seconds
    selection = 0.0
    for stage_end, (blocks, oracles) in zip(plan.stage_end, fisher_blocks_per_step(plan, pool, work)):
        if stage_end >= iteration:  # this acquisition step is still to come
            selection += (blocks + GAIN_FRACTION * oracles) * fisher_seconds
    return training + selection


def suggest_resolution(seconds: float, size: tuple[int, int], full_size: tuple[int, int],
                       limit: float = REPORT_ABOVE_SECONDS) -> tuple[int, int, float] | None:
    """(-r value, its width, projected seconds) of the largest image that brings `seconds` under `limit`.

    Tries the downscale factors first, then a target width from the square-root rule; None when even a
    16 px wide image would not do (the run is long for another reason: shorten it).
    """
    from scene.frames import target_size
    from scene.resolution_policy import MIN_IMAGE_SIDE

    pixels = size[0] * size[1]
    for factor in SUGGESTED_FACTORS:
        w, h = target_size(full_size[0], full_size[1], factor)
        projected = seconds * w * h / pixels
        if w < size[0] and projected <= limit and min(w, h) >= MIN_IMAGE_SIDE:
            return factor, w, projected
    width = math.floor(size[0] * math.sqrt(limit / seconds))
    while width in (1, *SUGGESTED_FACTORS):  # these would read as factors
        width -= 1
    w, h = target_size(full_size[0], full_size[1], width) if width > 0 else (0, 0)
    if min(w, h) < MIN_IMAGE_SIDE:
        return None
    return width, w, seconds * w * h / pixels


def format_duration(seconds: float) -> str:
    """'2 h 05 min' or '14 min' (at least 1 min)."""
    minutes = max(1, round(seconds / 60))
    return f"{minutes // 60} h {minutes % 60:02d} min" if minutes >= 60 else f"{minutes} min"


def estimate_message(plan: StagePlan, pool: int, work: SelectionWork, iteration: int, step_seconds: float,
                     fisher_seconds: float, size: tuple[int, int], full_size: tuple[int, int],
                     limit: float = REPORT_ABOVE_SECONDS) -> str | None:
    """The one-line estimate, or None when the projected rest of the run is within `limit`."""
    total = projected_seconds(plan, pool, work, iteration, step_seconds, fisher_seconds)
    if total <= limit:
        return None
    parts = f"{plan.total_iterations - iteration} iterations at {step_seconds:.2f} s/it"
    if work.uses_oracle:
        parts += f", Fisher blocks {fisher_seconds:.2f} s per view"
    line = (f"estimate: at the speed of the first iterations (usually the slowest) the rest of this run takes up to "
            f"about {format_duration(total)} ({parts}, {size[0]}x{size[1]} px)")
    suggestion = suggest_resolution(total, size, full_size, limit)
    if suggestion is None:
        return line + f"; even 16 px images would not bring it under {format_duration(limit)}: lower --iterations"
    value, width, projected = suggestion
    return line + f"; -r {value} ({width} px wide) would bring it to about {format_duration(projected)}"


class RunTimeEstimator:
    """Times this process's first training iterations and, once, returns the estimate line (or None).

    `fisher_probe` times one view's Fisher blocks on the current model (called once, at the estimate; None for
    selectors that do not call the oracle). The caller prints the line (e.g. `tqdm.write`).
    """

    def __init__(self, plan: StagePlan, pool: int, work: SelectionWork, size: tuple[int, int],
                 full_size: tuple[int, int], start_iteration: int, fisher_probe: Callable[[], float] | None):
        self.plan, self.pool, self.work = plan, pool, work
        self.size, self.full_size = size, full_size
        self.start_iteration = start_iteration
        self.fisher_probe = fisher_probe
        self._t0: float | None = None
        self.done = False

    def after_iteration(self, iteration: int) -> str | None:
        """Call after each training iteration; returns the estimate line once, when it is due and over the limit."""
        if self.done:
            return None
        elapsed = iteration - self.start_iteration
        if elapsed == WARMUP:
            self._t0 = time.perf_counter()
        if elapsed < MEASURE_UNTIL or self._t0 is None:
            return None
        self.done = True
        step = (time.perf_counter() - self._t0) / (elapsed - WARMUP)
        fisher = self.fisher_probe() if self.fisher_probe is not None and self.work.uses_oracle else 0.0
        return estimate_message(self.plan, self.pool, self.work, iteration, step, fisher, self.size, self.full_size)

    @classmethod
    def for_run(cls, run) -> "RunTimeEstimator":
        """The estimator of a `training.engine.Run` (config, scene, plan, selector, state), from its current iteration.

        The Fisher probe times `fisher_view_blocks` of the first view outside the training set on the model as it
        is at the estimate (the second of two calls, so a cold kernel cache's compile time is not counted).
        """
        from active.fisher import FISHER_PARAM_GROUPS, fisher_view_blocks
        from scene.resolution_policy import probe_image_size

        cfg, state, cameras = run.cfg, run.state, run.scene.train_cameras
        fisher = FisherSettings.from_active(cfg.active)
        uses_oracle = run.selector is not None and run.selector.uses_oracle
        work = SelectionWork(run.selector.conservative_count if uses_oracle else None, fisher.streaming)
        size = (cameras[0].width, cameras[0].height)
        full_size = probe_image_size(cfg.model.source_path, cfg.model.images) or size

        def fisher_probe() -> float:
            view = next((v for v in range(len(cameras)) if v not in state.train_views), 0)

            def blocks() -> None:
                fisher_view_blocks(state.gaussians, cameras[view], run.background, run.settings,
                                   param_groups=FISHER_PARAM_GROUPS[fisher.fisher_params])
            blocks()  # untimed: the first call compiles the Gram kernel when numba's cache is cold (~10 s)
            t0 = time.perf_counter()
            blocks()
            return time.perf_counter() - t0

        return cls(run.plan, len(cameras), work, size, full_size, state.iteration,
                   fisher_probe if uses_oracle else None)
