"""The information oracle: per-Gaussian block-diagonal Fisher information of a view.

Approximation (as in the LiTe-GS paper, following FisherRF/POP-GS):

* Parameters per Gaussian, in the raw (optimised) space: means (3), quats (4, unnormalised), log_scales (3),
  logit_opacities (1), SH DC colour (3): P = 14 (`param_groups="default"`); `"full_sh"` adds the rest coefficients.
* Pixel noise: i.i.d. Gaussian with standard deviation sigma on every pixel and colour channel, so the Fisher of a
  view is H_v = sigma^-2 J_v^T J_v with J_v the Jacobian of the rendered image w.r.t. the parameters.
* Only the per-Gaussian diagonal blocks of H_v are kept: [N, P, P].
* Fast path: a pixel depends on Gaussian i only through its 2D attributes a_i (means2d, conic, opacity, colour;
  A = 9), so H_v,i = sigma^-2 J_proj,i^T G_i J_proj,i with G_i = sum_p sum_c (dC_pc/da_i)(dC_pc/da_i)^T from
  `attribute_gram` and J_proj,i = da_i/dtheta_i from `projection_jacobian`. Its slow twin in the tests is the
  brute-force `torch.autograd.functional.jacobian` of the rendered image.
* Prior H_0 = sum over the training views of H_v plus a ridge (see `active.logdet.BlockInformation`).

Diagonal variant (FisherRF's approximation): `fisher_view_diagonals` gives diag(H_v) [N, P] from the same Gram and
projection Jacobian without forming the blocks (diag(J^T G J)_p = sum_ab J_ap G_ab J_bp), over every raw parameter
group; `DiagonalFisherOracle` serves it to selectors whose `oracle_kind` is "diagonal". `build_oracle(kind, ...)` is
the one entry point train.py calls, with the kind the selector declares.

`FisherOracle.build(...)` returns the one object the selectors call (`gain`, `commit`, `evaluated`: the
`GainOracle` protocol, by inheritance from `active.logdet.BlockGainOracle`); its `FisherViewBlocks` supplies the
blocks. Modes: "cached" keeps each candidate's blocks for the stage (an oracle is then a batched log-det update);
"streaming" keeps nothing and recomputes a view's blocks at every oracle (memory-lean). When the cache estimate
exceeds the memory budget, or the device runs out of memory while caching, cached mode falls back to streaming and
says so once.
"""
from __future__ import annotations

import logging
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Callable

import torch

from active.logdet import BlockGainOracle, BlockInformation
from gaussian_renderer import RasterSettings, attribute_gram, project_gaussians, projection_jacobian
from gaussian_renderer.fisher_partials import RAW_PARAMETER_GROUPS
from gaussian_renderer.sh import sh_to_colors
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel

log = logging.getLogger(__name__)

FISHER_PARAM_GROUPS = {  # --fisher_params: which raw parameters of a Gaussian form its Fisher block
    "default": ("means", "quats", "log_scales", "logit_opacities", "sh_dc"),
    "full_sh": ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest"),
}


def available_memory_bytes() -> int:
    """MemAvailable from /proc/meminfo (4 GiB when it cannot be read)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 4 << 30


def fisher_view_blocks(gaussians: GaussianModel, camera: Camera, background: torch.Tensor,
                       settings: RasterSettings, sigma: float = 1.0,
                       param_groups: tuple[str, ...] = FISHER_PARAM_GROUPS["default"]) -> torch.Tensor:
    """Per-Gaussian Fisher blocks of one view, H_v,i = sigma^-2 J_proj,i^T G_i J_proj,i.

    Returns:
        float64 blocks. [N, P, P]
    """
    jac, gram = _jacobian_and_gram(gaussians, camera, background, settings, param_groups)
    blocks = jac.transpose(1, 2) @ gram @ jac  # [N, P, P]
    return blocks / (sigma * sigma)


def fisher_view_diagonals(gaussians: GaussianModel, camera: Camera, background: torch.Tensor,
                          settings: RasterSettings, sigma: float = 1.0,
                          param_groups: tuple[str, ...] = RAW_PARAMETER_GROUPS) -> torch.Tensor:
    """The diagonals of `fisher_view_blocks`, sigma^-2 sum_pixels,channels (dI/dtheta_p)^2 per raw parameter, without
    forming the P x P blocks.

    Returns:
        float64 diagonals. [N, P]
    """
    jac, gram = _jacobian_and_gram(gaussians, camera, background, settings, param_groups)
    return torch.einsum("nap,nab,nbp->np", jac, gram, jac) / (sigma * sigma)


def parameter_columns(gaussians: GaussianModel, param_groups: tuple[str, ...]) -> dict[str, slice]:
    """The columns of each parameter group in a Fisher block or diagonal over `param_groups` (their widths from the
    model: means 3, quats 4, log_scales 3, logit_opacities 1, sh_dc 3, sh_rest 3((d+1)^2 - 1))."""
    columns, start = {}, 0
    for group in param_groups:
        width = gaussians.params[group].shape[1:].numel()
        columns[group] = slice(start, start + width)
        start += width
    return columns


def _jacobian_and_gram(gaussians: GaussianModel, camera: Camera, background: torch.Tensor, settings: RasterSettings,
                       param_groups: tuple[str, ...]) -> tuple[torch.Tensor, torch.Tensor]:
    """J_proj [N, A, P] and G [N, A, A] of one view, float64."""
    with torch.no_grad():
        proj = project_gaussians(gaussians.means, gaussians.unit_quats, gaussians.scales, camera.viewmat,
                                 camera.intrinsics, camera.width, camera.height)
        colors = sh_to_colors(gaussians.sh_coeffs, gaussians.means, camera.camera_center,
                              gaussians.active_sh_degree)
        gram = attribute_gram(proj.means2d, proj.conics, gaussians.opacities, colors, proj.depths, proj.radii,
                              camera.width, camera.height, background, settings)  # [N, A, A] float64
    params = gaussians.params
    jac = projection_jacobian(params["means"].detach(), params["quats"].detach(), params["log_scales"].detach(),
                              params["logit_opacities"].detach(), gaussians.sh_coeffs.detach(),
                              gaussians.active_sh_degree, camera.viewmat, camera.intrinsics, camera.width,
                              camera.height, param_groups=param_groups).double()  # [N, A, P]
    return jac, gram


@dataclass
class FisherViewBlocks:
    """Per-view Fisher blocks of one model: computed on demand, kept in an LRU cache (cached mode) or not (streaming).
    With `diagonal` set it supplies the blocks' diagonals instead ([N, P], `fisher_view_diagonals`)."""

    gaussians: GaussianModel
    cameras: list[Camera]
    background: torch.Tensor
    settings: RasterSettings
    sigma: float
    param_groups: tuple[str, ...]
    streaming: bool
    cache_bytes: int
    diagonal: bool = False  # diagonals [N, P] instead of blocks [N, P, P]
    views_computed: int = 0  # distinct views whose blocks were computed (candidates; prior views not counted)
    fisher_seconds: float = 0.0  # time spent computing blocks, prior included
    _cache: "OrderedDict[int, torch.Tensor]" = field(default_factory=OrderedDict)
    _seen: set = field(default_factory=set)

    def compute(self, view_id: int) -> torch.Tensor:
        """The blocks (or diagonals) of `cameras[view_id]`, timed, never cached. [N, P, P] or [N, P] float64"""
        t0 = time.perf_counter()
        kernel = fisher_view_diagonals if self.diagonal else fisher_view_blocks
        blocks = kernel(self.gaussians, self.cameras[view_id], self.background, self.settings,
                                    self.sigma, self.param_groups)
        self.fisher_seconds += time.perf_counter() - t0
        return blocks

    def use_streaming(self, reason: str) -> None:
        """Drop the cache and recompute from now on (logged once)."""
        if not self.streaming:
            log.warning("%s: switching the Fisher oracle to streaming mode", reason)
        self.streaming = True
        self._cache.clear()

    def __call__(self, view_id: int) -> torch.Tensor:
        """Blocks of one candidate view (from the cache, or computed). [N, P, P]"""
        if view_id in self._cache:
            self._cache.move_to_end(view_id)
            return self._cache[view_id]
        try:
            blocks = self.compute(view_id)
        except torch.cuda.OutOfMemoryError:
            if self.streaming or not self._cache:
                raise
            self.use_streaming(f"out of device memory with {len(self._cache)} views cached")
            blocks = self.compute(view_id)
        if view_id not in self._seen:
            self._seen.add(view_id)
            self.views_computed += 1
        if not self.streaming:
            self._cache[view_id] = blocks
            size = blocks.numel() * blocks.element_size()
            while len(self._cache) > 1 and len(self._cache) * size > self.cache_bytes:
                self._cache.popitem(last=False)
        return blocks


class _ViewStatistics:
    """What an oracle reports of its `FisherViewBlocks` (`self.blocks`): distinct candidate views computed and the
    seconds spent computing blocks or diagonals, the prior included."""

    blocks: "FisherViewBlocks"

    @property
    def views_computed(self) -> int:
        return self.blocks.views_computed

    @property
    def fisher_seconds(self) -> float:
        return self.blocks.fisher_seconds


class FisherOracle(_ViewStatistics, BlockGainOracle):
    """The counted Fisher gain oracle of one acquisition step: prior of the training views, blocks of the others."""

    def __init__(self, information: BlockInformation, view_blocks: FisherViewBlocks):
        super().__init__(information, view_blocks)
        self.blocks = view_blocks

    @classmethod
    def build(cls, gaussians: GaussianModel, cameras: list[Camera], train_views: list[int], background: torch.Tensor,
              settings: RasterSettings, *, sigma: float = 1.0, delta_rel: float = 1e-6, delta_abs: float = 1e-8,
              param_groups: str = "default", mode: str = "cached", cache_mb: int = 0) -> "FisherOracle":
        """Compute the prior from `train_views` and return an oracle over the other views of `cameras`."""
        source = FisherViewBlocks(gaussians, cameras, background, settings, sigma, FISHER_PARAM_GROUPS[param_groups],
                                  mode == "streaming", _cache_budget(cache_mb))
        prior = _prior(source, train_views, len(cameras))
        return cls(BlockInformation(prior, delta_rel=delta_rel, delta_abs=delta_abs), source)


class DiagonalGainOracle:
    """A counted `active.base.DiagonalOracle`: h = the prior diagonal plus the committed views' diagonals, and any
    candidate's diagonal from `view_diagonals(view_id)` [N, P] (which may cache or recompute). No ridge: a selector
    adds its own regulariser."""

    def __init__(self, information: torch.Tensor, view_diagonals: Callable[[int], torch.Tensor],
                 columns: dict[str, slice]):
        self.information = information.double()  # h [N, P]
        self.view_diagonals = view_diagonals
        self.columns = columns  # parameter group -> its columns of P
        self.evaluated = 0

    def diagonal(self, view_id: int) -> torch.Tensor:
        """diag(H_v) [N, P]: one oracle evaluation."""
        self.evaluated += 1
        return self.view_diagonals(view_id).double()

    def commit(self, view_id: int) -> None:
        """h <- h + diag(H_v) (not an oracle evaluation; in streaming mode the diagonal is recomputed)."""
        self.information = self.information + self.view_diagonals(view_id).double()

    def reset_counts(self) -> None:
        self.evaluated = 0


class DiagonalFisherOracle(_ViewStatistics, DiagonalGainOracle):
    """The counted diagonal Fisher oracle of one acquisition step, over every raw parameter group of the model."""

    def __init__(self, information: torch.Tensor, view_diagonals: FisherViewBlocks):
        super().__init__(information, view_diagonals,
                         parameter_columns(view_diagonals.gaussians, view_diagonals.param_groups))
        self.blocks = view_diagonals

    @classmethod
    def build(cls, gaussians: GaussianModel, cameras: list[Camera], train_views: list[int], background: torch.Tensor,
              settings: RasterSettings, *, sigma: float = 1.0, mode: str = "cached",
              cache_mb: int = 0) -> "DiagonalFisherOracle":
        """The prior diagonal of `train_views` and an oracle over the other views of `cameras`."""
        source = FisherViewBlocks(gaussians, cameras, background, settings, sigma, RAW_PARAMETER_GROUPS,
                                  mode == "streaming", _cache_budget(cache_mb), diagonal=True)
        return cls(_prior(source, train_views, len(cameras)), source)


def build_oracle(kind: str, gaussians: GaussianModel, cameras: list[Camera], train_views: list[int],
                 background: torch.Tensor, settings: RasterSettings, *, sigma: float = 1.0, delta_rel: float = 1e-6,
                 delta_abs: float = 1e-8, param_groups: str = "default", mode: str = "cached",
                 cache_mb: int = 0) -> FisherOracle | DiagonalFisherOracle:
    """The oracle of `kind` (a selector's `oracle_kind`): "logdet" -> `FisherOracle` (ridge and `param_groups`
    apply), "diagonal" -> `DiagonalFisherOracle` (every raw parameter group, no ridge)."""
    if kind == "logdet":
        return FisherOracle.build(gaussians, cameras, train_views, background, settings, sigma=sigma,
                                  delta_rel=delta_rel, delta_abs=delta_abs, param_groups=param_groups, mode=mode,
                                  cache_mb=cache_mb)
    if kind == "diagonal":
        return DiagonalFisherOracle.build(gaussians, cameras, train_views, background, settings, sigma=sigma,
                                          mode=mode, cache_mb=cache_mb)
    raise ValueError(f"unknown oracle kind {kind!r} (a selector's oracle_kind is 'logdet' or 'diagonal')")


def _cache_budget(cache_mb: int) -> int:
    """--fisher_cache_mb in bytes (0: a quarter of the available memory)."""
    return cache_mb * (1 << 20) if cache_mb > 0 else available_memory_bytes() // 4


def summed_views(compute: Callable[[int], torch.Tensor], views: list[int]) -> torch.Tensor:
    """The sum of `compute(v)` over `views` (fresh tensors, added in place): the training views' prior information,
    from blocks [N, P, P] or diagonals [N, P]."""
    total = None
    for v in views:
        blocks = compute(v)
        total = blocks if total is None else total.add_(blocks)
    return total


def _prior(source: FisherViewBlocks, train_views: list[int], num_views: int) -> torch.Tensor:
    """The sum of the training views' blocks (or diagonals); switches `source` to streaming when the candidates'
    cache would exceed its budget. [N, P, P] or [N, P]"""
    prior = summed_views(source.compute, train_views)
    num_candidates = num_views - len(train_views)
    estimate = num_candidates * prior.numel() * prior.element_size()
    if not source.streaming and estimate > source.cache_bytes:
        source.use_streaming(f"the Fisher cache would need {estimate / 2**20:.0f} MB for {num_candidates} "
                             f"candidate views (budget {source.cache_bytes / 2**20:.0f} MB, --fisher_cache_mb)")
    return prior
