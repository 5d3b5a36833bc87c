"""Where to capture next: rank candidate camera poses (no images) for a trained 3DGS model.

    model = load_model("output/lego")                                  # a train.py model directory
    model = load_model("splat.ply", captured="cameras.json")           # or any graphdeco-layout PLY + its views
    pool = make_pool(model, candidate_cameras("orbit:100", model))     # or "unused", or a pose file
    rec = recommend(model, pool, build_selector("lite_gs", eps=0.1), k=4)
    write_outputs(rec, model, "output/lego/next")                      # recommendations.json, transforms.json, ...

The prior H0 is the Fisher information of the captured views (a model directory's recorded training views; for a
bare PLY the `captured` cameras). The selection itself is `active.acquisition.run_selection`, the function train.py's
acquisition stage calls: the same model, prior, candidates and seed give the same picks from either entry point.
Candidates that see no Gaussian are left out of the selection (gain 0) and come only after every visible one.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch

from active.acquisition import Acquisition, run_selection
from active.base import Selector, StepChoice
from active.fisher import FISHER_PARAM_GROUPS
from active.memory_budget import (NO_FISHER_PASS, FisherWork, block_size, device_available_bytes, fit_fisher_memory,
                                  largest_pixels, pass_label, selection_work, smaller_passes)
from arguments import FisherSettings, ModelConfig, PipelineConfig
from gaussian_renderer import RasterSettings, project_gaussians
from recommender.advice import selection_advice
from recommender.candidates import generate, parse_spec
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from scene.pose_files import read_pose_file, scaled_camera
from scene.resolution_policy import CUDA_MAX_WIDTH
from scene.trained import load_trained, raster_settings, recorded_train_views
from utils.errors import UserError

log = logging.getLogger(__name__)


@dataclass
class LoadedModel:
    """A model to recommend for: Gaussians, the captured (prior) cameras and how it renders."""

    path: Path
    kind: str  # "model_dir" (train.py) or "ply"
    gaussians: GaussianModel
    captured: list[Camera]  # the prior's cameras
    background: torch.Tensor  # [3]
    settings: RasterSettings
    fisher: FisherSettings
    iteration: int | None = None  # model directory: the saved iteration used
    dataset_cameras: list[Camera] | None = None  # model directory: every training camera (view id = index)
    train_ids: list[int] = field(default_factory=list)  # model directory: the recorded training views


def load_model(model: str | Path, captured: str | Path | None = None, *, iteration: int = -1,
               device: str = "cpu", white_background: bool = False) -> LoadedModel:
    """A train.py model directory (prior: its recorded training views at `iteration`, cameras from its
    cameras.json, no image read) or a graphdeco-layout PLY with `captured` (a pose file or COLMAP model)."""
    model = Path(model)
    if model.is_dir():
        return _load_model_dir(model, iteration, device)
    if not model.is_file():
        raise UserError(f"model {model} does not exist: pass a train.py model directory or a 3DGS .ply file")
    if captured is None:
        raise UserError(f"{model} is a bare PLY: pass --captured with the views already taken (a 3DGS cameras.json, "
                        "a transforms.json or a COLMAP model) to form the prior")
    gaussians = GaussianModel.load_ply(model, device=device)
    cameras = [c.to(device) for c in read_pose_file(captured)]
    return LoadedModel(model, "ply", gaussians, cameras,
                       torch.full((3,), 1.0 if white_background else 0.0, device=device),
                       raster_settings(PipelineConfig()), FisherSettings())


def _load_model_dir(path: Path, iteration: int, device: str) -> LoadedModel:
    trained = load_trained(path, iteration, device=device, cameras_only=True, sh_degree_as_trained=True)
    cameras, active = trained.train_cameras, trained.record.get("active", {})
    train_ids = recorded_train_views(path, trained.iteration, len(cameras), active.get("method", ""))
    fisher = FisherSettings.from_active(active)
    return LoadedModel(path, "model_dir", trained.gaussians, [cameras[v] for v in train_ids], trained.background,
                       trained.settings, fisher, trained.iteration, cameras, list(train_ids))


def candidate_cameras(spec: str, model: LoadedModel, *, elevation: tuple[float, float] | None = None,
                      radius: float | None = None, size: tuple[int, int] | None = None,
                      fov_deg: float | None = None) -> list[Camera] | None:
    """The candidates of `--candidates`: "unused" (None: a model directory's training views not trained on),
    "orbit:N" / "hemisphere:N" around the captured views, or a pose file (cameras.json, transforms.json,
    camera_path.json, COLMAP model). `size` (width, height) and `fov_deg` (horizontal) override the intrinsics
    taken from the first captured camera."""
    template = model.captured[0]
    if size is not None or fov_deg is not None:
        w, h = size or (template.width, template.height)
        if min(w, h) <= 0 or (fov_deg is not None and not 0 < fov_deg < 180):
            raise UserError(f"--size needs positive sides and --fov lie in (0, 180) degrees; got {size}, {fov_deg}")
        fx = 0.5 * w / math.tan(math.radians(fov_deg) / 2) if fov_deg is not None else template.fx * w / template.width
        template = Camera(0, "template", template.viewmat, fx, fx, w / 2, h / 2, w, h)
    if spec == "unused":
        if model.kind != "model_dir":
            raise UserError("--candidates unused needs a train.py model directory (a bare PLY has no dataset views)")
        return None
    generated = parse_spec(spec)
    if generated is not None:
        return generate(*generated, model.captured, elevation=elevation, radius=radius, template=template)
    cameras = read_pose_file(spec, default_size=(template.width, template.height))
    if size is not None:
        cameras = [scaled_camera(c, size[0]) for c in cameras]
    return cameras


@dataclass
class Pool:
    """The cameras of one selection: prior views and candidates, as indices into `cameras`."""

    cameras: list[Camera]
    train_ids: list[int]
    candidate_ids: list[int]
    names: dict[int, str]  # candidate id -> a name (file frame name or generated name)
    source_index: dict[int, int]  # candidate id -> index in the candidate list (model dir "unused": the view id)


def make_pool(model: LoadedModel, candidates: list[Camera] | None, width: int | None = None) -> Pool:
    """The selection pool, every camera at `width` px (None: as given, but at most the device policy's cap: the CPU
    training width `--cpu_max_width` default, 1600 px on CUDA). `candidates` None: the model directory's unused
    training views, with train.py's view ids."""
    if candidates is None:
        cameras, train_ids = list(model.dataset_cameras), list(model.train_ids)
        candidate_ids = [v for v in range(len(cameras)) if v not in set(train_ids)]
        if not candidate_ids:
            raise UserError(f"{model.path}: every training view was trained on; no unused view is left to rank")
        index = {v: v for v in candidate_ids}
    else:
        if not candidates:
            raise UserError("no candidate cameras given")
        cameras = list(model.captured) + list(candidates)
        train_ids = list(range(len(model.captured)))
        candidate_ids = list(range(len(model.captured), len(cameras)))
        index = {v: v - len(model.captured) for v in candidate_ids}
    device = model.gaussians.device
    cap = width or (ModelConfig().cpu_max_width if device.type == "cpu" else CUDA_MAX_WIDTH)
    cameras = [scaled_camera(c, width if width else min(c.width, cap)).to(device) for c in cameras]
    return Pool(cameras, train_ids, candidate_ids, {v: cameras[v].image_name for v in candidate_ids}, index)


def fit_memory(model: LoadedModel, pool: Pool, selector: Selector, previews: bool) -> FisherSettings:
    """`model.fisher` for the selection over `pool`, its Fisher pass and (with `previews`) the previews' uncertainty
    pass checked against the available memory before either starts (`active.memory_budget.fit_fisher_memory`: the
    cache lowered, or one `UserError` line naming the estimate and recommend.py's flags that help)."""
    selector = step_selector(model, pool, selector).selector
    fisher, gaussians, pixels = model.fisher, model.gaussians, largest_pixels(pool.cameras)
    width, available = max(c.width for c in pool.cameras), device_available_bytes(gaussians.device)
    work = selection_work(selector.oracle_kind, gaussians, pixels, len(pool.candidate_ids), fisher.fisher_params)
    if work is not None and selector.uses_oracle:
        remedies = smaller_passes(work, gaussians, width, "--width")
        fisher = fit_fisher_memory(work, fisher, pass_label(f"{selector.name} Fisher pass", work, fisher.fisher_params),
                                   remedies, NO_FISHER_PASS, available)
    if previews:
        work = FisherWork("uncertainty", gaussians.num_gaussians,
                          block_size(gaussians, FISHER_PARAM_GROUPS[fisher.fisher_params]), pixels)
        remedies = {"--no_previews": None} | smaller_passes(work, gaussians, width, "--width")
        fit_fisher_memory(work, fisher, pass_label("previews' uncertainty", work, fisher.fisher_params), remedies,
                          "pass --no_previews", available)
    return fisher


def step_selector(model: LoadedModel, pool: Pool, selector: Selector) -> StepChoice:
    """The selector that runs the selection and its rule line: `selector.for_step` for the pool's captured views and
    the model's training length (itself and no line, but for `auto`)."""
    return selector.for_step(len(pool.train_ids), model.iteration)


@torch.no_grad()
def visible_counts(gaussians: GaussianModel, cameras: list[Camera]) -> list[int]:
    """How many Gaussians each camera's image receives (projected radius > 0)."""
    counts = []
    for c in cameras:
        proj = project_gaussians(gaussians.means, gaussians.unit_quats, gaussians.scales, c.viewmat, c.intrinsics,
                                 c.width, c.height)
        counts.append(int((proj.radii > 0).sum()))
    return counts


@dataclass
class Recommendation:
    """The result of `recommend`."""

    pool: Pool
    selector: Selector  # as asked for
    k: int  # requested
    picks: list[int]  # candidate ids (pool indices), in pick order
    pick_gains: list[float]
    acquisition: Acquisition | None  # None when no candidate sees a Gaussian
    visible: dict[int, int]  # candidate id -> Gaussians it sees
    seed: int
    notes: list[str]
    seconds: float  # visibility check + selection
    used: Selector  # the selector that ran (`step_selector`; differs from `selector` for auto)
    rule: str | None  # the line saying why `used` ran (a selector with a rule, auto), else None


def recommend(model: LoadedModel, pool: Pool, selector: Selector, k: int, *, seed: int = 0,
              progress: bool = False) -> Recommendation:
    """Rank `pool`'s candidates with `selector` and return the first `k` picks (all of them when k >= M).

    Candidates seeing no Gaussian are warned about, given gain 0 and appended after the visible picks."""
    if k <= 0:
        raise UserError(f"-k must be positive, got {k}")
    t0 = time.perf_counter()
    notes = []
    m = len(pool.candidate_ids)
    if k > m:
        notes.append(f"note: K={k} exceeds the {m} candidates: taking all {m}")
        k_taken = m
    else:
        k_taken = k
    counts = visible_counts(model.gaussians, [pool.cameras[v] for v in pool.candidate_ids])
    visible = dict(zip(pool.candidate_ids, counts))
    seen = [v for v in pool.candidate_ids if visible[v] > 0]
    unseen = [v for v in pool.candidate_ids if visible[v] == 0]
    if unseen:
        names = ", ".join(pool.names[v] for v in unseen[:5]) + (" ..." if len(unseen) > 5 else "")
        notes.append(f"warning: {len(unseen)} candidate(s) see no Gaussian (behind or inside the scene): {names}; "
                     "gain 0, never picked before a visible one")
    choice = step_selector(model, pool, selector)
    used, rule = choice.selector, choice.rule
    picks, gains, step = [], [], None
    if seen:
        step = run_selection(used, model.gaussians, pool.cameras, pool.train_ids, seen, min(k_taken, len(seen)),
                             model.background, model.settings, seed=seed, stage=0, fisher=model.fisher,
                             progress=progress)
        picks, gains = list(step.selection.ids), list(step.selection.gains)
        if step.selection.note is not None:
            notes.append(step.selection.note)
    for v in unseen[:k_taken - len(picks)]:
        picks.append(v)
        gains.append(0.0)
    advice = rule if rule is not None else selection_advice(used, len(pool.train_ids))
    if advice is not None:
        notes.append(advice)
    for note in notes:
        log.warning(note)
    return Recommendation(pool, selector, k, picks, gains, step, visible, seed, notes, time.perf_counter() - t0,
                          used, rule)
