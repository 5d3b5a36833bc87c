"""FisherOracle: blocks of a GaussianModel view vs brute force, cached == streaming, singular scenes."""
import math

import pytest
import torch

from active import build_selector
from active.base import SelectionContext
from active.fisher import FisherOracle, fisher_view_blocks
from active.logdet import BlockInformation
from arguments import FisherSettings
from gaussian_renderer import RasterSettings, camera_center, project_gaussians
from gaussian_renderer.reference import rasterize_reference
from gaussian_renderer.sh import sh_to_colors
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from tests.scenes import intrinsics_for, look_at_viewmat, random_gaussians

W, H = 16, 16
pytestmark = pytest.mark.parametrize("backend", ["torch", "compiled"])  # every test on both rasterizer backends


def settings(backend):
    return RasterSettings(tile_size=8, chunk_size=4, backend=backend)


BG = torch.zeros(3, dtype=torch.float64)


def tiny_model(n=6, seed=0, opacity_shift=0.0):
    p = random_gaussians(n, seed=seed, sh_degree=1, scale=0.2)
    model = GaussianModel(1, {"means": p["means"], "quats": p["quats"], "log_scales": p["log_scales"],
                              "logit_opacities": p["logit_opacities"] + opacity_shift,
                              "sh_dc": p["sh_coeffs"][:, :1], "sh_rest": p["sh_coeffs"][:, 1:]})
    model.active_sh_degree = 1
    return model


def cameras(count=6):
    K = intrinsics_for(W, H, 55.0)
    out = []
    for i in range(count):
        a = 2 * math.pi * i / count
        view = look_at_viewmat((2.5 * math.cos(a), 2.5 * math.sin(a), 1.2))
        out.append(Camera(i, f"v{i}", view, *K.tolist(), W, H))
    return out


NAMES = ["means", "quats", "log_scales", "logit_opacities", "sh_dc"]


def reference_image(cam, means, quats, log_scales, logit_opacities, sh_dc, sh_rest):
    """The image of raw parameters (the model's activations written out: exp, sigmoid, SH dc + rest, degree 1)
    through projection, SH and the dense reference compositing, all plain autograd (no rasterizer backend). [3,H,W]"""
    proj = project_gaussians(means, quats, torch.exp(log_scales), cam.viewmat, cam.intrinsics, W, H)
    colors = sh_to_colors(torch.cat([sh_dc, sh_rest], dim=1), means, camera_center(cam.viewmat), 1)
    return rasterize_reference(proj.means2d, proj.conics, torch.sigmoid(logit_opacities), colors, proj.depths,
                               proj.radii, W, H, BG, settings("torch"))[0]


def bruteforce_blocks(model, cam, sigma=1.0):
    """sigma^-2 J_i^T J_i per Gaussian from the full autograd Jacobian of the image rendered by the dense reference
    (every pixel and channel w.r.t. every raw parameter), its per-Gaussian diagonal blocks. [N, 14, 14]"""
    sh_rest = model.params["sh_rest"].detach()

    def image(means, quats, log_scales, logit_opacities, sh_dc):
        return reference_image(cam, means, quats, log_scales, logit_opacities, sh_dc, sh_rest)

    jac = torch.autograd.functional.jacobian(image, tuple(model.params[k].detach() for k in NAMES), vectorize=True)
    n = model.num_gaussians
    j = torch.cat([jac[0].reshape(-1, n, 3), jac[1].reshape(-1, n, 4), jac[2].reshape(-1, n, 3),
                   jac[3].reshape(-1, n, 1), jac[4].reshape(-1, n, 3)], dim=2)  # [pixels x channels, N, 14]
    return torch.einsum("mip,miq->ipq", j, j) / sigma**2


def test_view_blocks_equal_bruteforce_jacobian(backend):
    model, cam = tiny_model(), cameras()[1]
    expected = bruteforce_blocks(model, cam, sigma=0.5)
    blocks = fisher_view_blocks(model, cam, BG, settings(backend), sigma=0.5)
    assert expected.abs().max() > 1e-3
    torch.testing.assert_close(blocks, expected, rtol=1e-4, atol=1e-4 * expected.abs().max().item())
    # symmetric PSD blocks
    torch.testing.assert_close(blocks, blocks.transpose(1, 2))
    assert torch.linalg.eigvalsh(blocks).min() > -1e-8 * expected.abs().max()


def select(model, mode, backend, method="pop_gs", k=2, **options):
    oracle = FisherOracle.build(model, cameras(), [0, 3], BG, settings(backend),
                                fisher=FisherSettings(fisher_mode=mode))
    ctx = SelectionContext([1, 2, 4, 5], oracle, torch.Generator().manual_seed(0), 0)
    return build_selector(method, **options).select(ctx, k), oracle


def dense_greedy(blocks, prior, candidates, k):
    """Plain greedy on dense log-dets of the block-diagonal matrices, ties to the lowest id. -> (ids, gains)"""
    a = torch.block_diag(*BlockInformation(prior).matrix)  # the prior with the oracle's ridge
    ids, gains = [], []
    for _ in range(k):
        rest = [v for v in candidates if v not in ids]
        values = [float(torch.logdet(a + torch.block_diag(*blocks[v])) - torch.logdet(a)) for v in rest]
        best = max(range(len(rest)), key=lambda i: (values[i], -rest[i]))
        ids.append(rest[best])
        gains.append(values[best])
        a = a + torch.block_diag(*blocks[rest[best]])
    return ids, gains


def test_cached_and_streaming_equal_greedy_on_bruteforce_blocks(backend):
    model = tiny_model(seed=2)
    blocks = [bruteforce_blocks(model, cam) for cam in cameras()]
    ids, gains = dense_greedy(blocks, blocks[0] + blocks[3], [1, 2, 4, 5], 2)
    for mode in ("cached", "streaming"):
        sel, oracle = select(model, mode, backend)
        assert sel.ids == ids, mode
        torch.testing.assert_close(torch.tensor(sel.gains), torch.tensor(gains), rtol=1e-4, atol=1e-6)
        assert oracle.views_computed == 4 and oracle.evaluated == sel.conservative == 4 + 3
    # The one object is the oracle: its counts and statistics live on it, nothing else is assigned after build.
    assert oracle.fisher_seconds > 0


def test_prior_views_are_float64_and_candidates_are_stored_float32(backend):
    # The stage prior sums the training views' factors as computed (float64); the cache keeps FACTOR_STORAGE.
    oracle = FisherOracle.build(tiny_model(seed=2), cameras(), [0, 3], BG, settings(backend),
                                fisher=FisherSettings(fisher_mode="cached"))
    assert oracle.blocks.compute(0).packed.dtype == torch.float64
    assert oracle.blocks(1).packed.dtype == torch.float32


def test_out_of_memory_while_caching_falls_back_to_streaming(monkeypatch, caplog, backend):
    model = tiny_model(seed=2)
    oracle = FisherOracle.build(model, cameras(), [0, 3], BG, settings(backend),
                                fisher=FisherSettings(fisher_mode="cached"))
    reference, _ = select(model, "cached", backend)
    compute = oracle.blocks.compute
    failed = []

    def compute_once_out_of_memory(view_id, *dtype):
        if len(oracle.blocks._cache) == 2 and not failed:  # the third view does not fit on the device
            failed.append(view_id)
            raise torch.cuda.OutOfMemoryError("CUDA out of memory (simulated)")
        return compute(view_id, *dtype)

    monkeypatch.setattr(oracle.blocks, "compute", compute_once_out_of_memory)
    ctx = SelectionContext([1, 2, 4, 5], oracle, torch.Generator().manual_seed(0), 0)
    sel = build_selector("pop_gs").select(ctx, 2)
    assert failed and oracle.blocks.streaming and not oracle.blocks._cache
    assert "switching the Fisher oracle to streaming mode" in caplog.text
    assert sel.ids == reference.ids


def test_singular_scene_gives_valid_choice_without_nan(backend):
    # Opacities ~0: nothing is visible, every Fisher block is zero; the selector must still choose validly.
    model = tiny_model(seed=1, opacity_shift=-40.0)
    for method, options in (("pop_gs", {}), ("lite_gs", {"eps": 0.1})):
        sel, _ = select(model, "cached", backend, method, **options)
        assert len(sel.ids) == 2 and all(math.isfinite(g) for g in sel.gains)
