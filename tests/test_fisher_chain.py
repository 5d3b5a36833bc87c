"""The chained Fisher-ready partials equal the brute-force Jacobian of the rendered image."""
import pytest
import torch

from gaussian_renderer import RasterSettings, attribute_gram, project_gaussians, projection_jacobian, rasterization
from gaussian_renderer.api import camera_center
from gaussian_renderer.sh import sh_to_colors
from tests.scenes import intrinsics_for, look_at_viewmat, random_gaussians

W, H = 16, 12
GROUPS = ("means", "quats", "log_scales", "logit_opacities", "sh_dc")


def _render_raw(params, viewmat, K, degree, bg, settings):
    return rasterization(params["means"], params["quats"], torch.exp(params["log_scales"]),
                         torch.sigmoid(params["logit_opacities"]), params["sh_coeffs"], viewmat, K, W, H,
                         sh_degree=degree, background=bg, settings=settings).image


@pytest.mark.parametrize("degree", [0, 1])
def test_chained_blocks_equal_bruteforce_jacobian(degree):
    params = random_gaussians(5, seed=3, sh_degree=degree, scale=0.25)
    viewmat = look_at_viewmat((0.3, -2.5, 1.0))
    K = intrinsics_for(W, H, 50.0, cx=7.3, cy=6.6)  # off-centre principal point
    bg = torch.tensor([0.2, 0.5, 0.1], dtype=torch.float64)
    settings = RasterSettings(tile_size=8, chunk_size=2)

    # Brute force: d image / d raw params of every Gaussian, then per-Gaussian J_i^T J_i.
    names = ["means", "quats", "log_scales", "logit_opacities", "sh_coeffs"]
    def f(*tensors):
        return _render_raw(dict(zip(names, tensors)), viewmat, K, degree, bg, settings)
    jac = torch.autograd.functional.jacobian(f, tuple(params[k] for k in names))
    n = 5
    per_gauss = torch.cat([jac[0].reshape(-1, n, 3), jac[1].reshape(-1, n, 4), jac[2].reshape(-1, n, 3),
                           jac[3].reshape(-1, n, 1), jac[4].reshape(-1, n, (degree + 1) ** 2, 3)[:, :, 0, :]],
                          dim=2)  # [3HW, N, 14]
    expected = torch.einsum("mip,miq->ipq", per_gauss, per_gauss)

    # Fast path: G_i from closed-form pixel partials, chained with the projection Jacobian.
    proj = project_gaussians(params["means"], params["quats"], torch.exp(params["log_scales"]), viewmat, K, W, H)
    colors = sh_to_colors(params["sh_coeffs"], params["means"], camera_center(viewmat), degree)
    gram = attribute_gram(proj.means2d, proj.conics, torch.sigmoid(params["logit_opacities"]), colors, proj.depths,
                          proj.radii, W, H, bg, settings)
    jp = projection_jacobian(params["means"], params["quats"], params["log_scales"], params["logit_opacities"],
                             params["sh_coeffs"], degree, viewmat, K, W, H, GROUPS)
    blocks = jp.transpose(1, 2) @ gram @ jp
    assert expected.abs().max() > 1.0  # the scene is visible, the test is not vacuous
    # float64 throughout: only rounding differs between the two paths.
    torch.testing.assert_close(blocks, expected, rtol=1e-8, atol=1e-8 * expected.abs().max().item())
