"""A timed slice of a paper-scale Setup 1 run, and the projected wall time of the whole run.

    python benchmarks/gpu_slice.py --method lite_gs --data ../shared/data/lego --device cuda --budget_s 180

Runs the training engine's steps (`open_run`, `training_step`, `acquire`) with Setup 1's flags (read from
`experiments/protocols.py`, as `scripts/setup1.sh` runs it) at
`--iter_scale 1 --num_points 100000 --resolution 1` (800 px; 2 seed views, +3 per step to 11, 100 iterations per
view and stage, 11,000 in total) in streaming Fisher mode, for about --budget_s seconds: stage 0's training (cut at
half the budget), the first acquisition, then training again until the budget is spent. Records s/iteration, Fisher
seconds per oracle, selection seconds and peak memory, and projects the whole run: every iteration at the measured
s/iteration plus each acquisition scaled by its oracle count (the selector's `conservative_count`) from the measured
first one. The projection ignores densification's change of the Gaussian count (--max_gaussians bounds it).
Writes <out>/slice_<method>.json and prints one summary line.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch
from tqdm import tqdm

from active.registry import selector_options
from experiments.protocols import DEFAULT_EPS, PROTOCOLS, RunScale, expand
from training.config import parse_config
from training.engine import Run, acquire, open_run
from training.step import next_view, training_step
from utils.errors import run_cli

ROOT = Path(__file__).resolve().parents[1]


def setup1_flags(data: str, model: str, method: str, device: str, resolution: int, num_points: int) -> list[str]:
    """train.py flags of Setup 1 (`experiments/protocols.py`, as scripts/setup1.sh runs it) at --iter_scale 1, seed 0,
    streaming Fisher mode."""
    run = expand("setup1", [Path(data).name], [method], 1, DEFAULT_EPS, lambda m: "eps" in selector_options(m))[0]
    schedule = run.schedule_args(PROTOCOLS["setup1"], RunScale(resolution, 1.0, num_points))
    return ["-s", data, "-m", model, "--eval", "-r", str(resolution), "--white_background", "--device", device,
            *schedule, "--fisher_mode", "streaming", "--quiet", "--overwrite"]


def sync(device: str) -> None:
    if device == "cuda":
        torch.cuda.synchronize()


def train_for(run: Run, until_iteration: int, deadline: float, device: str) -> tuple[int, float]:
    """Train up to `until_iteration` or the deadline; returns (iterations done, seconds)."""
    state, start = run.state, run.state.iteration
    t0 = time.perf_counter()
    while state.iteration < until_iteration and time.perf_counter() < deadline:
        cam = run.scene.train_cameras[next_view(state, run.rng)]
        training_step(state, cam, run.cfg, run.background, run.settings, run.lr_schedule, run.scene.extent)
        if state.iteration % 10 == 0:
            sync(device)
    sync(device)
    return state.iteration - start, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--method", default="lite_gs")
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "lego"))
    parser.add_argument("--device", default="cuda", choices=("cuda", "cpu"))
    parser.add_argument("--resolution", type=int, default=1, help="train.py -r (1 = 800 px)")
    parser.add_argument("--num_points", type=int, default=100_000)
    parser.add_argument("--budget_s", type=float, default=180.0)
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    parser.add_argument("--model", default=None, help="model directory (default: <out>/slice_<method>_model)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    model = args.model or str(out / f"slice_{args.method}_model")
    t_start = time.perf_counter()
    deadline = t_start + args.budget_s
    cfg = parse_config(setup1_flags(args.data, model, args.method, args.device, args.resolution,
                                          args.num_points))
    run = open_run(cfg, model)
    load_s = time.perf_counter() - t_start
    if args.device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    n0 = run.state.gaussians.num_gaussians
    it0, sec0 = train_for(run, run.plan.stage_end[0], t_start + args.budget_s / 2, args.device)
    partial = {"method": args.method, "gaussians_start": n0, "stage0_iterations": it0,
               "stage0_s_per_iteration": sec0 / max(it0, 1), "load_s": load_s, "note": "acquisition did not finish"}
    (out / f"slice_{args.method}.json").write_text(json.dumps(partial, indent=2) + "\n")  # kept if killed later
    progress = tqdm(disable=True)
    t0 = time.perf_counter()
    acquire(run, progress)
    sync(args.device)
    acquire_s = time.perf_counter() - t0
    record = run.state.stages[0]
    it1, sec1 = train_for(run, run.plan.total_iterations, deadline, args.device)
    calls0 = record["oracle_calls"]["evaluated"]
    fisher_views0 = calls0 + len(record["train_views"])  # streaming: every gain recomputes a view; the prior too
    s_per_it = (sec0 + sec1) / max(it0 + it1, 1)
    plan, selector = run.plan, run.selector
    projected_acq, views = 0.0, len(record["train_views"])
    for k in plan.adds:
        m = len(run.scene.train_cameras) - views
        projected_acq += acquire_s * (selector.conservative_count(m, k) + views) / max(fisher_views0, 1)
        views += k
    result = {
        "method": args.method, "device": args.device,
        "device_name": torch.cuda.get_device_name() if args.device == "cuda" else "cpu",
        "resolution_px": run.scene.train_cameras[0].width, "gaussians_start": n0,
        "gaussians_end": run.state.gaussians.num_gaussians, "load_s": load_s,
        "stage0_iterations": it0, "stage0_s_per_iteration": sec0 / max(it0, 1),
        "later_iterations": it1, "later_s_per_iteration": sec1 / max(it1, 1) if it1 else None,
        "s_per_iteration": s_per_it,
        "acquisition_s": acquire_s, "oracle_evaluations": calls0, "fisher_views_computed": fisher_views0,
        "fisher_seconds": record["fisher_seconds"], "fisher_s_per_oracle": record["fisher_seconds"] / max(fisher_views0, 1),
        "select_seconds": record["select_seconds"], "selected": record["selected"],
        "peak_memory_mib": torch.cuda.max_memory_allocated() / 2**20 if args.device == "cuda" else None,
        "total_iterations": plan.total_iterations, "projected_training_s": plan.total_iterations * s_per_it,
        "projected_acquisitions_s": projected_acq,
        "projected_run_s": load_s + plan.total_iterations * s_per_it + projected_acq,
        "slice_wall_s": time.perf_counter() - t_start,
    }
    (out / f"slice_{args.method}.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"slice {args.method} on {result['device_name']} at {result['resolution_px']} px, {n0} Gaussians: "
          f"{s_per_it:.3f} s/iteration ({it0 + it1} iterations), first acquisition {acquire_s:.1f} s "
          f"({calls0} oracles, Fisher {result['fisher_s_per_oracle']:.2f} s/oracle, selection "
          f"{record['select_seconds']:.1f} s), peak {result['peak_memory_mib'] or 0:.0f} MiB; projected Setup 1 run "
          f"({plan.total_iterations} iterations, {len(plan.adds)} acquisitions): "
          f"{result['projected_run_s'] / 3600:.2f} h", flush=True)


if __name__ == "__main__":
    run_cli(main)
