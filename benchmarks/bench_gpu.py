"""Our rasterizer at the paper's sizes on a GPU, next to gsplat's CUDA rasterizer on the same Gaussians and camera.

    python benchmarks/bench_gpu.py --device cuda                     # 100k and 300k Gaussians at 800 x 800, SH 3
    python benchmarks/bench_gpu.py --device cpu --tiny               # the script itself, in seconds, on a CPU

Gaussians: the Mip-NeRF 360 garden SfM points of test_garden.npz (from --data, $LITEGS_SHARED/data or
../shared/data; jittered copies beyond its 138,766 points; random points in a cube without it), initialised as
3DGS does (`GaussianModel.from_point_cloud`: scale from 3 nearest neighbours, opacity 0.1) plus random rotations
and small random SH degree-3 coefficients. Camera: the garden's first camera, its focal length scaled to the
requested square image (principal point at the centre).

Timed (one warm-up, then the median of --repeats; CUDA synchronised around each call), per tile size:
* `fwd`: `gaussian_renderer.rasterization` (project, SH, rasterize) without gradients;
* `fwd_bwd`: the same with a backward pass of a weighted image + alpha loss (one training step's rendering);
* `gram`: `attribute_gram` on the projected attributes (one view's Fisher-ready Gram pass);
* `gsplat_fwd_bwd`: `gsplat.rasterization` (1.5.3) forward + backward on the same inputs, and ours / gsplat's.
Peak memory of each operation: `torch.cuda.max_memory_allocated` (CUDA only).

gsplat compiles its CUDA code on first use; that runs in a child process limited to --gsplat_timeout seconds
(240). Where gsplat is missing or does not compile in time, a line says so and only our numbers are reported.
Writes <out>/bench_gpu.json and <out>/bench_gpu.md (default benchmarks/results/).
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from gaussian_renderer import RasterSettings, rasterization
from gaussian_renderer.fisher_partials import attribute_gram
from gaussian_renderer.projection import camera_center, project_gaussians
from gaussian_renderer.sh import sh_to_colors
from scene.gaussian_model import GaussianModel
from utils.errors import run_cli

ROOT = Path(__file__).resolve().parents[1]

SH_DEGREE = 3
GARDEN_REL = Path("gsplat_garden") / "test_garden.npz"


def data_dirs(explicit: str | None) -> list[Path]:
    """Where the shared data may be: --data, $LITEGS_SHARED/data, ../shared/data, benchmarks/gpu_data."""
    dirs = [Path(explicit)] if explicit else []
    if os.environ.get("LITEGS_SHARED"):
        dirs.append(Path(os.environ["LITEGS_SHARED"]) / "data")
    return dirs + [ROOT.parent / "shared" / "data", ROOT / "benchmarks" / "gpu_data"]


def sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def measure(fn: Callable[[], object], repeats: int, device: torch.device) -> tuple[float, float | None]:
    """(median seconds of `repeats` calls after one warm-up, peak allocated MiB of one call or None off CUDA)."""
    fn()
    sync(device)
    peak = None
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
        fn()
        sync(device)
        peak = torch.cuda.max_memory_allocated(device) / 2**20
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        sync(device)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), peak


def make_scene(n: int, size: int, device: torch.device, data: str | None, seed: int = 0) -> dict:
    """Raw Gaussians (float32, on `device`) and a camera (viewmat [4,4], K [3,3]) for an image of size x size."""
    g = torch.Generator().manual_seed(seed)
    garden = next((d / GARDEN_REL for d in data_dirs(data) if (d / GARDEN_REL).is_file()), None)
    if garden is not None:
        npz = np.load(garden)
        base, base_colors = torch.from_numpy(npz["means3d"]).float(), torch.from_numpy(npz["colors"]).float() / 255
        viewmat, k = torch.from_numpy(npz["viewmats"][0]).float(), torch.from_numpy(npz["Ks"][0]).float()
        focal = float(k[0, 0]) * size / int(npz["width"])
        idx = torch.randperm(base.shape[0], generator=g)
        idx = idx.repeat(math.ceil(n / base.shape[0]))[:n]
        spread = (base.quantile(0.9, dim=0) - base.quantile(0.1, dim=0)).norm() * 1e-3
        jitter = torch.randn(n, 3, generator=g) * spread * (torch.arange(n) >= base.shape[0])[:, None]
        points, colors, source = base[idx] + jitter, base_colors[idx], str(garden)
    else:
        points = (torch.rand(n, 3, generator=g) * 2 - 1) * 1.5
        colors = torch.rand(n, 3, generator=g)
        viewmat = torch.eye(4)
        viewmat[2, 3] = 4.0  # camera 4 units in front of the cube, looking along +z
        focal, source = size * 1.2, "random cube (test_garden.npz not found)"
    model = GaussianModel.from_point_cloud(points, colors, SH_DEGREE, device)
    p = model.params
    quats = torch.randn(n, 4, generator=g).to(device)
    sh = torch.cat([p["sh_dc"], 0.1 * torch.randn(n, 15, 3, generator=g).to(device)], dim=1)  # [N, 16, 3]
    k = torch.tensor([[focal, 0, size / 2], [0, focal, size / 2], [0, 0, 1]], dtype=torch.float32)
    tensors = {"means": p["means"], "quats": quats, "scales": torch.exp(p["log_scales"]),
               "opacities": torch.sigmoid(p["logit_opacities"]), "sh": sh.contiguous()}
    return {**{name: t.detach() for name, t in tensors.items()}, "viewmat": viewmat.to(device), "K": k.to(device),
            "size": size, "source": source}


def our_ops(scene: dict, settings: RasterSettings) -> dict[str, Callable[[], object]]:
    """fwd, fwd_bwd and gram closures of our rasterizer on `scene`."""
    size, device = scene["size"], scene["means"].device
    k = scene["K"]
    intr = torch.stack([k[0, 0], k[1, 1], k[0, 2], k[1, 2]])
    bg = torch.zeros(3, device=device)
    leaves = [scene[name].clone().requires_grad_(True) for name in ("means", "quats", "scales", "opacities", "sh")]
    weights = torch.rand(3, size, size, generator=torch.Generator().manual_seed(1)).to(device)

    def render(*tensors):
        return rasterization(*tensors, scene["viewmat"], intr, size, size, sh_degree=SH_DEGREE, background=bg,
                             settings=settings)

    def fwd():
        with torch.no_grad():
            return render(*(scene[name] for name in ("means", "quats", "scales", "opacities", "sh"))).image

    def fwd_bwd():
        for leaf in leaves:
            leaf.grad = None
        out = render(*leaves)
        ((out.image * weights).sum() + out.alpha.sum()).backward()

    with torch.no_grad():
        proj = project_gaussians(scene["means"], scene["quats"], scene["scales"], scene["viewmat"], intr, size, size)
        colors = sh_to_colors(scene["sh"], scene["means"], camera_center(scene["viewmat"]), SH_DEGREE)

    def gram():
        return attribute_gram(proj.means2d, proj.conics, scene["opacities"], colors, proj.depths, proj.radii, size,
                              size, bg, settings)

    return {"fwd": fwd, "fwd_bwd": fwd_bwd, "gram": gram, "visible": lambda: int((proj.radii > 0).sum())}


def gsplat_fwd_bwd(scene: dict) -> Callable[[], object]:
    """gsplat.rasterization forward + backward with the same Gaussians, camera, loss and background."""
    import gsplat

    size, device = scene["size"], scene["means"].device
    leaves = [scene[name].clone().requires_grad_(True) for name in ("means", "quats", "scales", "opacities", "sh")]
    weights = torch.rand(3, size, size, generator=torch.Generator().manual_seed(1)).to(device)

    def step():
        for leaf in leaves:
            leaf.grad = None
        colors, alphas, _ = gsplat.rasterization(*leaves, scene["viewmat"][None], scene["K"][None], size, size,
                                                 sh_degree=SH_DEGREE, backgrounds=torch.zeros(1, 3, device=device))
        ((colors[0].permute(2, 0, 1) * weights).sum() + alphas.sum()).backward()

    return step


def gsplat_compiles(timeout_s: float) -> tuple[bool, str]:
    """Import gsplat and render once in a child process (its JIT build, cached on disk) within `timeout_s`."""
    code = ("import torch, gsplat; d = 'cuda'; n = 64; m = torch.randn(n, 3, device=d) + torch.tensor([0, 0, 4.], "
            "device=d); q = torch.randn(n, 4, device=d); s = torch.full((n, 3), .1, device=d); "
            "o = torch.full((n,), .5, device=d); c = torch.rand(n, 3, device=d); "
            "K = torch.tensor([[[40., 0, 32], [0, 40., 32], [0, 0, 1]]], device=d); "
            "r = gsplat.rasterization(m, q, s, o, c, torch.eye(4, device=d)[None], K, 64, 64); "
            "torch.cuda.synchronize(); print('gsplat', gsplat.__version__, 'ok')")
    t0 = time.perf_counter()
    try:
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return False, f"gsplat did not compile within {timeout_s:.0f} s"
    if r.returncode != 0:
        tail = " | ".join((r.stderr or r.stdout).strip().splitlines()[-3:])
        return False, f"gsplat failed (exit {r.returncode}): {tail}"
    return True, f"{r.stdout.strip()} (first use incl. JIT build {time.perf_counter() - t0:.0f} s)"


def gsplat_status(device: torch.device, timeout_s: float) -> tuple[bool, str]:
    if importlib.util.find_spec("gsplat") is None:  # not imported here: its import may start the JIT build
        return False, "gsplat is not installed: skipped (install gsplat==1.5.3 to compare)"
    if device.type != "cuda":
        return False, "gsplat needs CUDA: skipped on this device"
    return gsplat_compiles(timeout_s)


def markdown(rows: list[dict], header: dict) -> str:
    lines = [f"# bench_gpu — {header['device_name']}, {header['date']}", "",
             f"Gaussians from: {header['source']}; SH degree {SH_DEGREE}; gsplat: {header['gsplat']}", "",
             "| N | size | tile | visible | fwd s | fwd+bwd s | gram s | peak MiB fwd / fwd+bwd / gram "
             "| gsplat fwd+bwd s | gsplat peak MiB | ours ÷ gsplat |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]

    def f(v, fmt="{:.4f}"):
        return "–" if v is None else fmt.format(v)

    for r in rows:
        peaks = " / ".join(f(r.get(f"{op}_peak_mib"), "{:.0f}") for op in ("fwd", "fwd_bwd", "gram"))
        lines.append(f"| {r['gaussians']} | {r['size']} | {r['tile_size']} | {r['visible']} | {f(r['fwd_s'])} | "
                     f"{f(r['fwd_bwd_s'])} | {f(r['gram_s'])} | {peaks} | {f(r.get('gsplat_fwd_bwd_s'))} | "
                     f"{f(r.get('gsplat_fwd_bwd_peak_mib'), '{:.0f}')} | {f(r.get('ratio_fwd_bwd'), '{:.1f}×')} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cuda", choices=("cuda", "cpu"))
    parser.add_argument("--sizes", type=int, nargs="+", default=[100_000, 300_000], help="numbers of Gaussians")
    parser.add_argument("--resolution", type=int, default=800, help="square image side in pixels")
    parser.add_argument("--tile_sizes", type=int, nargs="+", default=[16, 4], help="our rasterizer's tile sizes")
    parser.add_argument("--chunk_size", type=int, default=RasterSettings.chunk_size)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--tiny", action="store_true", help="2,000 Gaussians at 64 px, 1 repeat: checks the script")
    parser.add_argument("--gsplat_timeout", type=float, default=240.0, help="seconds for gsplat's first use (JIT)")
    parser.add_argument("--data", default=None, help="the shared data folder (holding gsplat_garden/)")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results"), help="folder for the JSON and table")
    args = parser.parse_args()
    if args.device == "cuda" and not torch.cuda.is_available():
        print("error: --device cuda was asked for but torch sees no CUDA device; use --device cpu", file=sys.stderr)
        sys.exit(2)
    if args.tiny:
        args.sizes, args.resolution, args.repeats, args.tile_sizes = [2000], 64, 1, [8]
    device = torch.device(args.device)
    ok, gsplat_note = gsplat_status(device, args.gsplat_timeout)
    print(gsplat_note, flush=True)
    header = {"device": args.device, "device_name": torch.cuda.get_device_name(device) if device.type == "cuda"
              else platform.processor() or platform.machine(), "torch": torch.__version__,
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "gsplat": gsplat_note, "source": None}
    rows = []
    for n in args.sizes:
        scene = make_scene(n, args.resolution, device, args.data)
        header["source"] = scene["source"]
        gs = None
        if ok:
            gs_s, gs_peak = measure(gsplat_fwd_bwd(scene), args.repeats, device)
            gs = {"gsplat_fwd_bwd_s": gs_s, "gsplat_fwd_bwd_peak_mib": gs_peak}
        for tile in args.tile_sizes:
            ops = our_ops(scene, RasterSettings(tile_size=tile, chunk_size=args.chunk_size))
            row = {"gaussians": n, "size": args.resolution, "tile_size": tile, "chunk_size": args.chunk_size,
                   "visible": ops["visible"]()}
            for op in ("fwd", "fwd_bwd", "gram"):
                row[f"{op}_s"], row[f"{op}_peak_mib"] = measure(ops[op], args.repeats, device)
            if gs:
                row.update(gs, ratio_fwd_bwd=row["fwd_bwd_s"] / gs["gsplat_fwd_bwd_s"])
            rows.append(row)
            print(json.dumps(row), flush=True)
            if device.type == "cuda":
                torch.cuda.empty_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_gpu.json").write_text(json.dumps({**header, "rows": rows}, indent=2) + "\n")
    table = markdown(rows, header)
    (out / "bench_gpu.md").write_text(table)
    print(table)


if __name__ == "__main__":
    run_cli(main)
