"""Fisher view factors on real blocks of a small model: R R^T == the dense blocks, gains == the dense twin and dense
torch.logdet, float32 storage accuracy, cache budgets (too small for one view: say so, stream)."""
import logging
import math

import pytest
import torch

from active import build_selector
from active.base import SelectionContext
from active.fisher import FisherOracle, fisher_view_blocks, fisher_view_diagonals, fisher_view_factors
from active.logdet import BlockInformation, DenseBlockInformation
from arguments import FisherSettings
from gaussian_renderer import RasterSettings
from gaussian_renderer.fisher_partials import RAW_PARAMETER_GROUPS
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from tests.scenes import intrinsics_for, look_at_viewmat, random_gaussians

W, H = 24, 24
SETTINGS = RasterSettings(tile_size=8, chunk_size=8, backend="compiled")
BG = torch.zeros(3)


pytestmark = pytest.mark.usefixtures("single_torch_thread")  # tiny batched linear algebra (tests/conftest.py)


def model(n=80, seed=3):
    """float32 Gaussians (as trained models are), spread so that each view sees only part of them."""
    p = random_gaussians(n, seed=seed, spread=1.4, scale=0.12, sh_degree=1, dtype=torch.float32)
    gaussians = GaussianModel(1, {"means": p["means"], "quats": p["quats"], "log_scales": p["log_scales"],
                                  "logit_opacities": p["logit_opacities"] + 1.0, "sh_dc": p["sh_coeffs"][:, :1],
                                  "sh_rest": p["sh_coeffs"][:, 1:]})
    gaussians.active_sh_degree = 1
    return gaussians


def cameras(count=8):
    k = intrinsics_for(W, H, 40.0, dtype=torch.float32)
    out = []
    for i in range(count):
        a = 2 * math.pi * i / count
        view = look_at_viewmat((2.2 * math.cos(a), 2.2 * math.sin(a), 0.8 + 0.2 * i), dtype=torch.float32)
        out.append(Camera(i, f"v{i}", view, *k.tolist(), W, H))
    return out


def test_factors_equal_dense_blocks_on_the_visible_gaussians():
    gaussians, cams = model(), cameras()
    for cam in cams[:3]:
        blocks = fisher_view_blocks(gaussians, cam, BG, SETTINGS, sigma=0.5)  # [N, 14, 14]
        view = fisher_view_factors(gaussians, cam, BG, SETTINGS, sigma=0.5)
        seen = torch.nonzero(blocks.abs().flatten(1).amax(1) > 0).flatten()
        assert 0 < len(seen) < gaussians.num_gaussians  # the view sees part of the model
        assert torch.equal(view.indices, seen) and view.packed.shape == (len(seen), 90)
        assert (view.num_params, view.num_columns) == (14, 9)
        scale = float(blocks.abs().max())
        torch.testing.assert_close(view.dense(), blocks, rtol=1e-5, atol=1e-6 * scale)
        # ^ J_proj is float32 arithmetic (a float32 model), evaluated on the visible subset: batched float32 ops may
        # round differently for another batch size, ~1e-7 relative (seen 2e-7)


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_diagonals_on_the_visible_gaussians_equal_the_dense_block_diagonals(backend):
    """fisher_view_diagonals computes J_proj for the seen Gaussians only; its rows equal the diagonals of the dense
    blocks of every Gaussian (zero rows for the unseen), for both rasterizer backends."""
    gaussians, settings = model(), RasterSettings(tile_size=8, chunk_size=8, backend=backend)
    for cam in cameras()[:3]:
        blocks = fisher_view_blocks(gaussians, cam, BG, settings, sigma=0.5, param_groups=RAW_PARAMETER_GROUPS)
        diag = fisher_view_diagonals(gaussians, cam, BG, settings, sigma=0.5)  # [N, 23]
        dense = torch.diagonal(blocks, dim1=-2, dim2=-1)
        unseen = blocks.abs().flatten(1).amax(1) == 0
        assert 0 < int(unseen.sum()) < gaussians.num_gaussians and diag.shape == dense.shape
        assert torch.equal(diag[unseen], torch.zeros_like(diag[unseen]))
        torch.testing.assert_close(diag, dense, rtol=1e-5, atol=1e-6 * float(dense.abs().max()))  # float32 J_proj


@pytest.mark.parametrize("train_views", [tuple(range(8)), (0, 4)])  # all views (prior covers every candidate block)
def test_gains_on_real_blocks_equal_dense_twin_and_dense_logdet(train_views):
    gaussians, cams = model(), cameras()
    prior = sum(fisher_view_blocks(gaussians, cams[v], BG, SETTINGS) for v in train_views)
    sparse, twin = BlockInformation(prior), DenseBlockInformation(prior)
    candidates = [v for v in range(8) if v not in train_views] or [1, 2, 3, 5]
    views = {v: fisher_view_factors(gaussians, cams[v], BG, SETTINGS) for v in candidates}
    unseen = prior.abs().flatten(1).amax(1) == 0  # [N] Gaussians no training view sees: ridge 1e-8 only
    exposed = bool(unseen[torch.cat([views[v].indices for v in candidates])].any())
    assert exposed == (train_views == (0, 4))
    # Over a 1e-8 ridge, a dense rank-9 block's roundoff in its 5 null directions, ~eps |H|, is whitened to
    # eps |H| / 1e-8 (the factor form has no such directions): the dense references then agree only to that, over
    # N * P eigenvalues. Where every block a candidate sees has a prior, 1e-9 relative holds (condition <= ~1e6).
    noise = 80 * 14 * 2.2e-16 * float(prior.abs().max()) / 1e-8 if exposed else 0.0
    a = torch.block_diag(*twin.matrix)  # [N P, N P]
    for pick in candidates[1:3]:
        for v in candidates:
            blocks = views[v].dense()  # the same information as dense [N, 14, 14] blocks
            gain = sparse.gain(views[v])
            assert gain > 1.0
            assert math.isclose(gain, twin.gain(blocks), rel_tol=1e-9, abs_tol=noise)
            assert math.isclose(gain, float(torch.logdet(a + torch.block_diag(*blocks)) - torch.logdet(a)),
                                rel_tol=1e-9, abs_tol=noise)
        sparse.add(views[pick])
        twin.add(views[pick].dense())
        a = a + torch.block_diag(*views[pick].dense())
        assert math.isclose(sparse.rho(), twin.rho(), rel_tol=1e-9, abs_tol=noise)


def test_float32_storage_keeps_gains_to_1e6_and_the_picks():
    # Storage rounds each factor entry to 2^-24 relative; J_proj itself is float32 arithmetic (~1e-7), so the
    # cached float32 factors lose nothing the blocks had. Gains move by ~1e-7 relative.
    gaussians, cams = model(), cameras()
    prior = sum(fisher_view_blocks(gaussians, cams[v], BG, SETTINGS) for v in (0, 4))
    info = BlockInformation(prior)
    for v in (1, 2, 3, 5, 6, 7):
        view = fisher_view_factors(gaussians, cams[v], BG, SETTINGS)
        assert math.isclose(info.gain(view.stored_as(torch.float32)), info.gain(view), rel_tol=1e-6)
    picks = {}
    for storage in (torch.float32, torch.float64):
        oracle = FisherOracle.build(gaussians, cams, [0, 4], BG, SETTINGS)
        oracle.blocks.stored = lambda blocks, storage=storage: blocks.stored_as(storage)
        sel = build_selector("pop_gs").select(SelectionContext([1, 2, 3, 5, 6, 7], oracle,
                                                               torch.Generator().manual_seed(0), 0), 3)
        picks[storage] = sel.ids, sel.gains
    assert picks[torch.float32][0] == picks[torch.float64][0]
    torch.testing.assert_close(torch.tensor(picks[torch.float32][1]), torch.tensor(picks[torch.float64][1]),
                               rtol=1e-6, atol=0)


def test_cache_budget_too_small_for_one_view_streams_and_says_so(monkeypatch, caplog):
    gaussians, cams = model(), cameras()
    reference = FisherOracle.build(gaussians, cams, [0, 4], BG, SETTINGS,
                                   fisher=FisherSettings(fisher_mode="streaming"))
    expected = build_selector("pop_gs").select(SelectionContext([1, 2, 3, 5], reference,
                                                                torch.Generator().manual_seed(0), 0), 2)
    monkeypatch.setattr("active.fisher.cache_budget", lambda cache_mb: 1000)  # bytes: below one view's factors
    with caplog.at_level(logging.WARNING):
        oracle = FisherOracle.build(gaussians, cams, [0, 4], BG, SETTINGS,
                                    fisher=FisherSettings(fisher_mode="cached"))
    assert "more than the cache budget of 0.0 MB" in caplog.text and "switching the Fisher oracle to streaming" \
        in caplog.text
    assert oracle.blocks.streaming
    sel = build_selector("pop_gs").select(SelectionContext([1, 2, 3, 5], oracle, torch.Generator().manual_seed(0), 0),
                                          2)
    assert sel.ids == expected.ids and sel.gains == expected.gains  # streaming serves the same float32 factors


def test_cached_factors_are_bounded_by_the_budget_in_bytes():
    gaussians, cams = model(), cameras()
    oracle = FisherOracle.build(gaussians, cams, [0, 4], BG, SETTINGS, fisher=FisherSettings(fisher_mode="cached"))
    sizes = {v: oracle.blocks(v).nbytes for v in (1, 2, 3)}
    assert all(oracle.blocks(v).packed.dtype == torch.float32 for v in (1, 2, 3))
    assert oracle.blocks._cached_bytes == sum(sizes.values())
    size5 = FisherOracle.build(gaussians, cams, [0, 4], BG, SETTINGS).blocks(5).nbytes
    oracle.blocks.cache_bytes = sizes[3] + size5  # room for the two most recent views only
    oracle.blocks(5)
    assert list(oracle.blocks._cache) == [3, 5] and oracle.blocks._cached_bytes == sizes[3] + size5


def test_non_finite_model_is_one_line_error():
    from utils.errors import UserError
    gaussians, cams = model(), cameras()
    with torch.no_grad():
        gaussians.params["sh_dc"][7, 0, 1] = float("nan")
    with pytest.raises(UserError, match="view Fisher blocks of 80 Gaussians contain NaN or inf"):
        fisher_view_factors(gaussians, cams[0], BG, SETTINGS)


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_view_gram_over_the_projected_gaussians_equals_the_gram_over_all(backend):
    """`fisher._attribute_gram` renders only the Gaussians the view projects (radii > 0); the Grams, dense and seen,
    equal `attribute_gram` over the whole model, culled rows zero (some are culled in this view)."""
    from active.fisher import _attribute_gram
    from gaussian_renderer import attribute_gram
    from gaussian_renderer.projection import camera_center, project_gaussians
    from gaussian_renderer.sh import sh_to_colors
    gaussians, cam = model(), cameras()[0]
    settings = RasterSettings(tile_size=8, chunk_size=8, backend=backend)
    # the compiled backend projects and shades the float32 model in float64 (`project_and_shade`): so does the twin
    dtype, tol = (torch.float64, 1e-9) if backend == "compiled" else (torch.float32, 1e-12)
    p = {k: v.detach().to(dtype) for k, v in gaussians.params.items()}
    with torch.no_grad():
        proj = project_gaussians(p["means"], p["quats"] / p["quats"].norm(dim=-1, keepdim=True),
                                 p["log_scales"].exp(), cam.viewmat, cam.intrinsics, W, H)
        colors = sh_to_colors(torch.cat([p["sh_dc"], p["sh_rest"]], 1), p["means"],
                              camera_center(cam.viewmat.to(dtype)), 1)
        expected = attribute_gram(proj.means2d, proj.conics, gaussians.opacities.to(dtype), colors, proj.depths,
                                  proj.radii, W, H, BG, settings)  # [N, A, A]
        dense = _attribute_gram(gaussians, cam, BG, settings)
        indices, seen = _attribute_gram(gaussians, cam, BG, settings, seen_only=True)
    assert 0 < int((proj.radii > 0).sum()) < gaussians.num_gaussians
    torch.testing.assert_close(dense, expected, rtol=tol, atol=tol * float(expected.abs().max()))
    assert (expected.flatten(1).abs().sum(1) > 0).nonzero().squeeze(1).tolist() == indices.tolist()
    torch.testing.assert_close(seen, expected[indices], rtol=tol, atol=tol * float(expected.abs().max()))
