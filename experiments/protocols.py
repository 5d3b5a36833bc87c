"""The paper's experiment protocols as data, and their expansion into one run per (scene, method, K, eps, seed).

Iteration counts are paper scale; `RunScale.iter_scale` shrinks them (and the densification start and the
opacity-reset interval) for CPU-sized runs; `RunScale.stage_scale`, when set, scales the stages before each
selection on their own (e.g. the paper's stage lengths with a shortened final refinement). Directory names follow
`<method>[_k<K>][_eps<E>]`.

`fisherrf20` / `fisherrf20_360` are the protocol of FisherRF (Jiang et al. 2024) that POP-GS reuses, read from
FisherRF's public code (github.com/JiangWenPL/FisherRF): `scripts/blender_seq1.sh` and `scripts/mip360_seq1.sh`
run `active_train.py --eval --schema v20seq1_inplace --iterations 30000` (Blender, `--white_background`) and
`--iterations 20000` (Mip-NeRF 360); `active/schema.py` defines `v20seq1_inplace` as `VNSeqMInplace(N=20, M=1,
num_init_views=4, interval_epochs=100)`: seed views = training view 0 plus 3 by farthest-point sampling of camera
centres (the candidate farthest from the chosen set, first index on ties), then one view per step up to 20, the
step after a stage of 100 x |train| iterations (views are added at iterations 400, 900, 1500, ..., 18,400).
Seeding here is the same (`active.schedule.farthest_point_views`, from view 0). One difference: FisherRF's
`active_train.py` reloads the initial Gaussians and restarts the learning-rate and densification clock after each
acquisition; these protocols keep training the current model (the project's default, as in Setups 1-4).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

DEFAULT_EPS = 0.1  # the paper's eps "unless otherwise stated"
DENSIFY_FROM_ITER = 500  # 3DGS defaults, scaled with the iterations
OPACITY_RESET_INTERVAL = 3000


@dataclass(frozen=True)
class Protocol:
    """One setup of the paper: acquisition schedule, budgets and the settings swept."""

    description: str
    num_init_views: int  # seed views
    ks: tuple[int, ...]  # views added per acquisition step; several = a sweep over K
    max_views: int  # view budget
    iters_per_view: int  # each stage trains iters_per_view x current #views iterations (paper scale)
    iterations: int  # total iterations (paper scale)
    default_scenes: tuple[str, ...]
    default_methods: tuple[str, ...]
    eps_sweep: tuple[float, ...] = ()  # fixed eps values for every eps-taking method (--eps unused); () = --eps
    extra_eps: dict[int, tuple[float, ...]] = field(default_factory=dict)  # K -> more eps values (eps methods)
    k_in_name: bool = False  # directory names carry _k<K> (the K sweep)


SIX_METHODS = ("random", "coverage", "fisherrf", "pop_gs", "lite_gs", "ssg")

PROTOCOLS: dict[str, Protocol] = {
    "setup1": Protocol("2 seed views, +3 per step to 11, 100 v iterations per stage, 11,000 in total "
                       "(Blender, Mip-NeRF 360)", 2, (3,), 11, 100, 11_000, ("lego",),
                       ("random", "pop_gs", "lite_gs")),
    "setup2": Protocol("5 seed views, +4 per step to 21, 300 v per stage, 21,000 in total (Blender)",
                       5, (4,), 21, 300, 21_000, ("lego",), ("random", "pop_gs", "lite_gs")),
    "setup3": Protocol("3 seed views, +4 per step to 15, 100 v per stage, 11,000 in total (Mip-NeRF 360)",
                       3, (4,), 15, 100, 11_000, ("garden",), ("random", "pop_gs", "lite_gs")),
    "setup4": Protocol("3 seed views, K in {3, 4, 6} to 15, 300 v per stage, 15,000 in total (ship); "
                       "K = 6 also eps = 0.3, 0.6", 3, (3, 4, 6), 15, 300, 15_000, ("ship",),
                       ("random", "pop_gs", "lite_gs"), extra_eps={6: (0.3, 0.6)}, k_in_name=True),
    "ablation_ssg": Protocol("lite_gs vs ssg on ship, Setup 4 protocol with K = 4, "
                             "eps in {0.1, 0.2, 0.25, 0.4, 0.6}", 3, (4,), 15, 300, 15_000, ("ship",),
                             ("lite_gs", "ssg"), eps_sweep=(0.1, 0.2, 0.25, 0.4, 0.6)),
    "fisherrf20": Protocol("FisherRF / POP-GS: 4 seed views (view 0 + farthest-point sampling), +1 per step to 20, "
                           "100 v iterations per stage, 30,000 in total (Blender)", 4, (1,), 20, 100, 30_000,
                           ("lego",), SIX_METHODS),
    "fisherrf20_360": Protocol("FisherRF / POP-GS on Mip-NeRF 360: as fisherrf20 with 20,000 iterations in total",
                               4, (1,), 20, 100, 20_000, ("bonsai",), SIX_METHODS),
}


def stage_view_sum(protocol: Protocol, k: int) -> int:
    """Sum of the training-view counts of the stages before each acquisition step (a stage trains
    iters_per_view x that count): e.g. Setup 1, 2 + 5 + 8 = 15."""
    views, total = protocol.num_init_views, 0
    while views < protocol.max_views:
        total += views
        views = min(views + k, protocol.max_views)
    return total


@dataclass(frozen=True)
class RunScale:
    """How far a grid shrinks the paper's runs."""

    resolution: int = 8  # train.py -r (8: 100 px for 800 px Blender scenes)
    iter_scale: float = 0.1  # multiplies iterations per view, total, densification start, opacity-reset interval
    num_points: int = 3000  # random initial points for synthetic scenes (paper: 100,000)
    # None: stages scale with iter_scale. Else it multiplies the stage lengths (iterations per view), the
    # densification start and the opacity-reset interval, while the refinement after the last step keeps iter_scale.
    stage_scale: float | None = None

    def scaled(self, n: int) -> int:
        """max(1, round(n * iter_scale)), halves rounded up (as the shell scripts did)."""
        return _round_scaled(n, self.iter_scale)

    def stage_scaled(self, n: int) -> int:
        """`n` scaled as the stages are: by stage_scale when it is set, else by iter_scale."""
        return _round_scaled(n, self.iter_scale if self.stage_scale is None else self.stage_scale)

    def total_iterations(self, protocol: Protocol, k: int) -> int:
        """Total iterations: the paper's total scaled; with stage_scale, the scaled stages plus the paper's refinement
        (total minus the stages) scaled by iter_scale."""
        if self.stage_scale is None:
            return self.scaled(protocol.iterations)
        views = stage_view_sum(protocol, k)
        refinement = max(protocol.iterations - protocol.iters_per_view * views, 0)  # paper scale
        return self.stage_scaled(protocol.iters_per_view) * views + self.scaled(refinement)


def _round_scaled(n: int, scale: float) -> int:
    return max(1, int(n * scale + 0.5))


@dataclass(frozen=True)
class RunSpec:
    """One training run of a grid: where it goes and which schedule flags train.py gets."""

    setup: str
    scene: str
    method: str
    k: int
    eps: float | None  # None: the method takes no eps
    seed: int
    tag: str  # directory name <method>[_k<K>][_eps<E>]

    @property
    def key(self) -> str:
        """<scene>/<tag>/seed<S>, the run's path below OUT/<setup>."""
        return f"{self.scene}/{self.tag}/seed{self.seed}"

    def schedule_args(self, protocol: Protocol, scale: RunScale) -> list[str]:
        """train.py flags of the acquisition schedule, scaled."""
        args = ["--seed", str(self.seed), "--method", self.method]
        if self.eps is not None:
            args += ["--eps", f"{self.eps:g}"]
        return args + [
            "--num_init_views", str(protocol.num_init_views), "--views_per_step", str(self.k),
            "--max_views", str(protocol.max_views),
            "--iters_per_view", str(scale.stage_scaled(protocol.iters_per_view)),
            "--iterations", str(scale.total_iterations(protocol, self.k)), "--num_random_points", str(scale.num_points),
            "--densify_from_iter", str(scale.stage_scaled(DENSIFY_FROM_ITER)),
            "--opacity_reset_interval", str(scale.stage_scaled(OPACITY_RESET_INTERVAL))]


def expand(setup: str, scenes: list[str], methods: list[str], seeds: int, eps: float,
           takes_eps: Callable[[str], bool]) -> list[RunSpec]:
    """Every run of `setup` over scenes x methods x seeds (0..seeds-1), in scene, K, method, eps, seed order.

    An eps-taking method (`takes_eps(method)`) runs at `eps`, or at each value of the protocol's eps sweep; its
    directory name carries `_eps<E>` when the protocol sweeps eps or E is not the paper's 0.1. `extra_eps[K]`
    adds eps-taking runs at that K (always named with their eps; a value equal to `eps` is not repeated).
    """
    protocol = PROTOCOLS[setup]
    runs = []
    for scene in scenes:
        for k in protocol.ks:
            for method in methods:
                settings: list[tuple[float | None, bool]]
                if not takes_eps(method):
                    settings = [(None, False)]
                elif protocol.eps_sweep:
                    settings = [(e, True) for e in protocol.eps_sweep]
                else:
                    settings = [(eps, eps != DEFAULT_EPS)]
                    settings += [(e, True) for e in protocol.extra_eps.get(k, ()) if e != eps]
                for e, named in settings:
                    tag = method + (f"_k{k}" if protocol.k_in_name else "") + (f"_eps{e:g}" if named else "")
                    runs += [RunSpec(setup, scene, method, k, e, seed, tag) for seed in range(seeds)]
    return runs
