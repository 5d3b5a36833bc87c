"""Fast tile rasterizer vs the dense reference: images, alphas and gradients; cut-offs and edge cases."""
import pytest
import torch

from gaussian_renderer import RasterSettings, rasterize
from gaussian_renderer.reference import rasterize_reference
from utils.errors import UserError

BG = torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64)
BACKENDS = ["torch", "compiled"]  # every rasterizer test names its backend ("auto" would test only one)


def random_2d_scene(n, width, height, seed=0, dtype=torch.float64):
    """n overlapping 2D Gaussians; for n > 4 also one culled, one off-screen, one clamped, one indefinite conic."""
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
    if n > 4:
        radii[0] = 0  # culled: must be ignored even though it sits on screen
        means2d[1] = torch.tensor([-30.0, 5.0], dtype=dtype)  # off-screen
        opacities[2] = 1.0  # alpha clamps at alpha_max near its centre
        conics[3] = torch.tensor([0.3, 0.5, 0.3], dtype=dtype)  # indefinite: power > 0 in places, skipped there
    return means2d, conics, opacities, colors, depths, radii


def _run(fn, scene, width, height, settings, **kwargs):
    """Render with fn; returns (image, alpha, leaves) with the differentiable inputs as leaves."""
    means2d, conics, opacities, colors, depths, radii = scene
    leaves = [t.clone().requires_grad_(True) for t in (means2d, conics, opacities, colors, BG)]
    image, alpha = fn(*leaves[:4], depths, radii, width, height, leaves[4], settings, **kwargs)
    return image, alpha, leaves


def _grads(image, alpha, leaves, seed=1):
    """Gradients of <image, g> + <alpha, h> for a fixed random cotangent (g, h)."""
    gen = torch.Generator().manual_seed(seed)
    g = torch.randn(image.shape, generator=gen, dtype=image.dtype)
    h = torch.randn(alpha.shape, generator=gen, dtype=alpha.dtype)
    return torch.autograd.grad((image * g).sum() + (alpha * h).sum(), leaves, allow_unused=True)


@pytest.mark.parametrize("n, width, height, tile, chunk", [
    (30, 24, 20, 4, 32),  # default tiles, non-square image
    (30, 24, 20, 16, 4),  # 16 px tiles, lists longer than a chunk
    (30, 24, 20, 8, 64),
    (1, 16, 16, 4, 8),
    (60, 40, 17, 16, 16),  # height not a multiple of the tile size
])
@pytest.mark.parametrize("backend", BACKENDS)
def test_fast_matches_reference_forward_and_backward(n, width, height, tile, chunk, backend):
    settings = RasterSettings(tile_size=tile, chunk_size=chunk, backend=backend)
    scene = random_2d_scene(n, width, height)
    img, alpha, fast_leaves = _run(rasterize, scene, width, height, settings)
    img_ref, alpha_ref, ref_leaves = _run(rasterize_reference, scene, width, height, settings)
    assert img.shape == (3, height, width) and alpha.shape == (height, width)
    # float64, the same operations in a different order: agreement to rounding (the spec asks for 1e-5).
    torch.testing.assert_close(img, img_ref, atol=1e-10, rtol=0)
    torch.testing.assert_close(alpha, alpha_ref, atol=1e-10, rtol=0)
    for fast, ref in zip(_grads(img, alpha, fast_leaves), _grads(img_ref, alpha_ref, ref_leaves)):
        torch.testing.assert_close(fast, ref, atol=1e-9, rtol=1e-9)  # float64 rounding through the chain


def test_scene_exercises_every_rule():
    # Guards the test above against a scene where a rule never fires.
    width, height = 24, 20
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(30, width, height)
    ys, xs = torch.meshgrid(torch.arange(height) + 0.5, torch.arange(width) + 0.5, indexing="ij")
    dx, dy = xs[None] - means2d[:, 0, None, None], ys[None] - means2d[:, 1, None, None]  # [N, H, W]
    power = -0.5 * (conics[:, 0, None, None] * dx ** 2 + conics[:, 2, None, None] * dy ** 2) \
        - conics[:, 1, None, None] * dx * dy
    alpha = opacities[:, None, None] * torch.exp(power)
    assert (alpha > 0.99).any() and (power > 0).any() and ((alpha < 1 / 255) & (alpha > 0)).any()


@pytest.mark.parametrize("backend", BACKENDS)
def test_culled_gaussian_is_ignored(backend):
    width, height = 24, 20
    scene = list(random_2d_scene(30, width, height))
    settings = RasterSettings(backend=backend)
    img, alpha, _ = _run(rasterize, scene, width, height, settings)
    scene[3] = scene[3].clone()
    scene[3][0] = torch.tensor([5.0, -5.0, 5.0], dtype=torch.float64)  # recolour the culled Gaussian
    img2, alpha2, _ = _run(rasterize, scene, width, height, settings)
    assert torch.equal(img, img2) and torch.equal(alpha, alpha2)


@pytest.mark.parametrize("fn, backend", [(rasterize, "torch"), (rasterize, "compiled"), (rasterize_reference, "torch")])
def test_no_visible_gaussians_give_background(fn, backend):
    empty = (torch.zeros(0, 2), torch.zeros(0, 3), torch.zeros(0), torch.zeros(0, 3), torch.zeros(0),
             torch.zeros(0, dtype=torch.long))
    culled = random_2d_scene(6, 9, 5, dtype=torch.float32)[:5] + (torch.zeros(6, dtype=torch.long),)
    for scene in (empty, culled):
        img, alpha = fn(*scene, 9, 5, BG.float(), RasterSettings(backend=backend))
        assert img.shape == (3, 5, 9)
        torch.testing.assert_close(img, BG.float()[:, None, None].expand(3, 5, 9), atol=0, rtol=0)
        assert alpha.abs().max() == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_background_gradient_is_transmittance_weighted(backend):
    width, height = 24, 20
    img, alpha, leaves = _run(rasterize, random_2d_scene(30, width, height), width, height,
                              RasterSettings(backend=backend))
    grad_bg = torch.autograd.grad(img.sum(), leaves[4])[0]
    # d image / d bg_c = T_final per pixel, summed: (1 - alpha) summed over pixels, every channel. Rounding only.
    torch.testing.assert_close(grad_bg, (1 - alpha).sum().expand(3), atol=1e-10, rtol=0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_chunk_size_does_not_change_results(backend):
    width, height = 24, 20
    scene = random_2d_scene(30, width, height, seed=3)
    results = []
    for chunk in (1, 3, 1000):  # 1 and 3 force many chunks per tile list; 1000 is a single chunk
        img, alpha, leaves = _run(rasterize, scene, width, height,
                                  RasterSettings(tile_size=16, chunk_size=chunk, backend=backend))
        results.append((img, alpha, *_grads(img, alpha, leaves)))
    for other in results[1:]:
        for a, b in zip(results[0], other):
            torch.testing.assert_close(a, b, atol=1e-12, rtol=1e-12)  # same sums, split differently


@pytest.mark.parametrize("backend", BACKENDS)
def test_tile_cutoff_only_drops_pairs_the_alpha_test_skips(backend):
    # With radii too large to bind, the opacity-aware tile reach must not change the image: it only removes
    # pairs whose alpha is below alpha_min anyway. Compare with the dense twin that has no tile rule at all.
    width, height = 24, 20
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(30, width, height, seed=4)
    conics[3] = conics[4]  # positive-definite conics only: the reach bound assumes them
    scene = (means2d, conics, opacities, colors, depths, torch.where(radii > 0, 100, 0))
    settings = RasterSettings(tile_size=4, backend=backend)
    img, alpha, _ = _run(rasterize, scene, width, height, settings)
    img_all, alpha_all, _ = _run(rasterize_reference, scene, width, height, settings, tile_cutoff=False)
    torch.testing.assert_close(img, img_all, atol=1e-10, rtol=0)  # float64 rounding
    torch.testing.assert_close(alpha, alpha_all, atol=1e-10, rtol=0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_early_termination_matches_reference(backend):
    # Opaque Gaussians stacked on one spot: transmittance reaches the 1e-4 floor and later ones are skipped.
    n = 12
    means2d = torch.full((n, 2), 4.0, dtype=torch.float64)
    conics = torch.tensor([[0.05, 0.0, 0.05]], dtype=torch.float64).repeat(n, 1)
    opacities = torch.full((n,), 0.95, dtype=torch.float64)
    colors = torch.rand(n, 3, dtype=torch.float64)
    depths = torch.arange(n, dtype=torch.float64)
    radii = torch.full((n,), 6, dtype=torch.long)
    scene = (means2d, conics, opacities, colors, depths, radii)
    settings = RasterSettings(tile_size=8, chunk_size=3, backend=backend)
    img, alpha, fast_leaves = _run(rasterize, scene, 8, 8, settings)
    img_ref, alpha_ref, ref_leaves = _run(rasterize_reference, scene, 8, 8, settings)
    torch.testing.assert_close(img, img_ref, atol=1e-12, rtol=0)  # float64 rounding
    # Stopped pixels keep T >= transmittance_min: alpha ends just below 1 - 1e-4.
    assert 1 - 1e-3 < alpha.max() <= 1 - 1e-4
    fast_grads = _grads(img, alpha, fast_leaves)
    for fast, ref in zip(fast_grads, _grads(img_ref, alpha_ref, ref_leaves)):
        torch.testing.assert_close(fast, ref, atol=1e-10, rtol=1e-10)  # float64 rounding
    # At the centre pixel the stop happens after a few Gaussians: the ones behind get no colour gradient there.
    img, _, leaves = _run(rasterize, scene, 8, 8, settings)
    grad_colors = torch.autograd.grad(img[:, 3, 3].sum(), leaves[3])[0]
    assert (grad_colors[:3] > 0).all() and (grad_colors[-3:] == 0).all()


def test_gradcheck_fast_path():
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(4, 6, 5, seed=2)
    radii[:] = 6
    settings = RasterSettings(tile_size=4, chunk_size=2, backend="torch")  # compiled: test_compiled_rasterizer.py
    inputs = tuple(t.clone().requires_grad_(True) for t in (means2d, conics, opacities, colors, BG))

    def f(m, c, o, col, bg):
        return rasterize(m, c, o, col, depths, radii, 6, 5, bg, settings)
    # Central differences with eps 1e-6 in float64: truncation error ~1e-12, well inside atol.
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-5)


@pytest.mark.parametrize("bad", [dict(tile_size=0), dict(tile_size=2.5), dict(chunk_size=0),
                                 dict(alpha_max=1.0), dict(alpha_min=0.0), dict(transmittance_min=1.0)])
def test_bad_settings_raise_user_error(bad):
    with pytest.raises(UserError, match="must|need"):
        RasterSettings(**bad)
