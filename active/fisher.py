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
group; `DiagonalFisherOracle` serves it to selectors whose `oracle_kind` is "diagonal". `fisher_view_diagonals_reference`
reproduces what FisherRF's modified rasterizer computes instead (docs/deviations.md): for geometry and opacity the
square of the channel-summed pixel partial, and the exp / sigmoid derivative of log_scales / logit_opacities applied
once after squaring; the oracle kind "diagonal_reference" serves it. `build_oracle(kind, ...)` is the one entry point
train.py calls, with the kind the selector declares.

`FisherOracle.build(...)` returns the one object the selectors call (`gain`, `commit`, `evaluated`: the
`GainOracle` protocol, by inheritance from `active.logdet.BlockGainOracle`); its `FisherViewBlocks` supplies the
candidates' information as `fisher_view_factors`: only the Gaussians the view sees (a non-zero attribute Gram), each
block as the factor R_i = sigma^-1 J_proj,i^T C_i [P, A] (C_i C_i^T = G_i+, the PSD part of the attribute Gram, by a
pivoted Cholesky of the equilibrated Gram in numba, made once per view; `active.logdet.gram_root_factors`), so
H_v,i = R_i R_i^T and a gain or commit touches the visible blocks only. Factors are made lower trapezoidal (Householder
LQ) and stored packed, 90 of 126 entries, as float32 (`FACTOR_STORAGE`; arithmetic stays float64). Modes: "cached"
keeps each candidate's factors for the stage (an oracle is then a log-det update); "streaming" keeps nothing and recomputes a
view's factors at every oracle (memory-lean). When the cache estimate (the training views' visible counts times the
candidates) exceeds the memory budget, the cache keeps the views it can, evicting the one with the lowest selector
hint first (a lazy greedy's upper bound; least recently used without hints), and says so once. When one view alone
does not fit the budget, or the device runs out of memory while caching, cached mode falls back to streaming and
says so once.
"""
from __future__ import annotations

import logging
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Callable, Iterable

import torch

from active.cover_oracle import CoverageOracle
from active.gain_weights import gain_weights
from active.pool_cover_oracle import PoolCoverageOracle
from active.gated_oracle import CoverGatedOracle
from active.logdet import BlockGainOracle, BlockInformation, ViewFactors, check_finite, gram_root_factors
from active.probes import with_probes
from active.variance_oracle import RenderVarianceInformation
from arguments import FisherSettings
from gaussian_renderer import (RasterSettings, attribute_gram, project_and_shade, projection_jacobian,
                               seen_attribute_gram)
from gaussian_renderer.fisher_partials import RAW_PARAMETER_GROUPS
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from utils.errors import UserError
from utils.system_memory import available_memory_bytes

log = logging.getLogger(__name__)

FISHER_PARAM_GROUPS = {  # --fisher_params: which raw parameters of a Gaussian form its Fisher block
    "default": ("means", "quats", "log_scales", "logit_opacities", "sh_dc"),
    "full_sh": ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest"),
}
ORACLE_KINDS = ("logdet", "logdet_opacity", "logdet_area", "logdet_probes", "logdet_cover", "render_variance",
                "diagonal", "diagonal_reference", "coverage", "pool_coverage", "pool_coverage_pixels")  # build_oracle's
FACTOR_STORAGE = torch.float32  # dtype of cached view factors (the float32 accuracy test: tests/test_view_factors.py)


def fisher_view_blocks(gaussians: GaussianModel, camera: Camera, background: torch.Tensor,
                       settings: RasterSettings, sigma: float = FisherSettings.sigma,
                       param_groups: tuple[str, ...] = FISHER_PARAM_GROUPS[FisherSettings.fisher_params]
                       ) -> torch.Tensor:
    """Per-Gaussian Fisher blocks of one view, H_v,i = sigma^-2 J_proj,i^T G_i J_proj,i.

    Returns:
        float64 blocks. [N, P, P]
    """
    jac, gram = _jacobian_and_gram(gaussians, camera, background, settings, param_groups)
    blocks = jac.transpose(1, 2) @ gram @ jac  # [N, P, P]
    return blocks / (sigma * sigma)


def fisher_view_factors(gaussians: GaussianModel, camera: Camera, background: torch.Tensor,
                        settings: RasterSettings, sigma: float = FisherSettings.sigma,
                        param_groups: tuple[str, ...] = FISHER_PARAM_GROUPS[FisherSettings.fisher_params],
                        backend: str = "auto", dtype: torch.dtype = torch.float64) -> ViewFactors:
    """`fisher_view_blocks` over the Gaussians the view sees, as PSD factors: H_v,i = R_i R_i^T with
    R_i = sigma^-1 J_proj,i^T C_i, C_i C_i^T the PSD part of the attribute Gram G_i (`active.logdet.gram_root_factors`:
    pivoted Cholesky in numba with `backend` "auto"/"compiled", the eigen-clamping twin with "torch"). The projection
    Jacobian is computed for the visible Gaussians only.

    Returns:
        indices [n] of the Gaussians with a non-zero Gram, factors [n, P, A] (lower trapezoidal, packed) in `dtype`
        (computed in float64).
    """
    with torch.no_grad():
        for group in param_groups:  # the dense blocks of every Gaussian would carry a NaN parameter: refuse it too
            check_finite(gaussians.params[group], "view", gaussians.num_gaussians)
        indices, gram = _attribute_gram(gaussians, camera, background, settings, seen_only=True)  # [n], [n, A, A]
        check_finite(gram, "view", gaussians.num_gaussians)
        jac = _projection_jacobian(gaussians, camera, param_groups, settings.backend, indices)  # [n, A, P]
        check_finite(jac, "view", gaussians.num_gaussians)
        packed = gram_root_factors(gram, jac, sigma, backend, dtype)  # R [n, m], lower trapezoidal [P, A] packed
    return ViewFactors(indices, packed, jac.shape[2], jac.shape[1], gaussians.num_gaussians)


def fisher_view_diagonals(gaussians: GaussianModel, camera: Camera, background: torch.Tensor,
                          settings: RasterSettings, sigma: float = FisherSettings.sigma,
                          param_groups: tuple[str, ...] = RAW_PARAMETER_GROUPS) -> torch.Tensor:
    """The diagonals of `fisher_view_blocks`, sigma^-2 sum_pixels,channels (dI/dtheta_p)^2 per raw parameter, without
    forming the P x P blocks.

    Returns:
        float64 diagonals. [N, P]
    """
    with torch.no_grad():
        indices, gram = _attribute_gram(gaussians, camera, background, settings, seen_only=True)  # [n], [n, A, A]
        jac = _projection_jacobian(gaussians, camera, param_groups, settings.backend, indices)  # [n, A, P]
        diag = torch.zeros(gaussians.num_gaussians, jac.shape[2], dtype=torch.float64, device=gram.device)  # [N, P]
        diag[indices] = ((gram @ jac) * jac).sum(1)  # J_p^T G J_p per column p; unseen rows stay 0
    return diag / (sigma * sigma)


REFERENCE_DIAGONAL_GROUPS = ("means", "log_scales", "logit_opacities", "sh_dc", "sh_rest")  # FisherRF: no rotation
DIAGONAL_GROUPS = {"diagonal": RAW_PARAMETER_GROUPS, "diagonal_reference": REFERENCE_DIAGONAL_GROUPS}  # per oracle kind


def fisher_view_diagonals_reference(gaussians: GaussianModel, camera: Camera, background: torch.Tensor,
                                    settings: RasterSettings, sigma: float = FisherSettings.sigma,
                                    param_groups: tuple[str, ...] = REFERENCE_DIAGONAL_GROUPS) -> torch.Tensor:
    """The diagonal FisherRF's code accumulates (`diff/cuda_rasterizer/backward.cu`, `renderCUDAFused` with
    `atomicAddSquare`, pixel gradient 1 on every channel, then PyTorch's activation backward), per raw parameter:

    * geometry (means, log_scales, logit_opacities): sigma^-2 sum_pixels (sum_channels dI_pc/dtheta)^2, the square
      of the channel-summed partial, with the activation derivative f'(theta) (exp for log_scales, sigmoid for
      logit_opacities) applied once after squaring: f' sum_p (sum_c dI_pc/da)^2 instead of f'^2 (...);
    * colour (sh_dc, sh_rest): as `fisher_view_diagonals` (a coefficient reaches one channel, so both agree).

    The channel-summed partials are those of a one-channel render whose colour is the sum of the three (compositing
    is linear in colour). Rotation is not reproduced (FisherRF scores without it).

    Returns:
        float64 diagonals. [N, P]
    Raises:
        UserError: "quats" in `param_groups`.
    """
    if "quats" in param_groups:
        raise UserError("the reference (FisherRF-code) Fisher diagonal has no rotation columns; drop quats from "
                        "--fisherrf_params")
    jac, gram = _jacobian_and_gram(gaussians, camera, background, settings, param_groups)  # [N, A, P], [N, A, A]
    exact = torch.einsum("nap,nab,nbp->np", jac, gram, jac)  # per-channel squares [N, P]
    with torch.no_grad():  # [N, 7, 7] of the channel-summed image
        gram_sum = _attribute_gram(gaussians, camera, background, settings, sum_channels=True)
    lift = torch.zeros(9, 7, dtype=torch.float64, device=gram_sum.device)  # channel-summed partials, 7 -> 9 attributes
    lift[:6, :6] = torch.eye(6, dtype=torch.float64, device=gram_sum.device)
    lift[6:, 6] = 1.0  # d(sum_c I_c)/d colour_c' = the blending weight, for every c'
    summed = torch.einsum("nap,nab,nbp->np", jac, lift @ gram_sum @ lift.T, jac)  # [N, P]
    columns = parameter_columns(gaussians, param_groups)
    diag = summed.clone()
    for group in ("sh_dc", "sh_rest"):
        if group in columns:
            diag[:, columns[group]] = exact[:, columns[group]]
    params = gaussians.params
    if "log_scales" in columns:  # exp' = exp: f'^2 S -> f' S
        diag[:, columns["log_scales"]] /= params["log_scales"].detach().double().exp().clamp_min(1e-300)
    if "logit_opacities" in columns:  # sigmoid' = o (1 - o)
        o = torch.sigmoid(params["logit_opacities"].detach().double()).reshape(-1, 1)
        diag[:, columns["logit_opacities"]] /= (o * (1 - o)).clamp_min(1e-300)
    return diag / (sigma * sigma)


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
        gram = _attribute_gram(gaussians, camera, background, settings)
    return _projection_jacobian(gaussians, camera, param_groups, settings.backend), gram


def _attribute_gram(gaussians: GaussianModel, camera: Camera, background: torch.Tensor, settings: RasterSettings,
                    seen_only: bool = False,
                    sum_channels: bool = False) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """G [N, A, A] of one view (render + per-Gaussian Gram), float64; with `seen_only`, (indices [n], G [n, A, A]) of
    the Gaussians the view sees (`seen_attribute_gram`); with `sum_channels`, of the one-channel image whose colour
    is the sum of the three (A = 7)."""
    params = {k: v.detach() for k, v in gaussians.params.items()}
    # only the projected Gaussians take part (colours, binning, the kernels' per-Gaussian buffers): [n] ids, in order,
    # so the depth sort's ties fall as over all of them and the Grams are the same
    proj, ids, colors = project_and_shade(params["means"], params["quats"], params["log_scales"], params["sh_dc"],
                                          params["sh_rest"], gaussians.active_sh_degree, camera.viewmat,
                                          camera.intrinsics, camera.width, camera.height, settings)
    if sum_channels:
        colors, background = colors.sum(1, keepdim=True), background.sum().reshape(1)
    gram_of = seen_attribute_gram if seen_only else attribute_gram
    out = gram_of(proj.means2d[ids], proj.conics[ids], torch.sigmoid(params["logit_opacities"][ids]), colors,
                  proj.depths[ids], proj.radii[ids], camera.width, camera.height, background, settings)
    if seen_only:
        return ids[out[0]], out[1]
    full = out.new_zeros(gaussians.num_gaussians, *out.shape[1:])  # [N, A, A]
    full[ids] = out
    return full


def _sh_coeffs(gaussians: GaussianModel, ids: torch.Tensor) -> torch.Tensor:
    """`gaussians.sh_coeffs[ids]` without concatenating every Gaussian's coefficients first. [n, K, 3]"""
    return torch.cat([gaussians.params["sh_dc"][ids], gaussians.params["sh_rest"][ids]], dim=1)


def _projection_jacobian(gaussians: GaussianModel, camera: Camera, param_groups: tuple[str, ...], backend: str,
                         indices: torch.Tensor | None = None) -> torch.Tensor:
    """J_proj [N, A, P] float64 of every Gaussian, or [n, A, P] of `indices` (Gaussians are independent), by the
    rasterizer `backend`'s path (`projection_jacobian`: the numba kernel on CPU with "auto"/"compiled")."""
    pick = (lambda t: t.detach()) if indices is None else (lambda t: t.detach()[indices])
    params = gaussians.params
    sh = gaussians.sh_coeffs.detach() if indices is None else _sh_coeffs(gaussians, indices).detach()
    return projection_jacobian(pick(params["means"]), pick(params["quats"]), pick(params["log_scales"]),
                               pick(params["logit_opacities"]), sh, gaussians.active_sh_degree,
                               camera.viewmat, camera.intrinsics, camera.width, camera.height,
                               param_groups=param_groups, backend=backend).double()


EVICTION_POLICIES = ("priority", "lru")  # FisherViewBlocks.eviction


def eviction_victim(cached: Iterable[int], keep: int, eviction: str, priority: dict[int, float]) -> int:
    """The view `eviction` drops from `cached` (view ids, least recently used first), never `keep`: the lowest hinted
    priority (unhinted views count as -inf; the least recently used among equals) under "priority" once any hint
    came, else the least recently used. `FisherViewBlocks` evicts with it; benchmarks/cache_replay.py replays it."""
    others = (v for v in cached if v != keep)
    if eviction == "lru" or not priority:
        return next(others)
    return min(others, key=lambda v: priority.get(v, -float("inf")))  # first minimum


@dataclass
class FisherViewBlocks:
    """Per-view Fisher information of one model: computed on demand, kept in a cache bounded in bytes (cached mode)
    or not (streaming). Candidates come as `ViewFactors` stored in `FACTOR_STORAGE`; with `diagonal` set it supplies
    the blocks' diagonals instead ([N, P], `fisher_view_diagonals`).

    `fisher` gives sigma, the parameter groups of the factors (the diagonals' are every raw group, or FisherRF's with
    `reference`), the starting mode and the cache budget `cache_bytes` (`--fisher_cache_mb`).

    Eviction when the cached views exceed `cache_bytes` (`eviction`): "priority" (default) evicts the cached view
    with the lowest priority first, the priorities being the selector's hints (`set_priority(view, bound)`: a lazy
    greedy's cached upper bound, -inf once the view is chosen; a view never hinted counts as -inf), ties and a stage
    without any hint in least-recently-used order; "lru" ignores the hints. The view just requested (the lazy
    greedy's heap top) is never evicted for its own sake.

    With `requests` a list, every candidate request and hint is appended to it in order, ("get", view, bytes) and
    ("hint", view, bound), so that other eviction policies can be replayed on the same run
    (`benchmarks/cache_replay.py`); the requests do not depend on the cache, only which of them recompute.
    """

    gaussians: GaussianModel
    cameras: list[Camera]
    background: torch.Tensor
    settings: RasterSettings
    fisher: FisherSettings
    diagonal: bool = False  # diagonals [N, P] instead of factors
    reference: bool = False  # with `diagonal`: FisherRF's code's diagonals (`fisher_view_diagonals_reference`)
    eviction: str = "priority"  # "priority" (the selector's hints, LRU without them) or "lru"
    param_groups: tuple[str, ...] = field(init=False)  # the columns of P
    streaming: bool = field(init=False)  # from `fisher`; switched on by `use_streaming`
    cache_bytes: int = field(init=False)  # the cache budget (`cache_budget` of --fisher_cache_mb)
    views_computed: int = 0  # distinct views whose blocks were computed (candidates; prior views not counted)
    fisher_passes: int = 0  # candidate views' blocks computed, recomputations included (cache misses)
    fisher_seconds: float = 0.0  # time spent computing blocks, prior included
    _cache: "OrderedDict[int, ViewFactors | torch.Tensor]" = field(default_factory=OrderedDict)  # oldest use first
    _cached_bytes: int = 0
    _seen: set = field(default_factory=set)
    _priority: dict = field(default_factory=dict)  # view id -> the selector's last hint
    requests: list | None = None  # when a list: the log of requests and hints (see above)

    def __post_init__(self) -> None:
        if self.eviction not in EVICTION_POLICIES:
            raise ValueError(f"eviction must be one of {EVICTION_POLICIES}, got {self.eviction!r}")
        self.param_groups = (DIAGONAL_GROUPS["diagonal_reference" if self.reference else "diagonal"] if self.diagonal
                             else FISHER_PARAM_GROUPS[self.fisher.fisher_params])
        self.streaming = self.fisher.streaming
        self.cache_bytes = cache_budget(self.fisher.fisher_cache_mb)

    def set_priority(self, view_id: int, bound: float) -> None:
        """A selector's hint: how likely `view_id` is to be asked for again (a lazy greedy's upper bound on its gain;
        -inf: never again). Under "priority" eviction the lowest is evicted first."""
        self._priority[view_id] = float(bound)
        if self.requests is not None:
            self.requests.append(("hint", view_id, float(bound)))

    @property
    def cached_bytes(self) -> int:
        """Bytes the cache holds now (0 in streaming mode)."""
        return self._cached_bytes

    def compute(self, view_id: int, dtype: torch.dtype = torch.float64) -> ViewFactors | torch.Tensor:
        """The factors (in `dtype`, computed in float64) or diagonals [N, P] of `cameras[view_id]`, timed, never
        cached."""
        t0 = time.perf_counter()
        args = (self.gaussians, self.cameras[view_id], self.background, self.settings, self.fisher.sigma,
                self.param_groups)
        if self.diagonal:
            blocks = (fisher_view_diagonals_reference if self.reference else fisher_view_diagonals)(*args)
        else:
            blocks = fisher_view_factors(*args, dtype=dtype)
        self.fisher_seconds += time.perf_counter() - t0
        return blocks

    @staticmethod
    def stored(blocks: ViewFactors | torch.Tensor) -> ViewFactors | torch.Tensor:
        """What the cache would keep of a view computed in float64 (the training views, for the cache-size estimate):
        factors in `FACTOR_STORAGE`, diagonals unchanged. Candidates are computed in it directly (`__call__`), in both
        modes, so both give the same gains."""
        return blocks.stored_as(FACTOR_STORAGE) if isinstance(blocks, ViewFactors) else blocks

    def use_streaming(self, reason: str) -> None:
        """Drop the cache and recompute from now on (logged once)."""
        if not self.streaming:
            log.warning("%s: switching the Fisher oracle to streaming mode", reason)
        self.streaming = True
        self._cache.clear()
        self._cached_bytes = 0

    def __call__(self, view_id: int) -> ViewFactors | torch.Tensor:
        """The information of one candidate view (from the cache, or computed)."""
        blocks = self._fetch(view_id)
        if self.requests is not None:
            self.requests.append(("get", view_id, nbytes(blocks)))
        return blocks

    def _fetch(self, view_id: int) -> ViewFactors | torch.Tensor:
        """`__call__` without the request log."""
        if view_id in self._cache:
            self._cache.move_to_end(view_id)
            return self._cache[view_id]
        try:
            blocks = self.compute(view_id, FACTOR_STORAGE)  # what the cache keeps, written directly
        except torch.cuda.OutOfMemoryError:
            if self.streaming or not self._cache:
                raise
            self.use_streaming(f"out of device memory with {len(self._cache)} views cached")
            blocks = self.compute(view_id, FACTOR_STORAGE)  # what the cache keeps, written directly
        self.fisher_passes += 1
        if view_id not in self._seen:
            self._seen.add(view_id)
            self.views_computed += 1
        if not self.streaming:
            size = nbytes(blocks)
            if size > self.cache_bytes:
                self.use_streaming(f"one view's Fisher information needs {size / 2**20:.1f} MB, more than the "
                                   f"cache budget of {self.cache_bytes / 2**20:.1f} MB (--fisher_cache_mb)")
                return blocks
            self._cache[view_id] = blocks
            self._cached_bytes += size
            while len(self._cache) > 1 and self._cached_bytes > self.cache_bytes:
                victim = eviction_victim(self._cache, view_id, self.eviction, self._priority)
                self._cached_bytes -= nbytes(self._cache.pop(victim))
        return blocks


def nbytes(blocks: ViewFactors | torch.Tensor) -> int:
    """Bytes held by a view's factors or diagonals."""
    return blocks.nbytes if isinstance(blocks, ViewFactors) else blocks.numel() * blocks.element_size()


class _ViewStatistics:
    """What an oracle reports of its `FisherViewBlocks` (`self.blocks`): distinct candidate views computed and the
    seconds spent computing blocks or diagonals, the prior included."""

    blocks: "FisherViewBlocks"

    @property
    def views_computed(self) -> int:
        return self.blocks.views_computed

    @property
    def fisher_passes(self) -> int:
        return self.blocks.fisher_passes

    @property
    def fisher_seconds(self) -> float:
        return self.blocks.fisher_seconds

    def set_priority(self, view_id: int, bound: float) -> None:
        """A selector's optional hint for the cache (`FisherViewBlocks.set_priority`): the view's current upper bound,
        -inf once chosen. Selections do not depend on it."""
        self.blocks.set_priority(view_id, bound)


class FisherOracle(_ViewStatistics, BlockGainOracle):
    """The counted Fisher gain oracle of one acquisition step: prior of the training views, blocks of the others."""

    def __init__(self, information: BlockInformation, view_blocks: FisherViewBlocks,
                 weights: torch.Tensor | None = None):
        super().__init__(information, view_blocks, weights)
        self.blocks = view_blocks

    @classmethod
    def build(cls, gaussians: GaussianModel, cameras: list[Camera], train_views: list[int], background: torch.Tensor,
              settings: RasterSettings, *, fisher: FisherSettings = FisherSettings(),
              gain_weight: str = "none") -> "FisherOracle":
        """Compute the prior from `train_views` and return an oracle over the other views of `cameras` (all of
        `fisher` applies); with `gain_weight` other than "none" each Gaussian's log-det term is weighted by its
        opacity or its area share (`active.gain_weights`)."""
        source, prior = source_and_prior(gaussians, cameras, train_views, background, settings, fisher)
        return cls(BlockInformation(prior, delta_rel=fisher.delta_rel, delta_abs=fisher.delta_abs), source,
                   gain_weights(gaussians, gain_weight))

    @classmethod
    def build_render_variance(cls, gaussians: GaussianModel, cameras: list[Camera], train_views: list[int],
                              background: torch.Tensor, settings: RasterSettings, *,
                              fisher: FisherSettings = FisherSettings()) -> "FisherOracle":
        """`build`'s oracle with gains = reductions of the predicted rendering variance over the candidate poses
        (`active.variance_oracle`), the target summed by `candidate_target` before the first gain."""
        source, prior = source_and_prior(gaussians, cameras, train_views, background, settings, fisher)
        target = candidate_target(source, train_views) if set(range(len(cameras))) - set(train_views) else \
            torch.zeros_like(prior)
        information = RenderVarianceInformation(prior, target, delta_rel=fisher.delta_rel, delta_abs=fisher.delta_abs)
        return cls(information, source)


def source_and_prior(gaussians: GaussianModel, cameras: list[Camera], train_views: list[int],
                     background: torch.Tensor, settings: RasterSettings,
                     fisher: FisherSettings) -> tuple[FisherViewBlocks, torch.Tensor]:
    """The view blocks of `cameras` (cached or streamed as `fisher` says) and the prior: the sum of the training
    views' blocks. [N, P, P]"""
    source = FisherViewBlocks(gaussians, cameras, background, settings, fisher)
    return source, _prior(source, train_views, len(cameras))


def candidate_target(source: FisherViewBlocks, train_views: list[int]) -> torch.Tensor:
    """T = the sum of every candidate's blocks (the views of `source` not in `train_views`, at least one), one
    Fisher pass each, kept in `source`'s cache for the gains as a cached stage keeps them anyway. [N, P, P] float64"""
    taken = set(train_views)
    return summed_views(lambda v: source(v).dense(), [v for v in range(len(source.cameras)) if v not in taken])


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
              settings: RasterSettings, *, fisher: FisherSettings = FisherSettings(),
              reference: bool = False) -> "DiagonalFisherOracle":
        """The prior diagonal of `train_views` and an oracle over the other views of `cameras` (with `reference`,
        FisherRF's code's diagonal over `REFERENCE_DIAGONAL_GROUPS`); of `fisher`, sigma, the mode and the cache
        budget apply."""
        source = FisherViewBlocks(gaussians, cameras, background, settings, fisher, diagonal=True, reference=reference)
        return cls(_prior(source, train_views, len(cameras)), source)


def build_oracle(kind: str, gaussians: GaussianModel, cameras: list[Camera], train_views: list[int],
                 background: torch.Tensor, settings: RasterSettings, *, fisher: FisherSettings = FisherSettings()
                 ) -> FisherOracle | DiagonalFisherOracle | CoverageOracle:
    """The oracle of `kind` (a selector's `oracle_kind`): "logdet" -> `FisherOracle` (ridge and `fisher_params`
    apply), "logdet_opacity" / "logdet_area" -> the same with each Gaussian's term weighted by its opacity / the
    surface area it stands for (`active.gain_weights`), "logdet_probes" -> the same over
    the model and probe Gaussians in the space no training view observed (`active.probes`), "logdet_cover" -> the log-det
    oracle with COVER's score beside it (`active.gated_oracle.CoverGatedOracle`), "render_variance" -> the
    same blocks scored by the predicted rendering variance they remove over the candidate poses, "diagonal" ->
    `DiagonalFisherOracle` (every raw parameter group, no ridge), "diagonal_reference" -> the same over FisherRF's
    code's diagonal (`fisher_view_diagonals_reference`), "coverage" -> COVER's geometric `CoverageOracle`,
    "pool_coverage" -> its direction coverage over the pool's poses, `PoolCoverageOracle`, "pool_coverage_pixels" ->
    the same weighted by the pixels each Gaussian paints in each pose (one render per pose; these three make no
    Fisher pass; the Fisher options do not apply)."""
    if kind in ("logdet", "logdet_opacity", "logdet_area"):
        return FisherOracle.build(gaussians, cameras, train_views, background, settings, fisher=fisher,
                                  gain_weight=kind.removeprefix("logdet").removeprefix("_") or "none")
    if kind == "logdet_probes":
        augmented, _ = with_probes(gaussians, cameras, train_views, settings)
        return FisherOracle.build(augmented, cameras, train_views, background, settings, fisher=fisher)
    if kind == "logdet_cover":
        return CoverGatedOracle(FisherOracle.build(gaussians, cameras, train_views, background, settings, fisher=fisher),
                                CoverageOracle.for_model(gaussians, cameras, train_views))
    if kind == "render_variance":
        return FisherOracle.build_render_variance(gaussians, cameras, train_views, background, settings, fisher=fisher)
    if kind == "coverage":
        return CoverageOracle.for_model(gaussians, cameras, train_views)
    if kind in ("pool_coverage", "pool_coverage_pixels"):
        return PoolCoverageOracle.for_model(gaussians, cameras, train_views, settings=settings,
                                            weight="pixels" if kind == "pool_coverage_pixels" else "opacity")
    if kind in ("diagonal", "diagonal_reference"):
        return DiagonalFisherOracle.build(gaussians, cameras, train_views, background, settings, fisher=fisher,
                                          reference=kind == "diagonal_reference")
    raise ValueError(f"unknown oracle kind {kind!r} (a selector's oracle_kind is one of {', '.join(ORACLE_KINDS)})")


def cache_budget(cache_mb: int, available: int | None = None) -> int:
    """--fisher_cache_mb in bytes (0: a quarter of `available`, default the available memory)."""
    if cache_mb > 0:
        return cache_mb * (1 << 20)
    return (available_memory_bytes() if available is None else available) // 4


def summed_views(compute: Callable[[int], torch.Tensor], views: list[int]) -> torch.Tensor:
    """The sum of `compute(v)` over `views` (fresh tensors, added in place): the training views' prior information,
    from blocks [N, P, P] or diagonals [N, P]."""
    total = None
    for v in views:
        blocks = compute(v)
        total = blocks if total is None else total.add_(blocks)
    return total


def _prior(source: FisherViewBlocks, train_views: list[int], num_views: int) -> torch.Tensor:
    """The sum of the training views' blocks (or diagonals); switches `source` to streaming when one view would
    exceed the cache budget, and says once that the cache will hold only part of the candidates when all of them
    would (estimated from the training views' stored sizes). [N, P, P] or [N, P]"""
    sizes = []

    def dense_view(v: int) -> torch.Tensor:  # a training view's blocks (factors scattered to dense) or diagonals
        blocks = source.compute(v)
        sizes.append(nbytes(source.stored(blocks)))
        return blocks.dense() if isinstance(blocks, ViewFactors) else blocks

    prior = summed_views(dense_view, train_views)
    num_candidates = num_views - len(train_views)
    estimate = num_candidates * sum(sizes) / len(sizes)
    if not source.streaming and max(sizes) > source.cache_bytes:
        source.use_streaming(f"one view's Fisher information needs about {max(sizes) / 2**20:.1f} MB, more than the "
                             f"cache budget of {source.cache_bytes / 2**20:.1f} MB (--fisher_cache_mb)")
    elif not source.streaming and estimate > source.cache_bytes:  # a partial cache: never more passes than streaming
        log.warning("the Fisher cache would need %.0f MB for %d candidate views (budget %.0f MB, --fisher_cache_mb): "
                    "caching part of them, evicting %s first", estimate / 2**20, num_candidates,
                    source.cache_bytes / 2**20,
                    "the lowest upper bound" if source.eviction == "priority" else "the least recently used")
    return prior
