"""The pool-coverage oracle (`active.pool_cover_oracle`) against its definition written out one pose, Gaussian and
captured view at a time, with opacity and with per-pose pixel weights; its gains only shrink as views are committed
(lazy greedy makes exhaustive greedy's picks); the `cover_pool` selector and its `--pool_weight` through
`build_oracle`; `--pool_compare coverage` keeps whichever of greedy's and the farthest-camera picks covers more,
against both sets' objective written out, with its counts."""
import pytest
import torch

from active.base import SelectionContext
from active.blend_weights import VISIBLE_PIXELS, blend_weights
from active.farthest_point import farthest_point_picks
from active.fisher import build_oracle
from active.pool_cover_oracle import PoolCoverageOracle, check_memory
from active.registry import build_selector
from active.selectors.lazy_greedy import lazy_greedy_select
from active.selectors.pop_gs import exhaustive_greedy
from tests.test_cover import direction, in_frustum, scene
from tests.test_fisher_cache import spiral_cameras
from tests.test_view_factors import BG, SETTINGS, model
from utils.errors import UserError

pytestmark = pytest.mark.usefixtures("single_torch_thread")


def reference_objective(means, weights, cameras, committed):
    """F(S) = sum over poses c and Gaussians i in c's frustum of w_i min(1, min_s (1 - d_c,i . d_s,i) / 2)."""
    total = 0.0
    for c in range(len(cameras)):
        for i in range(means.shape[0]):
            p = means[i]
            if not in_frustum(p, cameras[c])[0]:
                continue
            error = 1.0
            for s in committed:
                if in_frustum(p, cameras[s])[0]:
                    error = min(error, 0.5 * (1.0 - float(direction(p, cameras[c]) @ direction(p, cameras[s]))))
            total += float(weights[i]) * error
    return total


def reference_pixel_objective(means, pair_weights, seen, cameras, committed):
    """F(S) = sum over poses c and Gaussians i that c sees of w_c,i min(1, min_{s sees i} (1 - d_c,i . d_s,i) / 2)."""
    total = 0.0
    for c in range(len(cameras)):
        for i in range(means.shape[0]):
            if not seen[i, c]:
                continue
            error = 1.0
            for s in committed:
                if seen[i, s]:
                    error = min(error, 0.5 * (1.0 - float(direction(means[i], cameras[c]) @
                                                          direction(means[i], cameras[s]))))
            total += float(pair_weights[i, c]) * error
    return total


def test_pose_dependent_weights_and_visibility_are_the_written_out_objective():
    means, _, cams = scene(n=40, seed=4)
    g = torch.Generator().manual_seed(4)
    pair_weights = torch.rand(40, len(cams), generator=g, dtype=torch.float64) * 30  # [N, V] pixels
    seen = pair_weights > 8.0  # about a quarter of the pairs are hidden
    oracle = PoolCoverageOracle(means, pair_weights, cams, [1, 6], inside=seen)
    before = reference_pixel_objective(means, pair_weights, seen, cams, [1, 6])
    assert oracle.objective() == pytest.approx(before, rel=1e-10)
    for view in (0, 4, 9):
        after = reference_pixel_objective(means, pair_weights, seen, cams, [1, 6, view])
        assert oracle.gain(view) == pytest.approx(before - after, rel=1e-9, abs=1e-12)


def test_gains_are_the_written_out_objective_drop():
    means, weights, cams = scene(n=40)
    oracle = PoolCoverageOracle(means, weights, cams, [0, 3])
    assert oracle.objective() == pytest.approx(reference_objective(means, weights, cams, [0, 3]), rel=1e-10)
    for view in (1, 5, 8):
        expected = reference_objective(means, weights, cams, [0, 3]) - reference_objective(means, weights, cams,
                                                                                            [0, 3, view])
        assert oracle.gain(view) == pytest.approx(expected, rel=1e-9, abs=1e-12)
    oracle.commit(5)
    assert oracle.objective() == pytest.approx(reference_objective(means, weights, cams, [0, 3, 5]), rel=1e-10)
    assert oracle.gain(5) == pytest.approx(0.0, abs=1e-12)  # a committed view adds nothing
    assert oracle.evaluated == 4


def test_an_empty_prior_counts_every_seen_pair_once():
    means, weights, cams = scene(n=30, seed=2)
    oracle = PoolCoverageOracle(means, weights, cams, [])
    assert oracle.objective() == pytest.approx(reference_objective(means, weights, cams, []), rel=1e-12)
    assert oracle.objective() > 0


def test_gains_only_shrink_so_lazy_greedy_is_exact():
    means, weights, cams = scene(n=60, seed=1)
    before = PoolCoverageOracle(means, weights, cams, [0])
    after = PoolCoverageOracle(means, weights, cams, [0, 4])
    for view in range(1, 10):
        assert after.gain(view) <= before.gain(view) + 1e-12
    plain = exhaustive_greedy(list(range(1, 10)), 4, PoolCoverageOracle(means, weights, cams, [0]))
    lazy_oracle = PoolCoverageOracle(means, weights, cams, [0])
    lazy = lazy_greedy_select(list(range(1, 10)), 4, lazy_oracle, lambda j, heap: heap)
    assert lazy.ids == plain.ids
    assert lazy_oracle.evaluated <= plain.conservative


def test_the_selector_gets_its_oracle_from_build_oracle():
    gaussians, cams = model(n=120), spiral_cameras(12)
    selector = build_selector("cover_pool")
    assert selector.oracle_kind == "pool_coverage" and selector.uses_oracle
    oracle = build_oracle(selector.oracle_kind, gaussians, cams, [0], BG, SETTINGS)
    assert isinstance(oracle, PoolCoverageOracle) and oracle.views_computed == 0
    ctx = SelectionContext(list(range(1, len(cams))), oracle, torch.Generator().manual_seed(0), 0,
                           camera_centers=torch.stack([c.camera_center for c in cams]))
    sel = selector.select(ctx, 3)
    reference = exhaustive_greedy(list(range(1, len(cams))), 3, PoolCoverageOracle.for_model(gaussians, cams, [0]))
    assert sel.ids == reference.ids and oracle.evaluated < sel.conservative == reference.conservative


def test_pool_weight_pixels_renders_each_pose_and_keeps_exact_greedy():
    gaussians, cams = model(n=120), spiral_cameras(12)
    selector = build_selector("cover_pool", pool_weight="pixels")
    assert selector.oracle_kind == "pool_coverage_pixels"
    oracle = build_oracle(selector.oracle_kind, gaussians, cams, [0], BG, SETTINGS)
    pixels = torch.stack([blend_weights(gaussians, camera, SETTINGS) for camera in cams], dim=1)  # [N, V]
    torch.testing.assert_close(oracle.weights, pixels)
    assert torch.equal(oracle.inside, pixels >= VISIBLE_PIXELS)
    ctx = SelectionContext(list(range(1, len(cams))), oracle, torch.Generator().manual_seed(0), 0,
                           camera_centers=torch.stack([c.camera_center for c in cams]))
    sel = selector.select(ctx, 3)
    reference = exhaustive_greedy(list(range(1, len(cams))), 3, PoolCoverageOracle(
        gaussians.means, pixels, cams, [0], inside=pixels >= VISIBLE_PIXELS))
    assert sel.ids == reference.ids


@pytest.mark.parametrize("seed, spread_wins", [(2, True), (0, False)])
def test_pool_compare_keeps_the_set_that_covers_more(seed, spread_wins):
    """Spiral poses, view 0 captured, K = 3: seed 2 is an instance where the farthest-camera picks cover more than
    greedy's (greedy is only a 1 - 1/e approximation), seed 0 one where greedy's do."""
    (means, weights, _), cams = scene(n=30, seed=seed), spiral_cameras(16)
    centers = torch.stack([c.camera_center for c in cams])  # [V, 3]
    pool = list(range(1, len(cams)))
    greedy = exhaustive_greedy(pool, 3, PoolCoverageOracle(means, weights, cams, [0]))
    spread = farthest_point_picks(centers.double(), [0], pool, 3)

    def drop(views):
        return reference_objective(means, weights, cams, [0]) - reference_objective(means, weights, cams, [0, *views])

    assert (drop(spread) > drop(greedy.ids)) == spread_wins  # the instance exercises the branch it names
    oracle = PoolCoverageOracle(means, weights, cams, [0])
    selector = build_selector("cover_pool", pool_compare="coverage")
    ctx = SelectionContext(pool, oracle, torch.Generator().manual_seed(0), 0, train_ids=(0,), camera_centers=centers)
    sel = selector.select(ctx, 3)
    kept = spread if spread_wins else greedy.ids
    assert sel.ids == kept
    kept_name = "coverage's farthest-camera picks" if spread_wins else "greedy's picks"
    assert sel.note.startswith(f"cover_pool --pool_compare coverage: kept {kept_name}") and "\n" not in sel.note
    assert sum(sel.gains) == pytest.approx(drop(kept), rel=1e-9)
    # the oracle's state is the kept set's: nothing of the other set stays committed
    assert oracle.objective() == pytest.approx(reference_objective(means, weights, cams, [0, *kept]), rel=1e-10)
    lazy = PoolCoverageOracle(means, weights, cams, [0])
    build_selector("cover_pool").select(SelectionContext(pool, lazy, torch.Generator(), 0, train_ids=(0,),
                                                         camera_centers=centers), 3)
    assert oracle.evaluated == lazy.evaluated + 3  # greedy's gains, then the spread set's three
    assert sel.conservative == selector.conservative_count(len(pool), 3) == greedy.conservative + 3


def test_pool_compare_none_is_plain_greedy_and_an_unknown_value_is_one_error_line():
    assert build_selector("cover_pool").config.pool_compare == "none"
    means, weights, cams = scene(n=30)
    ctx = SelectionContext(list(range(1, 10)), PoolCoverageOracle(means, weights, cams, [0]), torch.Generator(), 0,
                           train_ids=(0,), camera_centers=torch.stack([c.camera_center for c in cams]))
    assert build_selector("cover_pool").select(ctx, 2).note is None  # nothing compared, nothing to say
    with pytest.raises(UserError, match="--pool_compare must be one of none, coverage"):
        build_selector("cover_pool", pool_compare="fps")


def test_an_unknown_pool_weight_is_one_error_line():
    with pytest.raises(UserError, match="--pool_weight must be one of opacity, pixels"):
        build_selector("cover_pool", pool_weight="area")


def test_a_pool_too_large_for_memory_is_one_clear_error(monkeypatch):
    monkeypatch.setattr("utils.system_memory.available_memory_bytes", lambda: 1 << 30)
    check_memory(100, 50_000)  # 0.34 GiB: fits in half of 1 GiB
    with pytest.raises(UserError, match="fewer candidates, or --method cover"):
        check_memory(1000, 138_766)
