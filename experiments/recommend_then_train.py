"""The pieces of scripts/recommend_then_train.py: a seed-view dataset without the candidates' images, the runs of the
project's CLIs, and the summary table (recommend from poses alone, then train on the picks)."""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import torch

from active.schedule import farthest_point_views
from experiments.jobs import THREAD_VARS
from scene.pose_files import read_pose_file
from utils.errors import UserError
from utils.io import write_json

ROOT = Path(__file__).resolve().parents[1]
IMAGE_EXTENSIONS = (".png", ".jpg", "")  # a Blender frame's file_path names its image without (or with) one


def make_seed_dataset(data: Path, out: Path, num_seed: int) -> tuple[list[int], list[int]]:
    """OUT/data: transforms_train.json with the `num_seed` seed frames, the test split, links to those images only,
    and candidates.json (the other training frames, whose images are not linked). Returns (seed ids, candidate ids)
    as indices of DATA/transforms_train.json."""
    train = json.loads((data / "transforms_train.json").read_text())
    test = json.loads((data / "transforms_test.json").read_text())
    frames = train["frames"]
    centers = torch.stack([c.camera_center for c in read_pose_file(data / "transforms_train.json",
                                                                   default_size=(800, 800))])
    seeds = farthest_point_views(centers.double(), num_seed)
    candidates = [v for v in range(len(frames)) if v not in seeds]
    folder = out / "data"
    for frame in [frames[v] for v in seeds] + test["frames"]:
        for ext in IMAGE_EXTENSIONS:
            src = data / (frame["file_path"] + ext)
            if src.is_file():
                dst = folder / (frame["file_path"] + ext)
                dst.parent.mkdir(parents=True, exist_ok=True)
                if not dst.exists():
                    dst.symlink_to(src.resolve())
                break
        else:
            raise UserError(f"{data}: no image for frame {frame['file_path']!r}")
    write_json(folder / "transforms_train.json", {**train, "frames": [frames[v] for v in seeds]})
    write_json(folder / "transforms_test.json", test)
    write_json(folder / "candidates.json", {**train, "frames": [frames[v] for v in candidates]})
    present = [v for v in candidates
               if any((folder / (frames[v]["file_path"] + e)).exists() for e in IMAGE_EXTENSIONS)]
    if present:
        raise UserError(f"{folder}: candidate images are present ({present[:5]}); remove them")
    return seeds, candidates


def method_args(spec: str) -> list[str]:
    """recommend.py's selector flags for a method spec NAME[+OPTION=VALUE...], e.g. "pop_gs+gain_weight=opacity"
    -> ["--method", "pop_gs", "--gain_weight", "opacity"]; the spec itself labels the results."""
    name, *options = spec.split("+")
    flags = ["--method", name]
    for option in options:
        key, sep, value = option.partition("=")
        if not sep or not key or not value:
            raise UserError(f"method {spec!r}: write selector options as NAME+OPTION=VALUE (e.g. pop_gs+gain_weight=opacity)")
        flags += [f"--{key}", value]
    return flags


def run(cmd: list[str], threads: int, log: Path) -> float:
    """Run one CLI of the project with `threads` threads; its output goes to `log`. Returns the wall seconds."""
    env = {**os.environ, **{v: str(threads) for v in THREAD_VARS}}
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        proc = subprocess.run([sys.executable, *cmd], cwd=ROOT, env=env, stdout=fh, stderr=subprocess.STDOUT)
    if proc.returncode != 0:
        tail = "".join(log.read_text().splitlines(keepends=True)[-5:])
        raise UserError(f"{' '.join(cmd[:2])} failed (log {log}):\n{tail}")
    return time.perf_counter() - t0


def summary_table(results: dict, methods: list[str], seeds: list[int]) -> str:
    """Per-seed test PSNR and mean +- std per method, with the picks and oracle counts."""
    s = results["settings"]
    lines = [f"Seed views {s['seed_views']} ({s['base_iterations']} iterations: base test PSNR "
             f"{s['base_test_psnr']:.2f} dB); +{s['k']} views from {s['candidates']} candidate poses, then "
             f"{s['iterations']} iterations from the base model (`--init_ply`), -r {s['resolution']}, "
             f"`{s['train_args']}`.", "",
             "| added views from | " + " | ".join(f"seed {x}" for x in seeds) + " | mean ± std | picks (seed "
             f"{seeds[0]}) | oracles evaluated / conservative |",
             "|---|" + "---|" * len(seeds) + "---|---|---|"]
    for m in methods:
        rows = [results[f"{m}/seed{x}"] for x in seeds]
        values = [r["test_psnr"] for r in rows]
        spread = statistics.stdev(values) if len(values) > 1 else 0.0
        calls = rows[0].get("oracle_calls")
        lines.append(f"| {m} | " + " | ".join(f"{v:.2f}" for v in values)
                     + f" | {statistics.mean(values):.2f} ± {spread:.2f} | {rows[0].get('picks', '–')} | "
                     + (f"{calls['evaluated']} / {calls['conservative']}" if calls else "–") + " |")
    return "\n".join(lines) + "\n"
