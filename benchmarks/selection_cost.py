"""Per-candidate selection cost, old (dense [N, P, P] blocks, `DenseBlockInformation`) vs new (visible-set factors,
`BlockInformation` with the numba kernels), measured in one run, beside POP-GS's GPU rates.

    python benchmarks/selection_cost.py --synthetic 50000 --visible 0.3 1.0     # gain / commit at N = 50k, P = 14
    python benchmarks/selection_cost.py --model output/quickstart               # a trained model at its resolution
    python benchmarks/selection_cost.py --garden 648x420 1296x840               # garden SfM init, 138k Gaussians

For a model or the garden: Fisher seconds per candidate (old: the dense blocks; new: the visible factors),
gain and commit ms, candidates per second end to end (render + Gram + Jacobian + gain), the cached stage's size,
for 14-parameter ("default") and full-SH blocks, and the arithmetic floor of a gain and a commit at the machine's
peak f64 rate (--peak_gflops, all cores used; an estimate, stated with the numbers). The old path is skipped where
its dense blocks would need more than --dense_limit_gb. Peak resident memory of the process is printed at the end.
Take numbers with --threads 2 and say whether the machine was shared.
"""
from __future__ import annotations

import argparse
import json
import platform
import resource
import statistics
import time
from pathlib import Path

import torch

from active import fisher
from active.fisher import FACTOR_STORAGE, FISHER_PARAM_GROUPS, fisher_view_blocks, fisher_view_factors
from active.logdet import BlockInformation, DenseBlockInformation, ViewFactors
from active.schedule import farthest_point_views
from gaussian_renderer import RasterSettings
from scene.cameras import Camera
from scene.garden import load_garden
from scene.gaussian_model import GaussianModel
from utils.errors import run_cli

RESULTS_DIR = Path(__file__).parent / "results"
POP_GS_HZ = {"block w/o SH": 1.71, "full block": 0.15, "diagonal": 12.16}  # per candidate, Blender ship, a GPU


def timed(fn, repeats: int) -> tuple[float, object]:
    """Median seconds of `repeats` calls (no warm-up: the first call is timed too) and the last result."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def gain_flops(n: int, p: int, r: int) -> float:
    """Arithmetic of one gain over n visible blocks: L^-1 R (P^2 r), Y^T Y (P r (r + 1)), r x r Cholesky (r^3 / 3)."""
    return n * (p * p * r + p * r * (r + 1) + r ** 3 / 3)


def commit_flops(n: int, p: int, r: int) -> float:
    """One commit: L^-1 R (P^2 r), I + Y Y^T (P^2 r), P x P Cholesky (P^3 / 3), L C (P^3 / 3)."""
    return n * (2 * p * p * r + 2 * p ** 3 / 3)


def synthetic(n: int, visible: float, peak: float, repeats: int) -> dict:
    """Gain and commit at N Gaussians, P = 14, rank-9 view factors on a `visible` fraction of them."""
    g = torch.Generator().manual_seed(0)
    p, r = 14, 9
    j = torch.randn(n, 12, p, generator=g, dtype=torch.float64)
    prior = j.transpose(1, 2) @ j  # [N, P, P]
    seen = torch.sort(torch.randperm(n, generator=g)[:int(round(visible * n))]).values
    view = ViewFactors.from_factors(seen, torch.randn(len(seen), p, r, generator=g, dtype=torch.float64), n)
    new, old = BlockInformation(prior), DenseBlockInformation(prior)
    new.gain(view)  # compile
    dense = view.dense()
    t_new, gain_new = timed(lambda: new.gain(view), repeats)
    view32 = view.stored_as(torch.float32)
    t_new32, gain_new32 = timed(lambda: new.gain(view32), repeats)
    t_old, (gain_old, w) = timed(lambda: old.gain_and_whitened(dense), max(1, repeats // 3))
    t_commit_old, _ = timed(lambda: old.add_whitened(w), 1)
    t_commit_new, _ = timed(lambda: new.add(view), 1)
    row = {"N": n, "visible": len(seen), "gain_old_ms": 1e3 * t_old, "gain_new_ms": 1e3 * t_new,
           "gain_new_f32_ms": 1e3 * t_new32, "commit_old_ms": 1e3 * t_commit_old, "commit_new_ms": 1e3 * t_commit_new,
           "gain_rel_diff": abs(gain_new - gain_old) / gain_old, "f32_rel_diff": abs(gain_new32 - gain_new) / gain_new,
           "gain_floor_ms": 1e3 * gain_flops(len(seen), p, r) / peak,
           "commit_floor_ms": 1e3 * commit_flops(len(seen), p, r) / peak}
    print(f"N = {n}, {len(seen)} seen (P = {p}, r = {r}): gain old {row['gain_old_ms']:.1f} ms, new "
          f"{row['gain_new_ms']:.2f} ms (float32 storage {row['gain_new_f32_ms']:.2f} ms), "
          f"{t_old / t_new:.1f}x; floor {row['gain_floor_ms']:.2f} ms | commit old {row['commit_old_ms']:.1f} ms, new "
          f"{row['commit_new_ms']:.1f} ms; floor {row['commit_floor_ms']:.2f} ms | |new - old| / old = "
          f"{row['gain_rel_diff']:.1e}, float32 storage {row['f32_rel_diff']:.1e}", flush=True)
    return row


def per_candidate(name: str, gaussians: GaussianModel, cams: list[Camera], bg: torch.Tensor,
                  settings: RasterSettings, train: list[int], candidates: list[int], num_candidates: int,
                  peak: float, dense_limit: float, repeats: int,
                  param_groups: tuple[str, ...] = ("default", "full_sh")) -> list[dict]:
    """Old vs new per-candidate cost on one scene, for 14-parameter and full-SH blocks."""
    rows = []
    n = gaussians.num_gaussians
    with torch.no_grad():  # the render + attribute Gram part of a Fisher pass (the rest: Jacobian, factor)
        def gram():
            return fisher._attribute_gram(gaussians, cams[candidates[0]], bg, settings)

        gram()  # compile (numba caches on disk)
        t_gram = timed(gram, 1)[0]
    print(f"{name}: render + attribute Gram of one view {t_gram:.2f} s", flush=True)
    for groups in param_groups:
        params = FISHER_PARAM_GROUPS[groups]
        p = sum(gaussians.params[g].shape[1:].numel() for g in params)
        dense_gb = n * p * p * 8 * 4 / 2**30  # blocks, whitened copy, eigenvectors, QR: ~4 dense copies
        do_old = dense_gb <= dense_limit
        if n * p * p * 8 * 3 / 2**30 > 2 * dense_limit:  # the new path's dense state: prior, A, L
            print(f"{name} {groups}: skipped (the dense prior, A and L need {n * p * p * 24 / 2**30:.1f} GB)")
            continue

        def factors(v):
            return fisher_view_factors(gaussians, cams[v], bg, settings, param_groups=params, dtype=FACTOR_STORAGE)

        prior = None  # [N, P, P], summed in place: full-SH blocks at the garden are 3.9 GB a copy
        for v in train:
            blocks = fisher_view_factors(gaussians, cams[v], bg, settings, param_groups=params).dense()
            prior = blocks if prior is None else prior.add_(blocks)
            del blocks
        new = BlockInformation(prior)
        warm_prior = prior[:1].clone()
        if not do_old:  # only the dense path needs it again
            del prior
        t_fisher, views = [], []
        for v in candidates[:repeats]:
            t, view = timed(lambda v=v: factors(v), 1)
            t_fisher.append(t)
            views.append(view)
        t_fisher = statistics.median(t_fisher)
        new.gain(views[0])  # compile (numba caches on disk) the gain and the commit for this factor dtype
        warm = ViewFactors(torch.zeros(1, dtype=torch.long), views[0].packed[:1], views[0].num_params,
                           views[0].num_columns, 1)
        BlockInformation(warm_prior).add(warm)
        t_gain = statistics.median(timed(lambda v=v: new.gain(v), 3)[0] for v in views)
        mean_bytes = sum(v.nbytes for v in views) / len(views)
        seen = sum(v.indices.numel() for v in views) / len(views)
        row = {"scene": name, "params": groups, "P": p, "N": n, "seen": seen, "fisher_new_s": t_fisher,
               "gram_s": t_gram,
               "gain_new_ms": 1e3 * t_gain, "rate_new_hz": 1.0 / (t_fisher + t_gain),
               "stage_cache_new_mb": num_candidates * mean_bytes / 2**20,
               "stage_cache_old_mb": num_candidates * n * p * p * 8 / 2**20,
               "gain_floor_ms": 1e3 * gain_flops(int(seen), p, 9) / peak,
               "commit_floor_ms": 1e3 * commit_flops(int(seen), p, 9) / peak}
        commit_info = BlockInformation(prior) if do_old else new  # without the dense path, `new` is not used again
        row["commit_new_ms"] = 1e3 * timed(lambda: commit_info.add(views[0]), 1)[0]
        if do_old:
            old = DenseBlockInformation(prior)
            t_old_fisher, gains = [], []
            for v in candidates[:repeats]:
                t, blocks = timed(lambda v=v: fisher_view_blocks(gaussians, cams[v], bg, settings,
                                                                 param_groups=params), 1)
                t_old_fisher.append(t)
            t_old_gain, (gain_old, w) = timed(lambda: old.gain_and_whitened(blocks), 1)
            row.update({"fisher_old_s": statistics.median(t_old_fisher), "gain_old_ms": 1e3 * t_old_gain,
                        "commit_old_ms": 1e3 * timed(lambda: old.add_whitened(w), 1)[0]})
            row["rate_old_hz"] = 1.0 / (row["fisher_old_s"] + t_old_gain)
            last = new.gain(views[-1])
            row["gain_rel_diff_f32"] = abs(last - gain_old) / gain_old
        rows.append(row)
        old_text = (f"old: Fisher {row['fisher_old_s']:.2f} s, gain {row['gain_old_ms']:.0f} ms, commit "
                    f"{row['commit_old_ms']:.0f} ms, {row['rate_old_hz']:.2f} candidates/s | " if do_old else
                    f"old: skipped (dense blocks ~{dense_gb:.1f} GB) | ")
        print(f"{name} {groups} (P = {p}, {n} Gaussians, {seen:.0f} seen): {old_text}new: Fisher {t_fisher:.2f} s, "
              f"gain {row['gain_new_ms']:.1f} ms (floor {row['gain_floor_ms']:.2f}), commit {row['commit_new_ms']:.0f} "
              f"ms (floor {row['commit_floor_ms']:.1f}), {row['rate_new_hz']:.2f} candidates/s | stage cache "
              f"{num_candidates} views: old {row['stage_cache_old_mb']:.0f} MB, new {row['stage_cache_new_mb']:.0f} MB"
              + (f" | float32 new vs old gain {row['gain_rel_diff_f32']:.1e}" if do_old else ""), flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--synthetic", type=int, default=0, help="N Gaussians of random blocks (0: skip)")
    parser.add_argument("--visible", type=float, nargs="+", default=[0.3, 1.0], help="fractions seen (synthetic)")
    parser.add_argument("--model", type=Path, default=None, help="a trained model directory")
    parser.add_argument("--garden", nargs="*", default=None, help="WxH sizes of the garden scene (648x420 ...)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--peak_gflops", type=float, default=96.0,
                        help="f64 peak of all threads (default: 2 cores x 48, AVX2 FMA at ~3 GHz)")
    parser.add_argument("--dense_limit_gb", type=float, default=4.0,
                        help="skip the old path above this (the new path above twice this)")
    parser.add_argument("--params", nargs="+", choices=tuple(FISHER_PARAM_GROUPS), default=list(FISHER_PARAM_GROUPS))
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    peak = args.peak_gflops * 1e9
    print(f"{platform.platform()}, torch {torch.__version__}, {torch.get_num_threads()} threads; POP-GS (GPU, Blender "
          f"ship) per candidate: " + ", ".join(f"{k} {v} Hz" for k, v in POP_GS_HZ.items()), flush=True)
    out = {"machine": platform.platform(), "threads": args.threads, "peak_gflops": args.peak_gflops,
           "pop_gs_hz": POP_GS_HZ, "synthetic": [], "scenes": []}
    for fraction in (args.visible if args.synthetic else []):
        out["synthetic"].append(synthetic(args.synthetic, fraction, peak, args.repeats))
    if args.model:
        from scene.trained import load_trained
        trained = load_trained(args.model, device="cpu")
        cams = trained.scene.train_cameras
        seeds = farthest_point_views(torch.stack([c.camera_center for c in cams]), 2)
        candidates = [v for v in range(len(cams)) if v not in seeds]
        name = f"{args.model} {cams[0].width}x{cams[0].height}"
        out["scenes"] += per_candidate(name, trained.gaussians, cams, trained.background, trained.settings, seeds,
                                       candidates, len(candidates), peak, args.dense_limit_gb, args.repeats,
                                       args.params)
    for size in args.garden or []:
        gaussians, cams, bg, settings = load_garden(size)
        out["scenes"] += per_candidate(f"garden {size}", gaussians, cams, bg, settings, [0], [1, 2, 1], 78, peak,
                                       args.dense_limit_gb, args.repeats, args.params)
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory of this process: {out['peak_rss_mb']:.0f} MB")
    path = args.json or RESULTS_DIR / f"selection_cost_{time.strftime('%Y%m%d_%H%M%S')}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    run_cli(main)
