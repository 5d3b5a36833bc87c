"""Closed-form per-pair partials and the per-Gaussian Gram matrix vs brute-force autograd on the dense reference."""
import pytest
import torch

from gaussian_renderer import RasterSettings, attribute_gram, pixel_attribute_partials, rasterize, seen_attribute_gram
from gaussian_renderer.reference import rasterize_reference
from tests.test_rasterize import BG, random_2d_scene

WIDTH, HEIGHT = 16, 16


def small_scene(seed=5):
    """5 Gaussians on 16x16: one clamped (opacity 1) and, for seed 5, overlaps in every tile size tested."""
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(5, WIDTH, HEIGHT, seed=seed)
    radii[:] = 10
    opacities[2] = 1.0  # alpha clamps at 0.99 on the pixel at its centre: zero geometry/opacity derivative there
    means2d[2] = torch.tensor([8.5, 8.5], dtype=torch.float64)
    return means2d, conics, opacities, colors, depths, radii


def dense_jacobian(scene, settings):
    """d image / d (means2d, conics, opacities, colors) of the reference by autograd, as [H*W, N, D, A]."""
    means2d, conics, opacities, colors, depths, radii = scene

    def image(m, c, o, col):
        return rasterize_reference(m, c, o, col, depths, radii, WIDTH, HEIGHT, BG, settings)[0]
    jm, jc, jo, jcol = torch.autograd.functional.jacobian(image, (means2d, conics, opacities, colors))
    dense = torch.cat([jm, jc, jo[..., None], jcol], dim=-1)  # [D, H, W, N, A]
    n, d = colors.shape
    return dense.permute(1, 2, 3, 0, 4).reshape(HEIGHT * WIDTH, n, d, 6 + d)


SETTINGS = [RasterSettings(backend="compiled"), RasterSettings(tile_size=8, chunk_size=2, backend="torch"),
            RasterSettings(tile_size=16, chunk_size=1, backend="torch"),
            RasterSettings(tile_size=8, chunk_size=2, backend="compiled")]


@pytest.fixture(scope="module", params=range(len(SETTINGS)),
                ids=["compiled-default", "torch-tile8-chunk2", "torch-tile16-chunk1", "compiled-tile8-chunk2"])
def case(request):
    settings = SETTINGS[request.param]
    scene = small_scene()
    return scene, settings, dense_jacobian(scene, settings)


def test_pair_partials_equal_autograd_jacobian(case):
    scene, settings, dense = case
    pp = pixel_attribute_partials(*scene, WIDTH, HEIGHT, BG, settings)
    assert pp.jac.shape == (pp.pixel_ids.shape[0], 3, 9)
    packed = torch.zeros_like(dense)
    packed[pp.pixel_ids, pp.gaussian_ids] = pp.jac
    # float64 closed form vs autograd through the same arithmetic: rounding only.
    torch.testing.assert_close(packed, dense, atol=1e-10, rtol=1e-9)
    # Every pair the jacobian sees is listed exactly once (no duplicates, none missing).
    keys = pp.pixel_ids * 5 + pp.gaussian_ids
    assert keys.unique().numel() == keys.numel()
    assert keys.numel() >= int((dense.abs().sum((2, 3)) > 0).sum())
    # The clamped Gaussian has pairs with zero alpha derivative but a colour derivative.
    clamped = pp.jac[pp.gaussian_ids == 2]
    assert ((clamped[:, :, :6].abs().sum((1, 2)) == 0) & (clamped[:, 0, 6] > 0)).any()


def test_gram_equals_sum_of_jacobian_products(case):
    scene, settings, dense = case
    gram = attribute_gram(*scene, WIDTH, HEIGHT, BG, settings)
    assert gram.dtype == torch.float64 and gram.shape == (5, 9, 9)
    expected = torch.einsum("pnda,pndb->nab", dense, dense)
    torch.testing.assert_close(gram, expected, atol=1e-9, rtol=1e-9)  # float64 rounding over 256 pixels


def test_weighted_gram(case):
    scene, settings, dense = case
    weights = torch.rand(HEIGHT, WIDTH, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    gram = attribute_gram(*scene, WIDTH, HEIGHT, BG, settings, weights=weights)
    expected = torch.einsum("p,pnda,pndb->nab", weights.reshape(-1), dense, dense)
    torch.testing.assert_close(gram, expected, atol=1e-9, rtol=1e-9)  # float64 rounding


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_gram_symmetric_psd_and_float32_close(backend):
    scene = small_scene(seed=7)
    settings = RasterSettings(backend=backend)
    gram = attribute_gram(*scene, WIDTH, HEIGHT, BG, settings)
    torch.testing.assert_close(gram, gram.transpose(1, 2), atol=0, rtol=0)
    eig = torch.linalg.eigvalsh(gram)
    assert (eig >= -1e-12 * eig.abs().max()).all()  # PSD up to float64 rounding
    gram32 = attribute_gram(*(t.float() if t.is_floating_point() else t for t in scene), WIDTH, HEIGHT, BG.float(),
                            settings)
    assert gram32.dtype == torch.float64
    # float32 per-tile sums: relative error ~1e-6 of the largest entry per Gaussian.
    scale = gram.abs().amax((1, 2), keepdim=True).clamp_min(1e-30)  # the off-screen Gaussian has G = 0
    assert ((gram32 - gram).abs() / scale).max() < 1e-4


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_seen_gram_is_the_full_gram_at_its_nonzero_rows(backend):
    """seen_attribute_gram (compiled: rows assembled from the moment sums; torch: selected from the full Gram) equals
    attribute_gram's non-zero rows exactly, in order, on a 24x20 scene with culled and off-screen Gaussians."""
    width, height = 24, 20
    scene = random_2d_scene(30, width, height, seed=9)
    settings = RasterSettings(tile_size=8, chunk_size=4, backend=backend)
    full = attribute_gram(*scene, width, height, BG, settings)  # [N, 9, 9]
    nonzero = torch.nonzero((full != 0).flatten(1).any(1)).flatten()
    assert 0 < len(nonzero) < 30  # some Gaussians are not seen
    indices, gram = seen_attribute_gram(*scene, width, height, BG, settings)
    assert torch.equal(indices, nonzero) and torch.equal(gram, full[nonzero])
    none_seen = list(scene)
    none_seen[0] = scene[0] + 1000.0  # every mean far off-screen
    indices, gram = seen_attribute_gram(*none_seen, width, height, BG, settings)
    assert indices.shape == (0,) and gram.shape == (0, 9, 9)


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_partials_chain_to_the_fast_backward(backend):
    # sum over pairs of g_pixel . jac equals the gradient rasterize's backward computes, on a 24x20 scene with
    # culled, off-screen, clamped and indefinite-conic Gaussians.
    width, height = 24, 20
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(30, width, height, seed=9)
    settings = RasterSettings(tile_size=16, chunk_size=4, backend=backend)  # 16 px tiles overhang the 24x20 image
    leaves = [t.clone().requires_grad_(True) for t in (means2d, conics, opacities, colors)]
    image, _ = rasterize(*leaves, depths, radii, width, height, BG, settings)
    g = torch.randn(image.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
    grads = torch.cat([x.reshape(30, -1) for x in torch.autograd.grad((image * g).sum(), leaves)], dim=1)
    pp = pixel_attribute_partials(means2d, conics, opacities, colors, depths, radii, width, height, BG, settings)
    g_pix = g.reshape(3, -1).T[pp.pixel_ids]  # [M, D]
    chained = torch.zeros(30, 9, dtype=torch.float64).index_add_(0, pp.gaussian_ids,
                                                                 torch.einsum("md,mda->ma", g_pix, pp.jac))
    torch.testing.assert_close(chained, grads, atol=1e-10, rtol=1e-9)  # float64 rounding


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_empty_scene(backend):
    scene = (torch.zeros(0, 2), torch.zeros(0, 3), torch.zeros(0), torch.zeros(0, 3), torch.zeros(0),
             torch.zeros(0, dtype=torch.long))
    assert attribute_gram(*scene, 8, 8, BG.float(), RasterSettings(backend=backend)).shape == (0, 9, 9)
    pp = pixel_attribute_partials(*scene, 8, 8, BG.float(), RasterSettings(backend=backend))
    assert pp.jac.shape == (0, 3, 9) and pp.pixel_ids.numel() == 0
