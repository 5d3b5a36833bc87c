"""Splitting a depth step's tiles into groups (bounded working set) changes nothing: image, gradients, Gram."""
import pytest
import torch

from gaussian_renderer import RasterSettings, attribute_gram, rasterize, tiles
from gaussian_renderer.reference import rasterize_reference
from tests.test_rasterize import _grads, _run, random_2d_scene


@pytest.mark.parametrize("tiles_per_group", [1, 3])
def test_grouped_chunks_match_the_reference(monkeypatch, tiles_per_group):
    settings = RasterSettings(tile_size=4, chunk_size=4)
    width, height = 24, 20  # 30 tiles: several groups per depth step, a last partial group
    monkeypatch.setattr(tiles, "MAX_CHUNK_PAIRS", tiles_per_group * settings.chunk_size * settings.tile_size ** 2)
    scene = random_2d_scene(30, width, height)
    img, alpha, leaves = _run(rasterize, scene, width, height, settings)
    img_ref, alpha_ref, ref_leaves = _run(rasterize_reference, scene, width, height, settings)
    # float64, the same operations in another order: agreement to rounding (as in test_rasterize.py).
    torch.testing.assert_close(img, img_ref, atol=1e-10, rtol=0)
    torch.testing.assert_close(alpha, alpha_ref, atol=1e-10, rtol=0)
    for fast, ref in zip(_grads(img, alpha, leaves), _grads(img_ref, alpha_ref, ref_leaves)):
        torch.testing.assert_close(fast, ref, atol=1e-9, rtol=1e-9)


def test_grouping_leaves_the_gram_unchanged(monkeypatch):
    settings = RasterSettings(tile_size=4, chunk_size=4)
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(30, 24, 20)
    args = (means2d, conics, opacities, colors, depths, radii, 24, 20, torch.zeros(3, dtype=torch.float64), settings)
    whole = attribute_gram(*args)
    monkeypatch.setattr(tiles, "MAX_CHUNK_PAIRS", 2 * settings.chunk_size * settings.tile_size ** 2)
    torch.testing.assert_close(attribute_gram(*args), whole, atol=1e-12, rtol=1e-10)  # float64 summation order
