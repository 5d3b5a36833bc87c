"""The closed capture loop on the built-in scene (CLI scripts/capture_loop.py, docs/recommend.md): per method and seed,
train on the views captured so far (train.py), recommend K of N generated hemisphere poses (`recommender`, no
images), "capture" them by rendering the built-in ground truth there, repeat up to the view budget; then the
PSNR-vs-views plot. Each (method, seed) writes OUT/METHOD/seedS/loop.json."""
from __future__ import annotations

import argparse
import json
import logging
import math
import random
import shutil
import sys
import time
from pathlib import Path

import torch

from experiments.jobs import error_line
from experiments.method_spec import selector_from_spec
from recommender.outputs import write_outputs
from recommender.pipeline import candidate_cameras, load_model, make_pool, recommend
from recommender.pipeline import log as recommend_log
from scene.builtin import CAMERA_ANGLE_X, hemisphere_positions, make_builtin_scene, render_rgba, scene_gaussians
from scene.cameras import look_at
from scene.frames import GL_TO_CV
from utils import model_dir
from utils.errors import UserError
from utils.image import save_image
from utils.io import read_json, write_json


def capture(dataset: Path, viewmats: list[torch.Tensor], resolution: int, seed: int, start: int) -> list[dict]:
    """Render the built-in ground truth at `viewmats` into dataset/train/c_NNN.png; the new transforms frames."""
    focal = 0.5 * resolution / math.tan(0.5 * CAMERA_ANGLE_X)
    intrinsics = torch.tensor([focal, focal, resolution / 2, resolution / 2])
    gaussians = scene_gaussians(seed)
    frames = []
    for i, viewmat in enumerate(viewmats):
        name = f"c_{start + i:03d}"
        save_image(render_rgba(viewmat.double(), intrinsics, resolution, resolution, seed, gaussians),
                   dataset / "train" / f"{name}.png")
        c2w = torch.linalg.inv(viewmat.double()) @ GL_TO_CV
        frames.append({"file_path": f"./train/{name}", "transform_matrix": c2w.tolist()})
    return frames


SEED_STARTS = ("first", "random")  # the start views: the fixed spiral, or the spiral turned by a seed-drawn azimuth


def start_positions(seed_start: str, seed: int, count: int = 3) -> torch.Tensor:
    """The loop's first `count` camera centres: `hemisphere_positions(count, 0.5)`, turned about the up axis (+z) by
    an azimuth drawn with `seed` when `seed_start` is "random" (then each seed starts from other views, so a
    deterministic selector's seeds are different view sets). [count, 3] float64"""
    positions = hemisphere_positions(count, 0.5)
    if seed_start == "first":
        return positions
    angle = random.Random(seed).uniform(0.0, 2 * math.pi)
    c, s = math.cos(angle), math.sin(angle)
    turn = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    return positions @ turn.T


def train(dataset: Path, model: Path, iterations: int, seed: int, max_gaussians: int, num_random_points: int) -> float:
    """train.py on every captured view (from scratch, `num_random_points` random initial points); returns the test
    PSNR."""
    import subprocess
    root = Path(__file__).resolve().parents[1]
    cmd = [sys.executable, str(root / "train.py"), "-s", str(dataset), "-m", str(model), "--eval", "--iterations",
           str(iterations), "--seed", str(seed), "--max_gaussians", str(max_gaussians), "--quiet", "--overwrite",
           "--num_random_points", str(num_random_points),
           "--densify_from_iter", "100", "--densification_interval", "50"]
    done = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
    if done.returncode != 0:
        reason = error_line(done.stderr or done.stdout).removeprefix("error: ")
        raise UserError(f"train.py failed on {dataset}: {reason}")
    return read_json(model / model_dir.RUN_STATUS)["test_psnr"]


# Flags that do not change a loop's result; every other flag must agree between loops resumed or tabled together
NOT_PROTOCOL = ("methods", "seeds", "output", "plot", "png", "overwrite")
# Flags added after loops were committed: a loop.json without one ran with this value
ADDED_LATER = {"elevation": [0.0, 80.0], "seed_start": "first", "num_random_points": 10_000}


def protocol(settings: dict) -> dict:
    """The flags of a loop's `settings` that decide its result, as JSON values, flags added later filled in."""
    chosen = ADDED_LATER | {k: v for k, v in settings.items() if k not in NOT_PROTOCOL}
    return json.loads(json.dumps(chosen))  # tuples as lists, as loop.json holds them


def protocol_difference(a: dict, b: dict) -> str | None:
    """The first flag whose value differs between two loops' settings, as "--flag A against B"; None if none."""
    pa, pb = protocol(a), protocol(b)
    for key in sorted(pa.keys() | pb.keys()):
        if pa.get(key) != pb.get(key):
            return f"--{key} {pa.get(key)} against {pb.get(key)}"
    return None


def run_loop(method: str, seed: int, out: Path, args: argparse.Namespace) -> dict:
    """One closed loop; writes out/loop.json when it has finished. A finished loop of the same flags is kept (an
    interrupted run resumes at its first unfinished loop), one of other flags is an error unless --overwrite."""
    done = out / "loop.json"
    if done.is_file() and not args.overwrite:
        previous = read_json(done, fix="delete it to run the loop again")
        difference = protocol_difference(previous.get("settings", {}), vars(args))
        if difference:
            raise UserError(f"{done} ran with other flags ({difference}): give another -o, or --overwrite to run "
                            "it again")
        print(f"{method} seed {seed}: finished before, kept ({done})", flush=True)
        return previous
    if out.exists():
        shutil.rmtree(out)
    dataset = out / "data"
    (dataset / "train").mkdir(parents=True)
    builtin = make_builtin_scene(out.parent.parent / f"builtin_r{args.resolution}", 0, args.resolution, 3,
                                 args.num_test)
    shutil.copytree(builtin / "test", dataset / "test")
    shutil.copy(builtin / "transforms_test.json", dataset / "transforms_test.json")
    start = [look_at(eye) for eye in start_positions(args.seed_start, seed)]
    frames = capture(dataset, start, args.resolution, 0, 0)
    rounds = []
    while True:
        write_json(dataset / "transforms_train.json", {"camera_angle_x": CAMERA_ANGLE_X, "frames": frames})
        t0 = time.perf_counter()
        model_path = out / "model"
        psnr = train(dataset, model_path, args.iters_per_view * len(frames), seed, args.max_gaussians,
                     args.num_random_points)
        train_s = time.perf_counter() - t0
        record = {"views": len(frames), "test_psnr": psnr, "train_seconds": train_s}
        rounds.append(record)
        print(f"{method} seed {seed}: {len(frames)} views, test PSNR {psnr:.2f} dB", flush=True)
        if len(frames) >= args.budget:
            break
        t0 = time.perf_counter()
        model = load_model(model_path)
        pool = make_pool(model, candidate_cameras(f"hemisphere:{args.candidates}", model, elevation=args.elevation))
        k = min(args.k, args.budget - len(frames))
        rec = recommend(model, pool, selector_from_spec(method), k, seed=seed * 1000 + len(rounds))
        write_outputs(rec, model, out / f"recommend_{len(frames):02d}", candidates_spec=f"hemisphere:{args.candidates}",
                      previews=False)
        record["recommend_seconds"] = time.perf_counter() - t0
        record["oracle_evaluated"] = rec.acquisition.evaluated if rec.acquisition else 0
        frames += capture(dataset, [pool.cameras[v].viewmat.cpu() for v in rec.picks], args.resolution, 0,
                          len(frames))
    result = {"method": method, "seed": seed, "rounds": rounds, "settings": vars(args) | {"plot": None}}
    write_json(out / "loop.json", result)
    return result


def loop_results(root: Path) -> dict[str, tuple[list[int], torch.Tensor]]:
    """Per method folder of `root`: the view counts of its rounds and the test PSNR of every seed [S, R]."""
    out, first = {}, None
    for method_dir in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("builtin")):
        paths = sorted(method_dir.glob("seed*/loop.json"))
        runs = [read_json(p, fix="rerun scripts/capture_loop.py to write it again") for p in paths]
        for path, run in zip(paths, runs):  # one table, one protocol
            first = first or (path, run.get("settings", {}))
            difference = protocol_difference(run.get("settings", {}), first[1])
            if difference:
                raise UserError(f"{path} and {first[0]} ran with different flags ({difference}): table them from "
                                "separate folders")
        if runs:
            out[method_dir.name] = ([r["views"] for r in runs[0]["rounds"]],
                                    torch.tensor([[r["test_psnr"] for r in run["rounds"]] for run in runs]))
    return out


def summary_table(root: Path) -> str:
    """Markdown: one row per method, test PSNR mean +- std over seeds at each view count."""
    results = loop_results(root)
    views = next(iter(results.values()))[0] if results else []
    lines = ["| method | seeds | " + " | ".join(f"{v} views" for v in views) + " |",
             "|---|---|" + "---|" * len(views)]
    for method, (_, values) in results.items():
        cells = [f"{float(m):.2f} ± {float(s):.2f}" for m, s in zip(values.mean(0), values.std(0, correction=0))]
        lines.append(f"| {method} | {values.shape[0]} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot(root: Path, png: Path) -> None:
    """PSNR vs views, mean and min/max over seeds, one line per method."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for method, (views, values) in loop_results(root).items():
        ax.plot(views, values.mean(0), marker="o", label=f"{method} ({values.shape[0]} seeds)")
        ax.fill_between(views, values.min(0).values, values.max(0).values, alpha=0.15)
    ax.set_xlabel("captured views")
    ax.set_ylabel("test PSNR (dB)")
    ax.set_title("Closed capture loop on the built-in scene")
    ax.grid(alpha=0.3)
    ax.legend()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


class FirstNoteOnly(logging.Filter):
    """Passes the first `note:` record and every other record: a method's advice note is printed once, not once per
    round and seed (its text names the captured-view count, which changes every round)."""

    def __init__(self) -> None:
        super().__init__()
        self.noted = False

    def filter(self, record: logging.LogRecord) -> bool:
        if not record.getMessage().startswith("note:"):
            return True
        if self.noted:
            return False
        self.noted = True
        return True


def run_capture_loop(args: argparse.Namespace) -> None:
    """scripts/capture_loop.py's parsed flags (`args`): only the summary and plot of `args.plot`'s folder, or every
    (method, seed) loop into `args.output`, then its summary.md and the plot (`args.png`, default: psnr_vs_views.png
    in that folder)."""
    png = Path(args.png) if args.png else Path(args.plot or args.output) / "psnr_vs_views.png"
    if args.plot:
        root = Path(args.plot)
        if not root.is_dir() or not loop_results(root):
            raise UserError(f"--plot {root}: no loops there (METHOD/seedN/loop.json); give the -o folder of a "
                            "finished scripts/capture_loop.py run")
        write_summary(root)
        plot(root, png)
        return
    root = Path(args.output)
    for method in args.methods:
        selector_from_spec(method)  # a bad name or option: one error line before any loop runs
    for method in args.methods:
        once = FirstNoteOnly()
        recommend_log.addFilter(once)
        try:
            for seed in args.seeds:
                run_loop(method, seed, root / method / f"seed{seed}", args)
        finally:
            recommend_log.removeFilter(once)
    write_summary(root)
    plot(root, png)


def write_summary(root: Path) -> None:
    """`summary_table` of the loops under `root` into root/summary.md, and printed."""
    (root / "summary.md").write_text(summary_table(root))
    print((root / "summary.md").read_text())

