"""Memory known before the work: the peak bytes of a Fisher pass, estimated from the model size, the parameter block
and the image size, and the one check train.py, render.py --uncertainty and recommend.py make before starting one.

Each term is read off the code it estimates (u = N P^2 8 B: one [N, P, P] float64 copy of every Gaussian's block;
n <= N visible Gaussians, taken as N; T threads):

* "logdet" (the log-det oracles, `active.fisher.FisherOracle.build` then the candidates' gains):
  - adding a training view to the prior (`fisher._prior`): the running sum, the view's blocks scattered dense and
    R R^T of its visible ones (3 u), its unpacked float64 factors [n, P, 9], and the view's pass (below);
  - ridging and factorising the prior (`logdet.ridged_prior`): the prior, its symmetrised copy, the ridged matrix,
    the Cholesky factor and LAPACK's working copy (`DENSE_PEAK_COPIES` = 5 u; measured 4.97 u);
  - scoring candidates: A_0 and L stay (2 u), plus the cache (at most its budget, `--fisher_cache_mb`; a view's
    factors n (4 m + 8) B, m = `trapezoid.packed_width(P, 9)`) and one candidate's pass.
* "uncertainty" (`active.uncertainty.gaussian_uncertainty`: the position-variance map and recommend.py's previews):
  dense blocks of every Gaussian per training view (the sum, J^T G J and its sigma^-2 copy: 3 u, J^T G [N, P, 9]),
  then the same 5 u while the prior is factorised and inverted (`torch.cholesky_inverse`); no candidates.
* "diagonal" (the diagonal oracles and FisherRF's maps): d = N P 8 B per [N, P] diagonal; a view's pass is the
  larger of its render and Gram (`gram_pass_bytes`, freed before the next step) and J, G J and their product
  [n, 9, P] with the Gram and the diagonal (d); the prior (d) stays while candidates are scored, with the cache
  (d a view); the sigma^-2 copy and the selector's four [N, P] temporaries come after the [n, 9, P] arrays are freed
  and stay below them.

One view's pass (`fisher.fisher_view_factors`, compiled path) per visible Gaussian: the projection Jacobian
[9, P] and the attribute Gram [9, 9] in float64, the Gram kernel's moment sums (34 float64, one row per thread plus
the total: `row_kernels.gram`), the packed factors (m entries, float32 for a candidate, float64 for a training view)
and `RENDER_BYTES_PER_GAUSSIAN` of projection, render inputs, binning and colours; per pixel `PIXEL_BYTES`.
The model itself is resident when a check runs after loading it (the available memory already excludes it);
train.py's check before training adds the growth still to come (`model` bytes).

tests/test_memory_budget.py compares the estimate with the peak resident memory measured in a subprocess
(`tests/memory_probe.py`; the table in docs/performance.md).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from typing import Callable

import torch

from arguments import FisherSettings
from active.fisher import (DIAGONAL_GROUPS, FISHER_PARAM_GROUPS, ORACLE_KINDS, cache_budget,
                           parameter_columns)
from active.probes import PROBE_COUNT
from active.trapezoid import packed_width
from gaussian_renderer.tiles import NUM_GEOMETRY_ATTRIBUTES
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from scene.resolution_policy import MIN_IMAGE_SIDE
from utils.errors import UserError
from utils.system_memory import available_memory_bytes

log = logging.getLogger(__name__)

FLOAT64 = 8
ATTRIBUTES = NUM_GEOMETRY_ATTRIBUTES + 3  # 2D attributes per Gaussian (means2d, conic, opacity, colour): 9
MOMENT_SUMS = 34  # the compiled Gram kernel's moment sums per Gaussian: 15 + 6 D + 1 with D = 3 colours
RENDER_BYTES_PER_GAUSSIAN = 560  # projection (80), gathered inputs (80), bins and reach rectangles (48), packed
# attributes and colours (88), padded colours (24), SH coefficients of the visible ones (192), raw parameters (48)
PIXEL_BYTES = 64  # torch path: final colour and its prefix (3 float64 each), transmittance, weights; compiled: 20
DENSE_PEAK_COPIES = 5  # [N, P, P] float64 copies alive while the prior is ridged and factorised (or inverted)
DENSE_SUM_COPIES = 3  # ... while one training view is added to the prior
DENSE_RESIDENT_COPIES = 2  # ... while the candidates are scored: A_0 and its Cholesky factor
HEADROOM = 0.80  # a pass may take this share of the available memory; the rest covers the estimate's error:
# estimate / measured peak of the live buffers 1.00-1.12 (docs/performance.md); the allocator's cached buffers
# can raise a real process's resident peak above the live buffers' by up to ~15 %
PASS_KINDS = ("logdet", "uncertainty", "diagonal")
# oracle kind -> pass kind (None: no Fisher pass); render_variance holds one more [N, P, P] copy (its target) than
# the log-det while scoring, inside HEADROOM's margin at the scale of the measurements
ORACLE_PASSES = {"logdet": "logdet", "logdet_opacity": "logdet", "logdet_area": "logdet",
                 "logdet_probes": "logdet", "logdet_cover": "logdet",
                 "render_variance": "logdet", "diagonal": "diagonal", "diagonal_reference": "diagonal", "coverage": None,
                 "pool_coverage": None, "pool_coverage_pixels": None}
NO_FISHER_PASS = "use a selector without a Fisher pass (--method cover, coverage or random)"  # the CLIs' fallback
assert set(ORACLE_PASSES) == set(ORACLE_KINDS)


@dataclass(frozen=True)
class FisherWork:
    """What sets the memory of one Fisher pass."""

    kind: str  # one of PASS_KINDS
    num_gaussians: int  # N
    num_params: int  # P: the block's side ("logdet", "uncertainty") or the diagonal's width ("diagonal")
    pixels: int  # the largest image of the pass, W x H
    num_candidates: int = 0  # views the cache may hold
    threads: int = field(default_factory=torch.get_num_threads)  # the Gram kernel's slices: torch's threads
    model_bytes: int = 0  # model growth still to come (0 when the model is loaded at its size)

    def __post_init__(self) -> None:
        if self.kind not in PASS_KINDS:
            raise ValueError(f"pass kind must be one of {PASS_KINDS}, got {self.kind!r}")


@dataclass(frozen=True)
class FisherMemory:
    """The estimated peak of one Fisher pass in bytes, by part; `peak` = model + max(prior, resident + view + cache)."""

    work: FisherWork
    prior: int  # building the prior and factorising it
    resident: int  # what the prior leaves held while candidates are scored
    view: int  # one candidate view's pass
    cache: int  # candidate views kept (at most the cache budget)

    @property
    def fixed(self) -> int:
        """The peak without the cache: what no cache budget can lower."""
        return self.work.model_bytes + max(self.prior, self.resident + self.view)

    @property
    def peak(self) -> int:
        return self.work.model_bytes + max(self.prior, self.resident + self.view + self.cache)

    def describe(self) -> str:
        """'X GB (prior ..., one view ..., cache ..., model growth ...)', the parts that are not 0."""
        parts = {"prior": self.prior, "one view": self.view, "cache": self.cache, "model growth": self.work.model_bytes}
        return f"{gb(self.peak)} ({', '.join(f'{name} {gb(b)}' for name, b in parts.items() if b)})"


def gb(num_bytes: float) -> str:
    """Bytes as 'X.Y GB' (10^9)."""
    return f"{num_bytes / 1e9:.1f} GB"


def view_pass_bytes(work: FisherWork, factor_bytes: int) -> int:
    """One view's pass over N visible Gaussians: Jacobian, Gram, moment sums, render inputs, packed factors of
    `factor_bytes` per entry (0: dense blocks instead), and the per-pixel buffers."""
    p = work.num_params
    per_gaussian = FLOAT64 * ATTRIBUTES * p + packed_width(p, ATTRIBUTES) * factor_bytes
    return gram_pass_bytes(work) + work.num_gaussians * per_gaussian


def gram_pass_bytes(work: FisherWork) -> int:
    """The render and Gram of one view over N visible Gaussians: the Gram, moment sums, render inputs and the
    per-pixel buffers (what `fisher._attribute_gram` holds at its peak)."""
    per_gaussian = FLOAT64 * (ATTRIBUTES ** 2 + MOMENT_SUMS * (work.threads + 1)) + RENDER_BYTES_PER_GAUSSIAN
    return work.num_gaussians * per_gaussian + work.pixels * PIXEL_BYTES


def estimate(work: FisherWork, cache_bytes: int = 0) -> FisherMemory:
    """The peak bytes of `work` with a cache budget of `cache_bytes` (module docstring: where each term comes from)."""
    n, p = work.num_gaussians, work.num_params
    if work.kind == "diagonal":  # the Gram's pass ends before J, G J and their product [n, 9, P] are formed
        diag = n * p * FLOAT64
        view = max(gram_pass_bytes(work), n * (3 * ATTRIBUTES * p + ATTRIBUTES ** 2) * FLOAT64 + diag)
        cache = min(cache_bytes, work.num_candidates * diag)
        return FisherMemory(work, diag + view, diag, view, cache)
    dense = n * p * p * FLOAT64
    if work.kind == "uncertainty":  # dense blocks of every Gaussian per view, J^T G [N, P, 9] on the way
        adding = DENSE_SUM_COPIES * dense + n * ATTRIBUTES * p * FLOAT64 + view_pass_bytes(work, 0)
        return FisherMemory(work, max(DENSE_PEAK_COPIES * dense, adding), 0, 0, 0)
    m = packed_width(p, ATTRIBUTES)  # a training view's pass, then its factors unpacked and scattered dense
    adding = dense + max(view_pass_bytes(work, FLOAT64),
                         (DENSE_SUM_COPIES - 1) * dense + n * (ATTRIBUTES * p + m) * FLOAT64)
    per_view = n * (m * 4 + 8)  # float32 factors and int64 indices
    cache = min(cache_bytes, work.num_candidates * per_view)
    return FisherMemory(work, max(DENSE_PEAK_COPIES * dense, adding), DENSE_RESIDENT_COPIES * dense,
                        view_pass_bytes(work, 4), cache)


def block_size(gaussians: GaussianModel, groups: tuple[str, ...]) -> int:
    """P: the columns of `groups` in a Fisher block or diagonal of `gaussians` (`fisher.parameter_columns`)."""
    return sum(s.stop - s.start for s in parameter_columns(gaussians, groups).values())


def selection_work(oracle_kind: str, gaussians: GaussianModel, pixels: int, num_candidates: int,
                   param_groups: str, *, num_gaussians: int | None = None, model_bytes: int = 0) -> FisherWork | None:
    """The Fisher pass of one acquisition step with an oracle of `oracle_kind` (None: "coverage", no Fisher pass),
    over `num_gaussians` (default: the model's) and images of at most `pixels`."""
    kind = ORACLE_PASSES[oracle_kind]
    if kind is None:
        return None
    groups = DIAGONAL_GROUPS[oracle_kind] if kind == "diagonal" else FISHER_PARAM_GROUPS[param_groups]
    extra = PROBE_COUNT if oracle_kind == "logdet_probes" else 0  # at most this many probes join the model
    return FisherWork(kind, (gaussians.num_gaussians if num_gaussians is None else num_gaussians) + extra,
                      block_size(gaussians, groups), pixels, num_candidates, model_bytes=model_bytes)


def largest_pixels(cameras: list[Camera]) -> int:
    """W x H of the largest camera."""
    return max((c.width * c.height for c in cameras), default=0)


def pass_label(name: str, work: FisherWork, param_groups: str, up_to: bool = False) -> str:
    """'the NAME over [up to] N Gaussians (P = .., --fisher_params ..)' (no groups for a diagonal pass)."""
    groups = "" if work.kind == "diagonal" else f", --fisher_params {param_groups}"
    return f"the {name} over {'up to ' if up_to else ''}{work.num_gaussians} Gaussians (P = {work.num_params}{groups})"


def smaller_passes(work: FisherWork, gaussians: GaussianModel, width: int, size_flag: str) -> dict[str, FisherWork]:
    """The remedies every CLI with the flags has: --fisher_params default when the block is larger, and `size_flag`
    at half the widest image (`width`) while that stays >= `MIN_IMAGE_SIDE`."""
    remedies = {}
    default = block_size(gaussians, FISHER_PARAM_GROUPS["default"])
    if work.kind != "diagonal" and work.num_params > default:
        remedies["--fisher_params default"] = replace(work, num_params=default)
    if width // 2 >= MIN_IMAGE_SIDE:
        remedies[f"{size_flag} {width // 2}"] = replace(work, pixels=work.pixels // 4)
    return remedies


def fit_fisher_memory(work: FisherWork, fisher: FisherSettings, what: str,
                      remedies: dict[str, FisherWork | None], fallback: str,
                      available: int | None = None) -> FisherSettings:
    """Check `work` against `available` bytes (default: the host's MemAvailable) before it starts (`HEADROOM`).

    Returns `fisher` when the pass fits with its cache budget; when only the default budget (--fisher_cache_mb 0,
    a quarter of the available memory) does not, the budget lowered to what scoring the candidates leaves
    (streaming below 1 MB), with one message. Raises a one-line `UserError` otherwise: naming the estimate, the
    available memory and the `remedies` (flag -> the pass with it, None: no pass) that bring it under, else
    `fallback`; or, when only an explicit --fisher_cache_mb is too large, the budget that fits.
    """
    available = available_memory_bytes() if available is None else available
    usable = usable_bytes(available)
    budget = 0 if fisher.fisher_mode == "streaming" else cache_budget(fisher.fisher_cache_mb, available)
    need = estimate(work, budget)
    if need.peak <= usable:
        return fisher
    if need.fixed > usable:
        raise UserError(f"{what} needs about {need.describe()} but {gb(available)} is available "
                        f"({gb(usable)} usable); {_advice(remedies, usable, fallback, need.fixed)}")
    room = usable - work.model_bytes - need.resident - need.view  # what scoring the candidates leaves the cache
    if fisher.fisher_cache_mb == 0:
        lowered = (replace(fisher, fisher_cache_mb=room >> 20) if room >= 1 << 20
                   else replace(fisher, fisher_mode="streaming"))
        log.warning("%s: a Fisher cache of %s would exceed the available memory (%s); %s", what, gb(budget),
                    gb(available), f"caching at most {gb(room)}" if room >= 1 << 20 else "streaming")
        return lowered
    cache_flag = f"--fisher_cache_mb {room >> 20} or " if room >= 1 << 20 else ""
    raise UserError(f"{what} needs about {need.describe()} with --fisher_cache_mb {fisher.fisher_cache_mb} but "
                    f"{gb(available)} is available ({gb(usable)} usable); pass {cache_flag}--fisher_mode streaming")


def _advice(remedies: dict[str, FisherWork | None], usable: int, fallback: str, need: int) -> str:
    """'pass FLAG (about X GB) or ...' for the remedies that fit `usable` (their cache budget lowered as needed; a
    remedy None makes no Fisher pass), else what those saving a tenth of `need` would still need, and `fallback`."""
    needs = {flag: 0 if work is None else estimate(work).fixed for flag, work in remedies.items()}
    fits = [f"{flag} ({'no Fisher pass' if remedies[flag] is None else f'about {gb(b)}'})"
            for flag, b in needs.items() if b <= usable]
    if fits:
        return "pass " + " or ".join(fits)
    tried = [f"{flag} would still need {gb(b)}" for flag, b in needs.items() if b <= 0.9 * need]
    return "; ".join(tried + [fallback])


def device_available_bytes(device: torch.device) -> int:
    """Free memory where a pass's tensors live: the CUDA device's (`torch.cuda.mem_get_info`), else the host's
    MemAvailable (`utils.system_memory.available_memory_bytes`)."""
    return torch.cuda.mem_get_info(device)[0] if device.type == "cuda" else available_memory_bytes()


def usable_bytes(available: int) -> int:
    """The share of `available` a Fisher pass may take (`HEADROOM`)."""
    return int(available * HEADROOM)


def largest_count(work_at: Callable[[int], FisherWork], upper: int, usable: int) -> int:
    """The largest N <= `upper` whose pass `work_at(N)` fits `usable` bytes without a cache (0 if none does)."""
    lo, hi = 0, upper
    while lo < hi:
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if estimate(work_at(mid)).fixed <= usable else (lo, mid - 1)
    return lo
