"""scripts/grid.py's command line: its parser and the checks that turn it into a `GridConfig`."""
from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

from experiments.grid_config import GridConfig, SlurmOptions
from experiments.protocols import DEFAULT_EPS, PROTOCOLS, RunScale, expand
from utils.errors import UserError

ROOT = Path(__file__).resolve().parents[1]
LAUNCHERS = ("local", "slurm", "inline")


def build_parser(description: str | None = None) -> argparse.ArgumentParser:
    """scripts/grid.py's parser (every value is checked by `parse`)."""
    p = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--setup", required=True, help=f"protocol: {', '.join(PROTOCOLS)} (see experiments/protocols.py)")
    p.add_argument("--data", default=str(ROOT.parent / "shared" / "data"),
                   help="dataset root holding one directory per scene (default: ../shared/data)")
    p.add_argument("--scenes", nargs="+", default=None, help="scene directories under --data (default: the setup's)")
    p.add_argument("--methods", nargs="+", default=None,
                   help="selectors to compare (default: the setup's; see train.py --help for the registered ones)")
    p.add_argument("--seeds", default="1", help="number of seeds, run as 0..N-1 (default: 1)")
    p.add_argument("--out", default=str(ROOT / "output" / "experiments"),
                   help="output root (default: output/experiments)")
    p.add_argument("--launcher", default="local", help="local (submitit processes), slurm (submitit arrays) or "
                   "inline (this process, one job at a time; for debugging) (default: local)")
    p.add_argument("--max_parallel", default=None, help="jobs at a time (local: default 1; slurm: the array's "
                   "parallelism limit, default all)")
    p.add_argument("--threads", default=None, help="torch/BLAS/numba threads per job (default: local and inline "
                   "floor(cores / max_parallel), slurm --cpus_per_job)")
    p.add_argument("--resolution", default="8", help="train.py -r (default 8: 100 px for 800 px Blender scenes)")
    p.add_argument("--iter_scale", default="0.1", help="multiplies iterations per view, total iterations, the "
                   "densification start (500) and the opacity-reset interval (3000), rounded, at least 1; "
                   "1 = paper (default: 0.1)")
    p.add_argument("--stage_scale", default=None, help="multiplies the stages before each selection (iterations per "
                   "view, densification start, opacity-reset interval) instead of --iter_scale, which then scales "
                   "only the final refinement (the paper's total minus its stages); 1 = the paper's stage lengths "
                   "(default: --iter_scale for everything)")
    p.add_argument("--num_points", default="3000", help="random initial points for synthetic scenes "
                   "(paper: 100000; default: 3000)")
    p.add_argument("--eps", default=str(DEFAULT_EPS), help="eps of the methods that take one, where the protocol "
                   "does not sweep it (default: 0.1)")
    p.add_argument("--device", default="auto", help="auto (cuda when the job's machine has one), cpu or cuda")
    p.add_argument("--slurm_partition", default=None, help="slurm: partition")
    p.add_argument("--gpus_per_job", default="0", help="slurm: GPUs per job (default 0)")
    p.add_argument("--cpus_per_job", default="2", help="slurm: CPUs per job (default 2)")
    p.add_argument("--time_min", default="1440", help="per-job time limit in minutes; on timeout or preemption a "
                   "job stops at its last stage checkpoint and is requeued (default 1440)")
    p.add_argument("--python", default=sys.executable, help="interpreter for train.py/render.py/metrics.py "
                   "(default: this one)")
    p.add_argument("--uncertainty", action="store_true",
                   help="render the uncertainty maps too (render.py --uncertainty); results.json and the summary "
                        "then carry Spearman and AUSE (a rerun with it adds them to finished runs)")
    p.add_argument("--report", action="store_true",
                   help="after the summary, write the grid report OUT/<setup>/report.html and every run's report.html "
                        "(as report.py --grid OUT/<setup>)")
    p.add_argument("--progress_every", default="300",
                   help="seconds between the progress lines of running jobs (iteration, Gaussians; default 300)")
    p.add_argument("--dry_run", action="store_true", help="print the jobs (slurm: also write the sbatch file) "
                   "without running anything")
    return p


def _int(name: str, text: str, minimum: int) -> int:
    try:
        value = int(text)
    except ValueError:
        value = minimum - 1
    if value < minimum:
        raise UserError(f"--{name} must be an integer >= {minimum}, got {text!r}")
    return value


def _float(name: str, text: str, low: float, high: float | None = None) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (value > low and (high is None or value < high)):
        bounds = f"in ({low:g}, {high:g})" if high is not None else f"> {low:g}"
        raise UserError(f"--{name} must be a number {bounds}, got {text!r}")
    return value


def _words(values: list[str] | None, default: tuple[str, ...]) -> list[str]:
    """Names given as separate arguments or as one quoted, space-separated argument (the old scripts' form)."""
    words = [w for v in values for w in v.split()] if values is not None else list(default)
    return list(dict.fromkeys(words))


def parse(argv: list[str], description: str | None = None) -> GridConfig:
    """Validate scripts/grid.py's command line into a GridConfig (UserError on bad input)."""
    if "--" in argv:
        cut = argv.index("--")
        argv, extra = argv[:cut], argv[cut + 1:]
    else:
        extra = []
    args = build_parser(description).parse_args(argv)
    if args.setup not in PROTOCOLS:
        raise UserError(f"unknown --setup {args.setup!r}; choose one of: {', '.join(PROTOCOLS)}")
    if args.launcher not in LAUNCHERS:
        raise UserError(f"unknown --launcher {args.launcher!r}; choose one of: {', '.join(LAUNCHERS)}")
    if args.device not in ("auto", "cpu", "cuda"):
        raise UserError(f"--device must be auto, cpu or cuda, got {args.device!r}")
    protocol = PROTOCOLS[args.setup]
    seeds = _int("seeds", args.seeds, 1)
    scale = RunScale(resolution=_int("resolution", args.resolution, -1),
                     iter_scale=_float("iter_scale", args.iter_scale, 0.0),
                     num_points=_int("num_points", args.num_points, 1),
                     stage_scale=None if args.stage_scale is None else _float("stage_scale", args.stage_scale, 0.0))
    if scale.resolution == 0:
        raise UserError("--resolution must be -1 (as is), 1/2/4/8 (downscale) or a target width, got 0")
    eps = _float("eps", args.eps, 0.0, 1.0)
    data, out = Path(args.data).resolve(), Path(args.out).resolve()
    scenes = _words(args.scenes, protocol.default_scenes)
    methods = _words(args.methods, protocol.default_methods)
    if not scenes or not methods:
        raise UserError("--scenes and --methods need at least one name each")
    found = sorted(p.name for p in data.iterdir() if p.is_dir()) if data.is_dir() else []
    for scene in scenes:
        if not (data / scene).is_dir():
            raise UserError(f"scene directory {data / scene} not found; scenes in {data}: {' '.join(found) or 'none'} "
                            "(use --data / --scenes)")
    import active  # noqa: F401  (registers the selectors)
    from active.registry import list_selectors, selector_options
    for method in methods:
        if method not in list_selectors():
            raise UserError(f"unknown method {method!r}; registered selectors: {', '.join(list_selectors())}")

    def takes_eps(method: str) -> bool:
        return "eps" in selector_options(method)

    runs = expand(args.setup, scenes, methods, seeds, eps, takes_eps)
    if args.max_parallel is None:
        max_parallel = 1 if args.launcher != "slurm" else max(1, len(runs))
    else:
        max_parallel = _int("max_parallel", args.max_parallel, 1)
    if args.launcher == "inline" and max_parallel > 1:
        raise UserError("--launcher inline runs one job at a time; use --launcher local for --max_parallel > 1")
    slurm = SlurmOptions(partition=args.slurm_partition, gpus_per_job=_int("gpus_per_job", args.gpus_per_job, 0),
                         cpus_per_job=_int("cpus_per_job", args.cpus_per_job, 1),
                         time_min=_int("time_min", args.time_min, 1))
    if args.launcher == "slurm" and not args.dry_run and shutil.which("sbatch") is None:
        raise UserError("--launcher slurm needs sbatch on PATH (a Slurm login node); use --dry_run to write the "
                        "sbatch file, or --launcher local")
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if args.threads is not None:
        threads = _int("threads", args.threads, 1)
    elif args.launcher == "slurm":
        threads = slurm.cpus_per_job
    else:
        threads = max(1, cores // max_parallel)
    device = args.device
    if device == "auto" and args.launcher != "slurm":  # same machine as the jobs: decide once
        import torch
        device = "cuda" if torch.cuda.is_available() else "cpu"
    cfg = GridConfig(setup=args.setup, data=data, out=out, runs=tuple(runs), scale=scale, device=device,
                     extra_args=tuple(extra), launcher=args.launcher, max_parallel=max_parallel, threads=threads,
                     python=str(Path(args.python).absolute()) if os.sep in args.python else args.python,
                     slurm=slurm, dry_run=args.dry_run, uncertainty=args.uncertainty, report=args.report,
                     progress_every_s=_float("progress_every", args.progress_every, 0.0))
    return cfg
