"""The torch path's split of a depth step's tiles into groups (bounded working set) vs the dense reference.

With the default `MAX_CHUNK_PAIRS` every test image fits in one group, so these tests shrink the bound to a few
tiles per group: the image, the gradients and the Gram matrix must still equal the dense reference's.
"""
import importlib

import pytest
import torch

from gaussian_renderer import RasterSettings, attribute_gram, rasterize
from gaussian_renderer.reference import rasterize_reference
from tests.test_attribute_partials import HEIGHT, WIDTH, dense_jacobian, small_scene
from tests.test_rasterize import BG, _grads, _run, random_2d_scene

CHUNK_ENGINE = "gaussian_renderer.tiles"  # the module whose MAX_CHUNK_PAIRS bounds the torch path's groups


def limit_chunk_pairs(monkeypatch, pairs: int) -> None:
    """Bound the torch path's pixel-Gaussian pairs per group to `pairs` for this test."""
    module = importlib.import_module(CHUNK_ENGINE)
    assert hasattr(module, "MAX_CHUNK_PAIRS"), f"{CHUNK_ENGINE} has no MAX_CHUNK_PAIRS; retarget CHUNK_ENGINE"
    monkeypatch.setattr(module, "MAX_CHUNK_PAIRS", pairs)


@pytest.mark.parametrize("tiles_per_group", [1, 3])
def test_grouped_chunks_match_the_reference(monkeypatch, tiles_per_group):
    settings = RasterSettings(tile_size=4, chunk_size=4, backend="torch")
    width, height = 24, 20  # 30 tiles: several groups per depth step, a last partial group
    limit_chunk_pairs(monkeypatch, tiles_per_group * 4 * 4 ** 2)  # chunk x pixels per tile = 64 pairs per tile
    scene = random_2d_scene(30, width, height)
    img, alpha, leaves = _run(rasterize, scene, width, height, settings)
    img_ref, alpha_ref, ref_leaves = _run(rasterize_reference, scene, width, height, settings)
    # float64, the same operations in another order: agreement to rounding (as in test_rasterize.py).
    torch.testing.assert_close(img, img_ref, atol=1e-10, rtol=0)
    torch.testing.assert_close(alpha, alpha_ref, atol=1e-10, rtol=0)
    for fast, ref in zip(_grads(img, alpha, leaves), _grads(img_ref, alpha_ref, ref_leaves)):
        torch.testing.assert_close(fast, ref, atol=1e-9, rtol=1e-9)


@pytest.mark.parametrize("tiles_per_group", [1, 3])
def test_grouped_gram_equals_the_reference_jacobian_products(monkeypatch, tiles_per_group):
    settings = RasterSettings(tile_size=4, chunk_size=2, backend="torch")  # 16 tiles, several depth steps
    scene = small_scene()
    limit_chunk_pairs(monkeypatch, tiles_per_group * 2 * 4 ** 2)
    gram = attribute_gram(*scene, WIDTH, HEIGHT, BG, settings)
    dense = dense_jacobian(scene, settings)  # [H*W, N, D, A] by autograd through the dense reference
    expected = torch.einsum("pnda,pndb->nab", dense, dense)
    torch.testing.assert_close(gram, expected, atol=1e-9, rtol=1e-9)  # float64 rounding over 256 pixels
