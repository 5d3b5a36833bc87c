"""Rasterizer speed: the tiled fast path vs the dense autograd reference, and `attribute_gram` vs a training step.

    python benchmarks/bench_rasterize.py [--presets 2k@128 10k@256 garden] [--repeats 5] [--threads 2]
        [--backends torch,compiled] [--rounds 3] [--json PATH]
    python benchmarks/bench_rasterize.py --resolution_scaling [--model output/lego] [--widths 200 400 800]
        [--backends compiled]

Inputs are already-projected 2D Gaussians (what `rasterize` consumes). Synthetic presets `<N>@<size>` draw N
anisotropic Gaussians uniformly over a size x size image (sigma log-uniform in [0.5, 5] px at 128 px, scaled
with the image), opacity uniform in [0.05, 1). `garden` projects the real Mip-NeRF 360 garden SfM points of
../shared/data/gsplat_garden/test_garden.npz (3DGS initialisation: scale from the 3 nearest neighbours,
opacity 0.1) into its first camera at 1/4 resolution.

Timed (warm-up, then the median of R runs): fast forward (no grad), fast forward+backward (one training step
of the rasterizer), the dense reference forward+backward (only where N x H x W <= --ref_max_pairs), and
`attribute_gram` (one view's Fisher-ready Gram matrices). Prints a table and writes JSON to benchmarks/results/
(or --json PATH): one row per (preset, backend) with fwd_ms, fwd_bwd_ms, gram_ms. With several --backends each
runs in its own process (numba's and torch's thread pools never share one) and a torch/compiled ratio table follows;
`--rounds R` alternates the backend processes R times and reports median times and the median (and range) of the
per-round ratios, which a noisy shared machine moves far less than the times themselves.

`--resolution_scaling` times instead one whole training step (render forward + L1/SSIM loss + backward) of a
fixed set of 3D Gaussians from one view of a Blender scene (`--source`, default ../shared/data/lego) at each of
`--widths`, for two models: train.py's fresh random initialisation (`--num_random_points`, seed 0) and, with
`--model`, a trained one (a train.py model directory, its newest iteration). The ratio column is the step time over
the previous width's; with the pixel count growing 4x per doubling, a ratio near 4 means the cost is linear in pixels.
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from gaussian_renderer.fisher_partials import attribute_gram
from gaussian_renderer.rasterize import bin_gaussians, rasterize
from gaussian_renderer.reference import rasterize_reference
from gaussian_renderer.settings import RasterSettings
from utils.errors import run_cli
from utils.io import read_json

GARDEN = Path(__file__).resolve().parents[2] / "shared" / "data" / "gsplat_garden" / "test_garden.npz"
LEGO = Path(__file__).resolve().parents[2] / "shared" / "data" / "lego"
Inputs = tuple  # (means2d [N,2], conics [N,3], opacities [N], colors [N,3], depths [N], radii [N], W, H, bg [3])


def median_time(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time of `repeats` calls after one warm-up call, in seconds."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def synthetic_inputs(n: int, size: int, seed: int = 0) -> Inputs:
    """N random anisotropic 2D Gaussians over a size x size image (float32)."""
    g = torch.Generator().manual_seed(seed)
    means2d = torch.rand(n, 2, generator=g) * size
    scale = size / 128
    sigmas = scale * torch.exp(torch.empty(n, 2).uniform_(math.log(0.5), math.log(5.0), generator=g))  # [N, 2]
    theta = torch.rand(n, generator=g) * math.pi
    rot = torch.stack([torch.cos(theta), -torch.sin(theta), torch.sin(theta), torch.cos(theta)], -1).reshape(n, 2, 2)
    cov = rot @ torch.diag_embed(sigmas ** 2) @ rot.transpose(1, 2)  # [N, 2, 2]
    inv = torch.linalg.inv(cov)
    conics = torch.stack([inv[:, 0, 0], inv[:, 0, 1], inv[:, 1, 1]], -1)
    radii = torch.ceil(3 * sigmas.max(dim=1).values).long()
    opacities = torch.rand(n, generator=g) * 0.95 + 0.05
    return (means2d, conics, opacities, torch.rand(n, 3, generator=g), torch.rand(n, generator=g) * 10 + 1, radii,
            size, size, torch.zeros(3))


def garden_inputs(max_points: int) -> Inputs:
    """The garden SfM points projected into camera 0 at 1/4 resolution (needs gaussian_renderer.projection)."""
    from gaussian_renderer.projection import project_gaussians
    from utils.knn import mean_sq_dist_to_neighbours

    data = np.load(GARDEN)
    points = torch.from_numpy(data["means3d"]).float()
    colors = torch.from_numpy(data["colors"]).float() / 255.0
    idx = torch.randperm(points.shape[0], generator=torch.Generator().manual_seed(0))[:max_points]
    points, colors = points[idx], colors[idx]
    scales = mean_sq_dist_to_neighbours(points, k=3).clamp_min(1e-7).sqrt()[:, None].repeat(1, 3)
    quats = torch.tensor([[1.0, 0.0, 0.0, 0.0]]).repeat(points.shape[0], 1)
    factor = 4
    k = torch.from_numpy(data["Ks"][0]).float()
    intrinsics = torch.stack([k[0, 0], k[1, 1], k[0, 2], k[1, 2]]) / factor
    width, height = int(data["width"]) // factor, int(data["height"]) // factor
    proj = project_gaussians(points, quats, scales, torch.from_numpy(data["viewmats"][0]).float(), intrinsics,
                             width, height)
    return (proj.means2d, proj.conics, torch.full((points.shape[0],), 0.1), colors, proj.depths, proj.radii,
            width, height, torch.zeros(3))


def bench(name: str, inputs: Inputs, settings: RasterSettings, repeats: int, ref_max_pairs: float) -> dict:
    """Time the four operations on one input set with `settings.backend`; returns one JSON row (s and ms)."""
    means2d, conics, opacities, colors, depths, radii, width, height, bg = inputs
    leaves = [t.clone().requires_grad_(True) for t in (means2d, conics, opacities, colors, bg)]

    def forward() -> None:
        with torch.no_grad():
            rasterize(means2d, conics, opacities, colors, depths, radii, width, height, bg, settings)

    def train_step(fn=rasterize) -> None:
        image, alpha = fn(*leaves[:4], depths, radii, width, height, leaves[4], settings)
        (image.sum() + alpha.sum()).backward()

    def gram() -> None:
        attribute_gram(means2d, conics, opacities, colors, depths, radii, width, height, bg, settings)

    bins = bin_gaussians(means2d, conics, opacities, radii, depths, width, height, settings)
    row = {"preset": name, "gaussians": means2d.shape[0], "visible": int((radii > 0).sum()), "width": width,
           "height": height, "tile_size": settings.tile_size, "chunk_size": settings.chunk_size,
           "pairs_per_tile_max": bins.lists.shape[1], "pairs": int((bins.lists >= 0).sum()),
           "forward_s": median_time(forward, repeats), "train_step_s": median_time(train_step, repeats),
           "gram_s": median_time(gram, repeats), "backend": settings.backend}
    row.update(fwd_ms=1e3 * row["forward_s"], fwd_bwd_ms=1e3 * row["train_step_s"], gram_ms=1e3 * row["gram_s"])
    if settings.backend == "torch" and row["visible"] * width * height <= ref_max_pairs:
        row["reference_step_s"] = median_time(lambda: train_step(rasterize_reference), max(1, repeats // 2))
    return row


def scaling_models(source: Path, model: str | None, num_points: int) -> list[tuple[str, object]]:
    """(name, GaussianModel) pairs: train.py's fresh random initialisation and, when given, a trained model."""
    from scene.scene import Scene
    from scene.trained import load_trained

    scene = Scene.load(str(source), Path("unused"), white_background=False, resolution=8, eval=False)
    init = scene.initial_point_cloud(num_points, seed=0)
    models = [("fresh", scene.new_gaussians(init, sh_degree=3, device="cpu"))]
    if model:
        models.append(("trained", load_trained(model).gaussians))
    return models


def resolution_scaling(args: argparse.Namespace, settings: RasterSettings) -> list[dict]:
    """Per-step time of each model at each width (one training step: render, loss, backward)."""
    from gaussian_renderer.renderer import render
    from scene.dataset_readers import load_scene_info
    from utils.losses import photometric_loss

    rows = []
    models = scaling_models(args.source, args.model, args.num_random_points)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, {platform.machine()}, "
          f"tile {settings.tile_size}, chunk {settings.chunk_size}, view {args.view} of {args.source}")
    print(f"{'model':8} {'gaussians':>9} {'width':>6} {'pairs':>10} {'step ms':>9} {'x prev':>7} {'pixels x':>8}")
    for width in args.widths:
        camera = load_scene_info(str(args.source), resolution=width).train_cameras[args.view]
        bg = torch.zeros(3)
        for name, gaussians in models:
            def step() -> None:
                out = render(camera, gaussians, bg, settings)
                loss = photometric_loss(out.image, camera.image)
                loss.backward()
                for p in gaussians.params.values():
                    p.grad = None

            proj_pairs = _pair_count(gaussians, camera, settings)
            row = {"model": name, "gaussians": gaussians.num_gaussians, "width": camera.width,
                   "height": camera.height, "pairs": proj_pairs, "train_step_s": median_time(step, args.repeats)}
            prev = [r for r in rows if r["model"] == name]
            if prev:
                row["ratio"] = row["train_step_s"] / prev[-1]["train_step_s"]
                row["pixel_ratio"] = camera.width * camera.height / (prev[-1]["width"] * prev[-1]["height"])
            rows.append(row)
            ratio = f"{row['ratio']:7.2f} {row['pixel_ratio']:8.2f}" if prev else f"{'':7} {'':8}"
            print(f"{name:8} {row['gaussians']:9d} {camera.width:6d} {proj_pairs:10d} "
                  f"{1e3 * row['train_step_s']:9.0f} {ratio}", flush=True)
    return rows


@torch.no_grad()
def _pair_count(gaussians, camera, settings: RasterSettings) -> int:
    """Tile-Gaussian pairs of one view (the binning's work)."""
    from gaussian_renderer.projection import project_gaussians

    proj = project_gaussians(gaussians.means, gaussians.unit_quats, gaussians.scales, camera.viewmat,
                             camera.intrinsics, camera.width, camera.height)
    bins = bin_gaussians(proj.means2d, proj.conics, gaussians.opacities, proj.radii, proj.depths, camera.width,
                         camera.height, settings)
    return int((bins.lists >= 0).sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--presets", nargs="+", default=["2k@128", "10k@128", "50k@128", "2k@256", "10k@256",
                                                         "50k@256", "garden"],
                        help="<N>@<size> (k = 1000) or 'garden'")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's choice)")
    parser.add_argument("--tile_size", type=int, default=RasterSettings.tile_size)
    parser.add_argument("--chunk_size", type=int, default=RasterSettings.chunk_size)
    parser.add_argument("--garden_points", type=int, default=50_000, help="SfM points used from the garden scene")
    parser.add_argument("--ref_max_pairs", type=float, default=4e7,
                        help="run the dense reference only when visible N x H x W is at most this (memory)")
    parser.add_argument("--resolution_scaling", action="store_true",
                        help="time one training step of fixed 3D Gaussians at each of --widths instead")
    parser.add_argument("--source", type=Path, default=LEGO, help="Blender scene for --resolution_scaling")
    parser.add_argument("--model", default=None, help="trained model directory for --resolution_scaling")
    parser.add_argument("--widths", type=int, nargs="+", default=[200, 400, 800])
    parser.add_argument("--view", type=int, default=0, help="training view used by --resolution_scaling")
    parser.add_argument("--num_random_points", type=int, default=10_000, help="fresh model's points (train.py's)")
    parser.add_argument("--backends", default="torch",
                        help="comma-separated rasterizer backends to time: torch, compiled, auto")
    parser.add_argument("--rounds", type=int, default=1,
                        help="with several --backends: run them alternately this many times (noisy machines)")
    parser.add_argument("--json", default=None,
                        help="write the JSON here (default benchmarks/results/rasterize_<time>.json)")
    args = parser.parse_args()
    backends = args.backends.split(",")
    if args.resolution_scaling and len(backends) > 1:
        parser.error("--resolution_scaling times one backend at a time: pass --backends torch or --backends compiled")
    if len(backends) > 1:
        run_backends_apart(args, backends)
        return
    if args.threads:
        torch.set_num_threads(args.threads)
    settings = RasterSettings(tile_size=args.tile_size, chunk_size=args.chunk_size, backend=backends[0])
    if args.resolution_scaling:
        write_results("scaling", args, resolution_scaling(args, settings))
        return
    rows = []
    for preset in args.presets:
        if preset == "garden":
            if not GARDEN.is_file():
                print(f"skipping garden: {GARDEN} not found")
                continue
            inputs = garden_inputs(args.garden_points)
        else:
            count, size = preset.split("@")
            inputs = synthetic_inputs(int(float(count.lower().replace("k", "e3"))), int(size))
        rows.append(bench(preset, inputs, settings, args.repeats, args.ref_max_pairs))
        r = rows[-1]
        ref = r.get("reference_step_s")
        ref_cols = f"{1e3 * ref:10.0f} {ref / r['train_step_s']:7.0f}x" if ref else f"{'n/a':>10} {'n/a':>8}"
        if len(rows) == 1:
            print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, {platform.machine()}, "
                  f"tile {settings.tile_size}, chunk {settings.chunk_size}, backend {settings.backend}")
            print(f"{'preset':9} {'visible':>7} {'HxW':>9} {'pairs':>9} {'fwd ms':>8} {'fwd+bwd ms':>10} "
                  f"{'gram ms':>8} {'gram/step':>9} {'ref f+b ms':>10} {'speed-up':>8}")
        print(f"{r['preset']:9} {r['visible']:7d} {r['height']:4d}x{r['width']:<4d} {r['pairs']:9d} "
              f"{1e3 * r['forward_s']:8.1f} {1e3 * r['train_step_s']:10.1f} {1e3 * r['gram_s']:8.1f} "
              f"{r['gram_s'] / r['train_step_s']:9.2f} {ref_cols}", flush=True)
    write_results("rasterize", args, rows)


def write_results(kind: str, args: argparse.Namespace, rows: list[dict]) -> None:
    """Write the rows (and the machine and arguments) to --json or benchmarks/results/<kind>_<time>.json."""
    out = Path(args.json) if args.json else \
        Path(__file__).parent / "results" / f"{kind}_{time.strftime('%Y%m%d_%H%M%S')}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"machine": platform.platform(), "processor": platform.machine(),
                               "torch": torch.__version__, "threads": args.threads or torch.get_num_threads(),
                               "args": {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
                               "rows": rows}, indent=2))
    print(f"wrote {out}")


TIMED = ("fwd_ms", "fwd_bwd_ms", "gram_ms")


def run_backends_apart(args: argparse.Namespace, backends: list[str]) -> None:
    """Run each backend in its own process, `--rounds` times alternately, then print the other / first backend
    speed-ups (the median of the per-round ratios, and their range) and write one row per (preset, backend): the
    median times over the rounds, each round's times under `<key>_rounds`."""
    runs: dict[tuple[str, str], list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for round_index in range(args.rounds):
            for backend in backends:
                part = Path(tmp) / f"{backend}_{round_index}.json"
                cmd = [sys.executable, __file__, "--backends", backend, "--json", str(part), "--presets",
                       *args.presets, "--repeats", str(args.repeats), "--tile_size", str(args.tile_size),
                       "--chunk_size", str(args.chunk_size), "--garden_points", str(args.garden_points),
                       "--ref_max_pairs", str(args.ref_max_pairs)] + \
                    (["--threads", str(args.threads)] if args.threads else [])
                subprocess.run(cmd, check=True)
                for row in read_json(part)["rows"]:
                    runs.setdefault((row["preset"], backend), []).append(row)
    rows = []
    for (preset, backend), per_round in runs.items():
        row = dict(per_round[0])
        for key in TIMED:
            row[f"{key}_rounds"] = [r[key] for r in per_round]
            row[key] = statistics.median(row[f"{key}_rounds"])
        rows.append(row)
    first = backends[0]
    base = {r["preset"]: r for r in rows if r["backend"] == first}
    print(f"\nspeed-up of each backend over {first} (time {first} / time backend; {args.rounds} round(s) "
          "alternating the backends: median ms, median [min-max] of the per-round ratios)")
    print(f"{'preset':9} {'backend':9} {'fwd ms':>8} {'fwd+bwd ms':>10} {'gram ms':>8} {'fwd x':>15} "
          f"{'f+b x':>15} {'gram x':>15}")
    for r in rows:
        b = base[r["preset"]]
        cells = []
        for key in TIMED:
            ratios = [t0 / t1 for t0, t1 in zip(b[f"{key}_rounds"], r[f"{key}_rounds"])]
            r[key.replace("_ms", "_speedup")] = statistics.median(ratios)
            cells.append(f"{statistics.median(ratios):.1f} [{min(ratios):.1f}-{max(ratios):.1f}]")
        print(f"{r['preset']:9} {r['backend']:9} {r['fwd_ms']:8.1f} {r['fwd_bwd_ms']:10.1f} {r['gram_ms']:8.1f} "
              + " ".join(f"{c:>15}" for c in cells))
    write_results("rasterize", args, rows)

if __name__ == "__main__":
    run_cli(main)
