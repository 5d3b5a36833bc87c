"""One scene computed on two devices (or dtypes) and compared: image, alpha, gradients, Fisher blocks, selection.

`tests/test_cuda.py` compares CUDA with CPU in float32; `tests/test_device_compare.py` runs the same helpers on CPU
(float32 against float64, and a perturbed result that must be rejected) so the comparison code is proven without a
GPU. Everything returned is moved to the CPU.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import torch

from active.fisher import fisher_view_blocks
from gaussian_renderer import RasterSettings, rasterization
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from tests.conftest import run_cli
from tests.scenes import intrinsics_for, look_at_viewmat, random_gaussians

IMAGE_ATOL = 1e-5  # image and alpha, absolute (values in [0, 1])
GRAD_RTOL = 1e-4  # gradients, relative to the largest magnitude of that parameter's reference gradient
FISHER_RTOL = 1e-4  # Fisher blocks, relative to the largest magnitude of the reference blocks

W, H = 48, 40
SH_DEGREE = 3
BACKENDS = ("torch", "compiled")  # CPU backends; CUDA tensors always take the torch path
PARAM_NAMES = ("means", "quats", "log_scales", "logit_opacities", "sh_coeffs")


def scene_params(n: int = 120, seed: int = 0) -> dict[str, torch.Tensor]:
    """Raw float64 parameters of `n` random Gaussians with SH degree 3 (the CPU reference values)."""
    return random_gaussians(n, seed=seed, sh_degree=SH_DEGREE, scale=0.12)


def scene_camera(dtype: torch.dtype, device: str) -> tuple[torch.Tensor, torch.Tensor]:
    """World-to-camera [4, 4] and intrinsics [4] of a camera with an off-centre principal point."""
    view = look_at_viewmat((2.2, -1.1, 1.3), dtype=dtype).to(device)
    return view, intrinsics_for(W, H, 55.0, cx=W / 2 + 1.3, cy=H / 2 - 0.7, dtype=dtype).to(device)


@dataclass
class RenderResult:
    image: torch.Tensor  # [3, H, W]
    alpha: torch.Tensor  # [H, W]
    grads: dict[str, torch.Tensor]  # raw parameter -> gradient of the loss


def settings(backend: str) -> RasterSettings:
    """The comparison's raster settings with the rasterizer backend named explicitly ("torch" or "compiled")."""
    return RasterSettings(tile_size=8, chunk_size=8, backend=backend)


def render_with_grads(device: str, dtype: torch.dtype = torch.float32, n: int = 120, seed: int = 0,
                      backend: str = "torch") -> RenderResult:
    """Render the scene on `device` in `dtype` with `backend` and back-propagate a fixed random loss of image and
    alpha."""
    raw = {k: v.to(dtype=dtype, device=device).requires_grad_(True) for k, v in scene_params(n, seed).items()}
    view, K = scene_camera(dtype, device)
    out = rasterization(raw["means"], raw["quats"], torch.exp(raw["log_scales"]), torch.sigmoid(raw["logit_opacities"]),
                        raw["sh_coeffs"], view, K, W, H, sh_degree=SH_DEGREE,
                        background=torch.tensor([0.1, 0.2, 0.3], dtype=dtype, device=device), settings=settings(backend))
    g = torch.Generator().manual_seed(seed + 1)
    w_image = torch.randn(3, H, W, generator=g, dtype=torch.float64).to(dtype=dtype, device=device)
    w_alpha = torch.randn(H, W, generator=g, dtype=torch.float64).to(dtype=dtype, device=device)
    ((out.image * w_image).sum() + (out.alpha * w_alpha).sum()).backward()
    return RenderResult(out.image.detach().cpu(), out.alpha.detach().cpu(),
                        {k: raw[k].grad.detach().cpu() for k in PARAM_NAMES})


def relative_error(value: torch.Tensor, reference: torch.Tensor) -> float:
    """max |value - reference| / max |reference| (both in float64; 0 when both are 0)."""
    value, reference = value.double(), reference.double()
    scale = reference.abs().max().item()
    diff = (value - reference).abs().max().item()
    return diff / scale if scale > 0 else diff


def compare_renders(value: RenderResult, reference: RenderResult) -> list[str]:
    """The tolerance violations of `value` against `reference` (empty when they agree)."""
    problems = []
    for name, a, b in (("image", value.image, reference.image), ("alpha", value.alpha, reference.alpha)):
        diff = (a.double() - b.double()).abs().max().item()
        if not diff <= IMAGE_ATOL:
            problems.append(f"{name}: max abs diff {diff:.3g} > {IMAGE_ATOL}")
    for name in PARAM_NAMES:
        err = relative_error(value.grads[name], reference.grads[name])
        if not err <= GRAD_RTOL:
            problems.append(f"grad {name}: relative error {err:.3g} > {GRAD_RTOL}")
    return problems


def model_and_camera(device: str, dtype: torch.dtype = torch.float32, n: int = 120,
                     seed: int = 0) -> tuple[GaussianModel, Camera]:
    """A GaussianModel of the scene (SH degree 3 active) and its camera, on `device` in `dtype`."""
    p = {k: v.to(dtype=dtype, device=device) for k, v in scene_params(n, seed).items()}
    model = GaussianModel(SH_DEGREE, {"means": p["means"], "quats": p["quats"], "log_scales": p["log_scales"],
                                      "logit_opacities": p["logit_opacities"], "sh_dc": p["sh_coeffs"][:, :1],
                                      "sh_rest": p["sh_coeffs"][:, 1:]})
    model.active_sh_degree = SH_DEGREE
    view, K = scene_camera(dtype, device)
    return model, Camera(0, "v0", view, *K.tolist(), W, H)


def fisher_blocks(device: str, dtype: torch.dtype = torch.float32, n: int = 120, seed: int = 0,
                  backend: str = "torch") -> torch.Tensor:
    """The scene's per-Gaussian Fisher blocks computed on `device` with `backend`. [N, 14, 14] float64, on the CPU"""
    model, cam = model_and_camera(device, dtype, n, seed)
    background = torch.tensor([0.1, 0.2, 0.3], dtype=dtype, device=device)
    return fisher_view_blocks(model, cam, background, settings(backend)).cpu()


def compare_fisher(value: torch.Tensor, reference: torch.Tensor) -> list[str]:
    """The tolerance violation of Fisher blocks (empty when they agree)."""
    err = relative_error(value, reference)
    return [] if err <= FISHER_RTOL else [f"Fisher blocks: relative error {err:.3g} > {FISHER_RTOL}"]


ACTIVE_ARGS = ["--eval", "--num_init_views", "2", "--views_per_step", "3", "--max_views", "8", "--iters_per_view",
               "4", "--iterations", "40", "--num_random_points", "400", "--quiet", "--sh_degree", "1", "--seed", "3"]


def active_selection(scene: Path, model_dir: Path, device: str, method: str = "pop_gs",
                     extra: tuple[str, ...] = ()) -> dict:
    """Run a small active train.py run on `device`; returns its selection.json (asserts the run succeeded)."""
    r = run_cli("train.py", "-s", str(scene), "-m", str(model_dir), "--method", method, "--device", device,
                *ACTIVE_ARGS, *extra)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads((model_dir / "selection.json").read_text())


def compare_selections(value: dict, reference: dict, gain_rtol: float = 1e-3) -> list[str]:
    """Differences in the selected views of two runs; a flip is reported as a near-tie when the two views' gains
    differ by less than `gain_rtol` relative (the selection is then equally good within float32 noise)."""
    problems = []
    for a, b in zip(value["stages"], reference["stages"]):
        if a["selected"] == b["selected"]:
            continue
        tie = all(math.isclose(ga, gb, rel_tol=gain_rtol) for ga, gb in zip(a["gains"], b["gains"]))
        kind = "near-tie flip" if tie else "different selection"
        problems.append(f"stage {a['stage']}: {kind}: {a['selected']} (gains {a['gains']}) vs {b['selected']} "
                        f"(gains {b['gains']})")
    if len(value["stages"]) != len(reference["stages"]):
        problems.append(f"{len(value['stages'])} vs {len(reference['stages'])} stages")
    return problems
