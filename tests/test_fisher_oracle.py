"""FisherOracle: blocks of a GaussianModel view vs brute force, cached == streaming, singular scenes."""
import math

import torch

from active import build_selector
from active.base import SelectionContext
from active.fisher import FisherOracle, fisher_view_blocks
from gaussian_renderer import RasterSettings, rasterization
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from tests.scenes import intrinsics_for, look_at_viewmat, random_gaussians

W, H = 16, 16
SETTINGS = RasterSettings(tile_size=8, chunk_size=4)
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


def test_view_blocks_equal_bruteforce_jacobian():
    model, cam = tiny_model(), cameras()[1]
    names = ["means", "quats", "log_scales", "logit_opacities", "sh_dc"]

    sh_rest = model.params["sh_rest"].detach()

    def image(means, quats, log_scales, logit_opacities, sh_dc):  # the model's activations, written out
        return rasterization(means, quats, torch.exp(log_scales), torch.sigmoid(logit_opacities),
                             torch.cat([sh_dc, sh_rest], dim=1), cam.viewmat, cam.intrinsics, W, H, sh_degree=1,
                             background=BG, settings=SETTINGS).image

    jac = torch.autograd.functional.jacobian(image, tuple(model.params[k].detach() for k in names))
    n = model.num_gaussians
    j = torch.cat([jac[0].reshape(-1, n, 3), jac[1].reshape(-1, n, 4), jac[2].reshape(-1, n, 3),
                   jac[3].reshape(-1, n, 1), jac[4].reshape(-1, n, 3)], dim=2)
    expected = torch.einsum("mip,miq->ipq", j, j) / 0.5**2
    blocks = fisher_view_blocks(model, cam, BG, SETTINGS, sigma=0.5)
    assert expected.abs().max() > 1e-3
    torch.testing.assert_close(blocks, expected, rtol=1e-4, atol=1e-4 * expected.abs().max().item())
    # symmetric PSD blocks
    torch.testing.assert_close(blocks, blocks.transpose(1, 2))
    assert torch.linalg.eigvalsh(blocks).min() > -1e-8 * expected.abs().max()


def select(model, mode, method="pop_gs", k=2, **options):
    oracle = FisherOracle.build(model, cameras(), [0, 3], BG, SETTINGS, mode=mode)
    ctx = SelectionContext([1, 2, 4, 5], oracle.gain_oracle, torch.Generator().manual_seed(0), 0)
    return build_selector(method, **options).select(ctx, k), oracle


def test_cached_and_streaming_agree():
    model = tiny_model(seed=2)
    cached, oc = select(model, "cached")
    streaming, os_ = select(model, "streaming")
    assert cached.ids == streaming.ids and cached.gains == streaming.gains
    assert oc.views_computed == os_.views_computed == 4


def test_singular_scene_gives_valid_choice_without_nan():
    # Opacities ~0: nothing is visible, every Fisher block is zero; the selector must still choose validly.
    model = tiny_model(seed=1, opacity_shift=-40.0)
    for method, options in (("pop_gs", {}), ("lite_gs", {"eps": 0.1})):
        sel, _ = select(model, "cached", method, **options)
        assert len(sel.ids) == 2 and all(math.isfinite(g) for g in sel.gains)
