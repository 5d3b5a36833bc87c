"""Rasterizer and Fisher-pass speed: fast path vs the dense reference, and one view's Fisher blocks vs a training step.

    python benchmarks/bench_rasterize.py [--preset small|garden] [--repeats 5]

Presets: `small` = 1,500 random Gaussians at 64x64 (the dense reference fits in memory); `garden` = the real
Mip-NeRF 360 garden SfM points of ../shared/data/gsplat_garden (subsampled), initialised as a 3DGS trainer would,
rendered at 1/4 resolution. Prints a table and writes JSON to benchmarks/results/.
"""
from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from active.fisher import fisher_view_blocks  # noqa: E402
from gaussian_renderer import RasterSettings, project_gaussians, rasterization  # noqa: E402
from gaussian_renderer.reference import rasterize_reference  # noqa: E402
from scene.cameras import Camera  # noqa: E402
from scene.gaussian_model import GaussianModel  # noqa: E402
from utils.knn import mean_sq_dist_to_neighbours  # noqa: E402

SHARED = Path(__file__).resolve().parents[2] / "shared"


def median_time(fn, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def small_scene():
    g = torch.Generator().manual_seed(0)
    n = 1500
    points = (torch.rand(n, 3, generator=g) * 2 - 1) * 0.8
    model = GaussianModel.from_point_cloud(points, torch.rand(n, 3, generator=g), 0)
    model.params["logit_opacities"].data += 2.0
    view = torch.eye(4)
    view[2, 3] = 3.0
    return model, Camera(0, "small", view, 70.0, 70.0, 32.0, 32.0, 64, 64)


def garden_scene(max_points: int):
    data = np.load(SHARED / "data" / "gsplat_garden" / "test_garden.npz")
    points = torch.from_numpy(data["means3d"]).float()
    colors = torch.from_numpy(data["colors"]).float() / 255.0
    idx = torch.randperm(points.shape[0], generator=torch.Generator().manual_seed(0))[:max_points]
    model = GaussianModel.from_point_cloud(points[idx], colors[idx], 0)
    model.params["logit_opacities"].data += 2.0
    scale = 4
    K = torch.from_numpy(data["Ks"][0]).float() / scale
    w, h = int(data["width"]) // scale, int(data["height"]) // scale
    view = torch.from_numpy(data["viewmats"][0]).float()
    return model, Camera(0, "garden", view, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), w, h)


def run(preset: str, repeats: int, max_points: int) -> dict:
    model, cam = small_scene() if preset == "small" else garden_scene(max_points)
    settings = RasterSettings()
    bg = torch.zeros(3)
    for p in model.params.values():
        p.requires_grad_(True)

    def forward():
        with torch.no_grad():
            rasterization(model.means, model.quats, model.scales, model.opacities, model.sh_coeffs, cam.viewmat,
                          cam.intrinsics, cam.width, cam.height, sh_degree=0, background=bg, settings=settings)

    def train_step():
        out = rasterization(model.means, model.quats, model.scales, model.opacities, model.sh_coeffs, cam.viewmat,
                            cam.intrinsics, cam.width, cam.height, sh_degree=0, background=bg, settings=settings)
        out.image.sum().backward()

    def reference_step():
        proj = project_gaussians(model.means, model.quats, model.scales, cam.viewmat, cam.intrinsics, cam.width,
                                 cam.height)
        colors = model.sh_coeffs[:, 0] * 0.28209479177387814 + 0.5
        img, _ = rasterize_reference(proj.means2d, proj.conics, model.opacities, colors, proj.depths, proj.radii,
                                     cam.width, cam.height, bg, settings)
        img.sum().backward()

    def fisher():
        fisher_view_blocks(model, cam, bg, settings)

    with torch.no_grad():
        radii = project_gaussians(model.means, model.quats, model.scales, cam.viewmat, cam.intrinsics, cam.width,
                                  cam.height).radii
    row = {"preset": preset, "gaussians": model.num_gaussians, "visible": int((radii > 0).sum()),
           "width": cam.width, "height": cam.height,
           "forward_s": median_time(forward, repeats), "train_step_s": median_time(train_step, repeats),
           "fisher_view_s": median_time(fisher, repeats)}
    if preset == "small":
        row["reference_step_s"] = median_time(reference_step, max(1, repeats // 2))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--preset", choices=("small", "garden", "all"), default="all")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--garden_points", type=int, default=20_000, help="SfM points used from the garden scene")
    args = parser.parse_args()
    presets = ["small", "garden"] if args.preset == "all" else [args.preset]
    if "garden" in presets and not (SHARED / "data" / "gsplat_garden" / "test_garden.npz").is_file():
        print(f"skipping garden: {SHARED}/data/gsplat_garden/test_garden.npz not found")
        presets.remove("garden")
    rows = [run(p, args.repeats, args.garden_points) for p in presets]
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, {platform.processor() or platform.machine()}")
    print(f"{'preset':8} {'N':>7} {'visible':>7} {'HxW':>9} {'fwd ms':>8} {'fwd+bwd ms':>10} {'fisher ms':>9} "
          f"{'fisher/step':>11} {'ref fwd+bwd ms':>14} {'speed-up':>8}")
    for r in rows:
        ref = r.get("reference_step_s")
        print(f"{r['preset']:8} {r['gaussians']:7d} {r['visible']:7d} {r['height']:4d}x{r['width']:<4d} "
              f"{1e3 * r['forward_s']:8.1f} {1e3 * r['train_step_s']:10.1f} {1e3 * r['fisher_view_s']:9.1f} "
              f"{r['fisher_view_s'] / r['train_step_s']:11.2f} "
              f"{(f'{1e3 * ref:14.1f}' if ref else '           n/a')} "
              f"{(f'{ref / r['train_step_s']:7.1f}x' if ref else '     n/a')}")
    out = Path(__file__).parent / "results" / f"rasterize_{time.strftime('%Y%m%d_%H%M%S')}.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"machine": platform.platform(), "torch": torch.__version__,
                               "threads": torch.get_num_threads(), "rows": rows}, indent=2))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
