"""Where the training loop and the Fisher pass wait for the GPU: host syncs counted per source line.

    python benchmarks/gpu_syncs.py --data ../shared/data/lego --device cuda

Opens a train.py run (lego at -r 8, 20,000 random points, an active lite_gs set-up), then, under
`torch.cuda.set_sync_debug_mode("warn")`, runs 20 training steps and one view's Fisher blocks, and lists every
synchronising call by the project line that issued it, with its count per step / per view. The same phases also
run under `torch.profiler` and the device-to-host copies and stream synchronisations it records are counted.
On a CPU there are no host syncs: the script still runs (the plumbing of `benchmarks/gpu_check.sh`) and says so.
"""
from __future__ import annotations

import argparse
import collections
import tempfile
import traceback
import warnings
from pathlib import Path

import torch

from training.config import parse_config
from training.engine import open_run
from training.step import next_view, training_step
from utils.errors import run_cli

ROOT = Path(__file__).resolve().parents[1]

STEPS = 20


def project_frame(stack: list[traceback.FrameSummary]) -> str:
    """The innermost frame of this project (not torch, not this script) as path:line function."""
    for frame in reversed(stack):
        path = Path(frame.filename).resolve()
        if ROOT in path.parents and path.name != Path(__file__).name:
            return f"{path.relative_to(ROOT)}:{frame.lineno} {frame.name}: {(frame.line or '').strip()[:80]}"
    return "(outside the project)"


def count_syncs(fn, repeats: int) -> collections.Counter:
    """Synchronising CUDA calls of `repeats` calls of fn, by project source line (CUDA sync debug mode)."""
    counts: collections.Counter = collections.Counter()
    original = warnings.showwarning

    def record(message, category, filename, lineno, file=None, line=None):
        if "synchroniz" in str(message):
            counts[project_frame(traceback.extract_stack()[:-1])] += 1
        else:
            original(message, category, filename, lineno, file, line)

    warnings.showwarning = record
    torch.cuda.set_sync_debug_mode("warn")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.showwarning = record
            for _ in range(repeats):
                fn()
            torch.cuda.synchronize()
    finally:
        torch.cuda.set_sync_debug_mode(0)
        warnings.showwarning = original
    return counts


PROJECT = ("train.py", "gaussian_renderer/", "active/", "training/", "scene/", "utils/")  # profiler frame names
SYNC_OPS = ("aten::_local_scalar_dense", "aten::nonzero")  # a scalar read and a data-dependent shape: host syncs on CUDA


def profile_copies(fn, device: str) -> tuple[dict[str, int], collections.Counter]:
    """Counts of scalar reads, nonzero, device-to-host copies and synchronisations the torch profiler records for one
    call of fn, and the scalar reads / nonzero calls by project source line (these are the host syncs on CUDA, so
    the CPU profile already shows where they are)."""
    activities = [torch.profiler.ProfilerActivity.CPU]
    if device == "cuda":
        activities.append(torch.profiler.ProfilerActivity.CUDA)
    with torch.profiler.profile(activities=activities, with_stack=True) as prof:
        fn()
    events = prof.events()
    names = collections.Counter(e.name for e in events)
    keys = ("aten::item", *SYNC_OPS, "cudaStreamSynchronize", "cudaDeviceSynchronize",
            "Memcpy DtoH (Device -> Pageable)", "cudaMemcpyAsync")
    sites: collections.Counter = collections.Counter()
    for e in events:
        if e.name in SYNC_OPS:
            parent = e.cpu_parent  # the Python tracer's frames are the op's ancestors, named "path(line): function"
            while parent is not None and not parent.name.replace(str(ROOT) + "/", "").startswith(PROJECT):
                parent = parent.cpu_parent
            where = parent.name.replace(str(ROOT) + "/", "") if parent is not None else "?"
            sites[f"{e.name.split('::')[1]} at {where}"] += 1
    return {k: names.get(k, 0) for k in keys}, sites


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "lego"))
    parser.add_argument("--device", default="cuda", choices=("cuda", "cpu"))
    parser.add_argument("--resolution", default="8")
    parser.add_argument("--num_points", default="20000")
    args = parser.parse_args()
    model = tempfile.mkdtemp(prefix="gpu_syncs_")
    cfg = parse_config(["-s", args.data, "-m", model, "--eval", "-r", args.resolution, "--white_background",
                              "--device", args.device, "--method", "lite_gs", "--num_random_points", args.num_points,
                              "--densify_from_iter", "5", "--densification_interval", "10", "--quiet"])
    run = open_run(cfg, model)
    state = run.state

    def step():
        cam = run.scene.train_cameras[next_view(state, run.rng)]
        training_step(state, cam, run.cfg, run.background, run.settings, run.lr_schedule, run.scene.extent)

    from active.fisher import FisherOracle
    from arguments import FisherSettings
    oracle = FisherOracle.build(state.gaussians, run.scene.train_cameras, state.train_views[:1], run.background,
                                run.settings, fisher=FisherSettings(fisher_mode="streaming"))
    candidate = next(v for v in range(len(run.scene.train_cameras)) if v not in state.train_views)

    def fisher():
        oracle.blocks.compute(candidate)

    step()
    fisher()  # warm-up
    print(f"{state.gaussians.num_gaussians} Gaussians, {run.scene.train_cameras[0].width} px, device {args.device}")
    for name, fn, repeats, per in (("training step", step, STEPS, "step"), ("Fisher blocks of one view", fisher, 1,
                                                                             "view")):
        print(f"\n== {name}: torch.profiler counts of one call")
        totals, sites = profile_copies(fn, args.device)
        for key, value in totals.items():
            print(f"  {key:40s} {value}")
        print(f"== {name}: scalar reads and nonzero by source line (torch.profiler stacks)")
        for where, count in sites.most_common():
            print(f"  {count:6d}  {where}")
        if args.device != "cuda":
            print("  (CPU: no host syncs exist; run with --device cuda on a GPU for the sync report)")
            continue
        counts = count_syncs(fn, repeats)
        print(f"== {name}: synchronising calls per {per} (sync debug mode), {sum(counts.values()) / repeats:.1f} "
              "in all")
        for where, count in counts.most_common():
            print(f"  {count / repeats:8.1f}  {where}")


if __name__ == "__main__":
    run_cli(main)
