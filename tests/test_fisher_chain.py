"""Chained Fisher blocks J_proj^T G J_proj equal the brute-force per-Gaussian Gram of the rendered image's Jacobian."""
import pytest
import torch

from gaussian_renderer import RasterSettings, attribute_gram, project_gaussians, projection_jacobian, rasterization
from gaussian_renderer import camera_center
from gaussian_renderer.reference import rasterize_reference
from gaussian_renderer.sh import sh_to_colors
from tests.scenes import intrinsics_for, look_at_viewmat, random_gaussians

W = H = 16
N = 5
NAMES = ("means", "quats", "log_scales", "logit_opacities", "sh_coeffs")
VIEW = look_at_viewmat((0.3, -2.5, 1.0))
K = intrinsics_for(W, H, 50.0, cx=7.3, cy=8.6)  # off-centre principal point
BG = torch.tensor([0.2, 0.5, 0.1], dtype=torch.float64)
BACKENDS = ["torch", "compiled"]


def settings(backend):
    return RasterSettings(tile_size=8, chunk_size=2, backend=backend)


def _render_fast(means, quats, log_scales, logit_opacities, sh_coeffs, degree, backend):
    """The public path: custom-backward tile rasterizer. [3, H, W]"""
    return rasterization(means, quats, torch.exp(log_scales), torch.sigmoid(logit_opacities), sh_coeffs, VIEW, K,
                         W, H, sh_degree=degree, background=BG, settings=settings(backend)).image


def _render_reference(means, quats, log_scales, logit_opacities, sh_coeffs, degree, backend):
    """Projection, SH and the dense reference compositing, differentiated by plain autograd. [3, H, W]"""
    proj = project_gaussians(means, quats, torch.exp(log_scales), VIEW, K, W, H)
    colors = sh_to_colors(sh_coeffs, means, camera_center(VIEW), degree)
    return rasterize_reference(proj.means2d, proj.conics, torch.sigmoid(logit_opacities), colors, proj.depths,
                               proj.radii, W, H, BG, settings(backend))[0]  # backend unused: dense


def _bruteforce_blocks(render_fn, params, degree, groups, backend):
    """Sum over pixels and channels of J_i^T J_i, J_i = d image / d (Gaussian i's raw parameters). [N, P, P]"""
    # The fast path's in-place custom backward does not batch under vmap: one backward pass per output there.
    jac = torch.autograd.functional.jacobian(lambda *t: render_fn(*t, degree, backend), tuple(params[k] for k in NAMES),
                                             vectorize=render_fn is _render_reference)
    per = {k: j.reshape(3 * H * W, N, -1) for k, j in zip(NAMES, jac)}  # [3HW, N, size]
    per["sh_dc"], per["sh_rest"] = per["sh_coeffs"][:, :, :3], per["sh_coeffs"][:, :, 3:]
    per_gauss = torch.cat([per[g] for g in groups], dim=2)  # [3HW, N, P]
    return torch.einsum("mip,miq->ipq", per_gauss, per_gauss)


def _chained_blocks(params, degree, groups, backend):
    """Fast path: closed-form attribute Gram G_i chained with the projection Jacobian. [N, P, P]"""
    proj = project_gaussians(params["means"], params["quats"], torch.exp(params["log_scales"]), VIEW, K, W, H)
    colors = sh_to_colors(params["sh_coeffs"], params["means"], camera_center(VIEW), degree)
    gram = attribute_gram(proj.means2d, proj.conics, torch.sigmoid(params["logit_opacities"]), colors, proj.depths,
                          proj.radii, W, H, BG, settings(backend))  # [N, A, A]
    jp = projection_jacobian(params["means"], params["quats"], params["log_scales"], params["logit_opacities"],
                             params["sh_coeffs"], degree, VIEW, K, W, H, groups)  # [N, A, P]
    return jp.transpose(1, 2) @ gram @ jp


# The "fast" brute force (one backward pass per output pixel) is slow; the fast render's gradients are checked
# against the dense reference in test_render_api.py, so the default run keeps the reference variant only.
@pytest.mark.parametrize("render_fn", [_render_reference, pytest.param(_render_fast, marks=pytest.mark.slow)],
                         ids=["reference", "fast"])
@pytest.mark.parametrize("degree,groups", [
    (0, ("means", "quats", "log_scales", "logit_opacities", "sh_dc")),
    (1, ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest")),
])
@pytest.mark.parametrize("backend", BACKENDS)  # of the chained blocks' Gram and of the fast render
def test_chained_blocks_equal_bruteforce_jacobian(render_fn, degree, groups, backend):
    params = random_gaussians(N, seed=3, sh_degree=degree, scale=0.25)
    expected = _bruteforce_blocks(render_fn, params, degree, groups, backend)
    blocks = _chained_blocks(params, degree, groups, backend)
    p = 14 + (3 * ((degree + 1) ** 2 - 1) if "sh_rest" in groups else 0)
    assert blocks.shape == (N, p, p)
    scale = expected.abs().amax(dim=(1, 2))  # [N] per-Gaussian magnitude
    assert (scale > 0.5).all()  # every Gaussian is visible: no block is compared as 0 == 0
    # float64 throughout: only rounding separates the paths, far below the 1e-6 relative the oracle needs.
    rel = ((blocks - expected).abs().amax(dim=(1, 2)) / scale.clamp_min(1e-300))
    assert rel.max() < 1e-8, f"largest per-Gaussian relative error {rel.max():.3e}"
