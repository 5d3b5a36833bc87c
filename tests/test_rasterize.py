"""Fast tile rasterizer vs the dense reference: images, alphas and gradients; edge cases."""
import pytest
import torch

from gaussian_renderer import RasterSettings, pixel_attribute_partials, attribute_gram, rasterize
from gaussian_renderer.reference import rasterize_reference


def random_2d_scene(n, width, height, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    means2d = torch.rand(n, 2, generator=g, dtype=dtype) * torch.tensor([width, height], dtype=dtype)
    lower = torch.randn(n, 2, 2, generator=g, dtype=dtype) * 2
    cov = lower @ lower.transpose(1, 2) + torch.eye(2, dtype=dtype)
    inv = torch.linalg.inv(cov)
    conics = torch.stack([inv[:, 0, 0], inv[:, 0, 1], inv[:, 1, 1]], -1)
    opacities = torch.rand(n, generator=g, dtype=dtype) * 0.98 + 0.01
    colors = torch.rand(n, 3, generator=g, dtype=dtype)
    depths = torch.rand(n, generator=g, dtype=dtype)
    radii = torch.full((n,), 8, dtype=torch.long)
    if n > 2:
        radii[0] = 0  # culled
        means2d[1] = torch.tensor([-30.0, 5.0], dtype=dtype)  # off-screen
    return means2d, conics, opacities, colors, depths, radii


BG = torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64)


def _both(scene, width, height, settings):
    means2d, conics, opacities, colors, depths, radii = scene
    fast_in = [t.clone().requires_grad_(True) for t in (means2d, conics, opacities, colors, BG)]
    ref_in = [t.clone().requires_grad_(True) for t in (means2d, conics, opacities, colors, BG)]
    fast = rasterize(*fast_in[:4], depths, radii, width, height, fast_in[4], settings)
    ref = rasterize_reference(*ref_in[:4], depths, radii, width, height, ref_in[4], settings)
    return fast, ref, fast_in, ref_in


@pytest.mark.parametrize("n, width, height, chunk", [(30, 24, 20, 4), (30, 24, 20, 64), (1, 16, 16, 8),
                                                     (60, 40, 17, 16)])
def test_fast_matches_reference_forward_and_backward(n, width, height, chunk):
    settings = RasterSettings(tile_size=8, chunk_size=chunk)
    (img, alpha), (img_ref, alpha_ref), fast_in, ref_in = _both(random_2d_scene(n, width, height), width, height,
                                                                 settings)
    # float64, same operations in a different order: agreement to rounding.
    torch.testing.assert_close(img, img_ref, atol=1e-10, rtol=0)
    torch.testing.assert_close(alpha, alpha_ref, atol=1e-10, rtol=0)
    g_img, g_alpha = torch.randn_like(img), torch.randn_like(alpha)
    ((img * g_img).sum() + (alpha * g_alpha).sum()).backward()
    ((img_ref * g_img).sum() + (alpha_ref * g_alpha).sum()).backward()
    for fast, ref in zip(fast_in, ref_in):
        torch.testing.assert_close(fast.grad, ref.grad, atol=1e-9, rtol=1e-9)


def test_zero_gaussians_give_background():
    empty = [torch.zeros(0, 2), torch.zeros(0, 3), torch.zeros(0), torch.zeros(0, 3), torch.zeros(0),
             torch.zeros(0, dtype=torch.long)]
    img, alpha = rasterize(*empty, 9, 5, BG.float())
    assert img.shape == (3, 5, 9)
    torch.testing.assert_close(img, BG.float()[:, None, None].expand(3, 5, 9))
    assert alpha.abs().max() == 0


def test_early_termination_matches_reference():
    # Many opaque Gaussians stacked on one pixel: transmittance hits the 1e-4 floor, later ones are skipped.
    n = 12
    means2d = torch.full((n, 2), 4.0, dtype=torch.float64)
    conics = torch.tensor([[0.05, 0.0, 0.05]], dtype=torch.float64).repeat(n, 1)
    opacities = torch.full((n,), 0.95, dtype=torch.float64)
    colors = torch.rand(n, 3, dtype=torch.float64)
    depths = torch.arange(n, dtype=torch.float64)
    radii = torch.full((n,), 6, dtype=torch.long)
    scene = (means2d, conics, opacities, colors, depths, radii)
    (img, alpha), (img_ref, alpha_ref), _, _ = _both(scene, 8, 8, RasterSettings(tile_size=8, chunk_size=3))
    torch.testing.assert_close(img, img_ref, atol=1e-12, rtol=0)
    assert alpha.max() > 0.999


def test_gradcheck_fast_path():
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(4, 6, 5, seed=2)
    radii[:] = 6
    settings = RasterSettings(tile_size=4, chunk_size=2)
    inputs = tuple(t.clone().requires_grad_(True) for t in (means2d, conics, opacities, colors, BG))
    def f(m, c, o, col, bg):
        return rasterize(m, c, o, col, depths, radii, 6, 5, bg, settings)
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-5)


def test_pixel_partials_equal_autograd_jacobian_and_gram():
    width, height = 16, 16
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(5, width, height, seed=5)
    radii[:] = 10
    settings = RasterSettings(tile_size=8, chunk_size=2)
    pp = pixel_attribute_partials(means2d, conics, opacities, colors, depths, radii, width, height, BG, settings)
    def f(m, c, o, col):
        return rasterize_reference(m, c, o, col, depths, radii, width, height, BG, settings)[0]
    jm, jc, jo, jcol = torch.autograd.functional.jacobian(f, (means2d, conics, opacities, colors))
    dense = torch.cat([jm, jc, jo[..., None], jcol], dim=-1)  # [3, H, W, N, 9]
    dense = dense.permute(1, 2, 3, 0, 4).reshape(height * width, 5, 3, 9)  # [HW, N, D, A]
    packed = torch.zeros_like(dense)
    packed[pp.pixel_ids, pp.gaussian_ids] = pp.jac
    torch.testing.assert_close(packed, dense, atol=1e-10, rtol=1e-9)
    gram = attribute_gram(means2d, conics, opacities, colors, depths, radii, width, height, BG, settings)
    expected = torch.einsum("pnda,pndb->nab", dense, dense)
    torch.testing.assert_close(gram, expected, atol=1e-9, rtol=1e-9)
