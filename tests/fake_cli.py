"""A stand-in interpreter for the grid's CLI calls (`grid.py --python FAKE`): records each train/render/metrics
call as a JSON line in $FAKE_LOG and writes the files the real CLIs would (selection.json with closed-form oracle
counts, run_status.json, results.json). $FAKE_FAIL (':'-separated model paths) makes train.py fail with an
`error:` line; $FAKE_SLEEP seconds are spent in train.py after it made checkpoints/ and wrote its progress to
run_status.json (iteration 7, 123 Gaussians), unless checkpoints/ existed (a resumed run)."""
from __future__ import annotations

import os
import sys
from pathlib import Path

from tests.conftest import ROOT

POOL = 20  # training views of the fake scenes

FAKE = r'''#!{python}
import argparse, json, os, sys, time
from pathlib import Path
args = sys.argv[1:]
with open(os.environ["FAKE_LOG"], "a") as fh:
    threads = "OMP_NUM_THREADS=" + os.environ.get("OMP_NUM_THREADS", "")
    fh.write(json.dumps([Path(args[0]).name] + args[1:] + [threads]) + "\n")
p = argparse.ArgumentParser()
for name in ["-s", "-m", "-r", "--device", "--seed", "--method", "--eps", "--num_init_views", "--views_per_step",
             "--max_views", "--iters_per_view", "--iterations", "--num_random_points"]:
    p.add_argument(name)
a, _ = p.parse_known_args(args[1:])
model = Path(a.m)
if Path(args[0]).name == "train.py":
    if str(model) in os.environ.get("FAKE_FAIL", "").split(":"):
        print("error: fake failure of " + str(model), file=sys.stderr)
        sys.exit(2)
    if not (model / "checkpoints").is_dir():  # a resumed run (checkpoints on disk) does not sleep again
        (model / "checkpoints").mkdir(parents=True)
        (model / "run_status.json").write_text(json.dumps({{"status": "running", "iteration": 7,
            "total_iterations": int(a.iterations), "num_gaussians": 123, "updated": "now"}}))
        time.sleep(float(os.environ.get("FAKE_SLEEP", "0")))
    import math  # closed-form counts written out here (importing the active package would import torch)
    def step_count(method, m, k, eps):
        if method == "pop_gs":
            return sum(m - j for j in range(k))
        if method == "lite_gs":
            return sum(min(m - j, max(1, math.floor((m - j) * math.log(1 / eps) / k))) for j in range(k))
        if method == "ssg":
            p = min(m, max(k, math.floor(m * math.log(1 / eps) / k)))
            return sum(p - j for j in range(k))
        return 0
    n0, k, vmax = int(a.num_init_views), int(a.views_per_step), int(a.max_views)
    eps = float(a.eps) if a.eps else 0.1
    views, stages = list(range(n0)), []
    while len(views) < vmax:
        step = min(k, vmax - len(views))
        count = step_count(a.method, {pool} - len(views), step, eps)
        stages.append({{"stage": len(stages), "train_views": list(views), "candidates": {pool} - len(views),
                       "selected": list(range(len(views), len(views) + step)), "test_psnr": 10.0,
                       "oracle_calls": {{"conservative": count, "evaluated": count}},
                       "fisher_seconds": 0.0, "select_seconds": 0.0}})
        views += stages[-1]["selected"]
    model.mkdir(parents=True, exist_ok=True)
    options = {{"eps": eps}} if a.eps else {{}}
    (model / "selection.json").write_text(json.dumps({{"config": {{"method": a.method, "selector_options": options,
        "views_per_step": k, "seed": int(a.seed)}}, "stages": stages}}))
    (model / "run_status.json").write_text(json.dumps({{"status": "complete", "iteration": int(a.iterations)}}))
    (model / "cfg_args").write_text(json.dumps({{"method": a.method, "seed": int(a.seed)}}))
elif Path(args[0]).name == "render.py":
    status = json.loads((model / "run_status.json").read_text())
    rendered = model / "test" / "ours_{{}}".format(status["iteration"])
    (rendered / "renders").mkdir(parents=True, exist_ok=True)
    if "--uncertainty" in args:
        (rendered / "uncertainty" / "fisherrf").mkdir(parents=True)
elif Path(args[0]).name == "metrics.py":
    status = json.loads((model / "run_status.json").read_text())
    rendered = model / "test" / "ours_{{}}".format(status["iteration"])
    entry = {{"PSNR": 20.0 + int(model.name[4:]), "SSIM": 0.8, "LPIPS": None}}
    if (rendered / "uncertainty").is_dir():
        entry.update({{"Spearman/fisherrf/object": 0.5, "AUSE_MAE_norm/fisherrf/object": 0.01 * (1 + int(model.name[4:])),
                      "uncertainty_object_region": "pixels"}})
    (model / "results.json").write_text(json.dumps({{"ours_{{}}".format(status["iteration"]): entry}}))
'''


def make_fake(tmp_path: Path) -> tuple[dict, Path, Path, Path]:
    """(env, fake interpreter, data root with Blender-like scenes ship and lego, call log)."""
    python = tmp_path / "fake_python"
    python.write_text(FAKE.format(python=sys.executable, pool=POOL, root=ROOT))
    python.chmod(0o755)
    data = tmp_path / "data"
    for scene in ("ship", "lego"):
        (data / scene).mkdir(parents=True)
        (data / scene / "transforms_train.json").write_text("{}")
    log = tmp_path / "calls.jsonl"
    env = {**os.environ, "FAKE_LOG": str(log), "PYTHONPATH": str(ROOT)}
    return env, python, data, log


def calls(log: Path, cli: str) -> list[list[str]]:
    """The recorded calls of one CLI (train.py, render.py, metrics.py), in order."""
    import json
    if not log.exists():
        return []
    return [c for c in map(json.loads, log.read_text().splitlines()) if c[0] == cli]


def option(call: list[str], name: str) -> str:
    return call[call.index(name) + 1]
