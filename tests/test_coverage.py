"""coverage: farthest-point picks against a written-out twin, both spaces; the camera geometry train.py puts in the
SelectionContext (centres, look-at point) against known cameras; an end-to-end coverage and fisherrf run."""
import json
import math

import pytest
import torch

from active import build_selector
from active.base import SelectionContext
from active.farthest_point import farthest_point_picks
from gaussian_renderer.projection import camera_center, camera_centers, look_at_point
from scene.scene import Scene
from tests.conftest import run_cli
from tests.scenes import look_at_viewmat
from utils.errors import UserError


def fps_written_out(points, chosen, candidates, k):
    """Each pick: the candidate with the largest distance to its nearest chosen point, the lowest id on ties."""
    chosen, picks = list(chosen), []
    for _ in range(min(k, len(candidates))):
        def nearest(v):
            return min((math.dist(points[v], points[c]) for c in chosen), default=math.inf)
        best = max((v for v in sorted(candidates) if v not in picks), key=lambda v: (nearest(v), -v))
        picks.append(best)
        chosen.append(best)
    return picks


@pytest.mark.parametrize("seed", range(4))
def test_farthest_point_picks_equal_the_written_out_twin(seed):
    points = torch.randn(30, 3, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    candidates = [v for v in range(30) if v % 4 != 1]
    for chosen in ([1, 5], []):
        expected = fps_written_out(points.tolist(), chosen, candidates, 6)
        assert farthest_point_picks(points, chosen, candidates, 6) == expected
    assert sorted(farthest_point_picks(points, [1], candidates, 99)) == sorted(candidates)


def test_exact_ties_go_to_the_lowest_id():
    points = torch.tensor([[0.0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]])
    assert farthest_point_picks(points, [0], [4, 3, 2, 1], 2) == [1, 2]


def eyes():
    """Six cameras around the origin at mixed distances, all looking at (0.2, -0.1, 0.3)."""
    return [(3.0, 0, 1), (0, 6.0, 1.5), (-2.0, 0.5, 0.5), (0.5, -4.0, 2.0), (1.0, 1.0, 3.0), (-5.0, -5.0, 1.0)]


def test_camera_geometry_of_known_cameras():
    target = (0.2, -0.1, 0.3)
    viewmats = torch.stack([look_at_viewmat(e, target) for e in eyes()])
    torch.testing.assert_close(camera_centers(viewmats), torch.tensor(eyes(), dtype=torch.float64))
    torch.testing.assert_close(camera_centers(viewmats)[2], camera_center(viewmats[2]))
    torch.testing.assert_close(look_at_point(viewmats), torch.tensor(target, dtype=torch.float64), atol=1e-6,
                               rtol=0)


def test_directions_ignore_the_distance():
    target = torch.tensor((0.2, -0.1, 0.3), dtype=torch.float64)
    viewmats = torch.stack([look_at_viewmat(e, tuple(target.tolist())) for e in eyes()])
    centers = camera_centers(viewmats)
    far = target + 3.0 * (centers[0] - target)  # view 6: view 0's direction, 3x as far
    centers = torch.cat([centers, far[None]])
    ctx = SelectionContext([2, 3, 4, 5, 6], None, torch.Generator(), 0, train_ids=(0, 1), camera_centers=centers,
                           scene_center=target)
    units = (centers - target) / (centers - target).norm(dim=-1, keepdim=True)
    sel = build_selector("coverage", coverage_space="directions").select(ctx, 5)
    assert sel.ids == fps_written_out(units.tolist(), [0, 1], [2, 3, 4, 5, 6], 5) and sel.ids[-1] == 6
    assert sel.conservative == 0 and sel.gains == [0.0] * 5
    by_centres = build_selector("coverage").select(ctx, 5)
    assert by_centres.ids == fps_written_out(centers.tolist(), [0, 1], [2, 3, 4, 5, 6], 5)
    with pytest.raises(UserError, match="--coverage_space"):
        build_selector("coverage", coverage_space="sphere")


ACTIVE = ["--num_init_views", "2", "--views_per_step", "2", "--max_views", "6", "--iters_per_view", "2",
          "--iterations", "10", "--num_random_points", "200", "--quiet"]


def test_train_py_gives_the_selectors_the_camera_geometry(tiny_scene, tmp_path):
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(tmp_path / "c"), "--method", "coverage", *ACTIVE)
    assert r.returncode == 0, r.stderr
    scene = Scene.load(str(tiny_scene), tmp_path / "x", white_background=False, resolution=1, eval=False)
    centers = torch.stack([c.camera_center for c in scene.train_cameras]).double()
    stages = json.loads((tmp_path / "c" / "selection.json").read_text())["stages"]
    assert len(stages) == 2
    for stage in stages:
        pool = [v for v in range(len(centers)) if v not in stage["train_views"]]
        assert stage["selected"] == fps_written_out(centers.tolist(), stage["train_views"], pool, 2)
        assert stage["oracle_calls"] == {"conservative": 0, "evaluated": 0}
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(tmp_path / "f"), "--method", "fisherrf", *ACTIVE)
    assert r.returncode == 0, r.stderr
    selection = json.loads((tmp_path / "f" / "selection.json").read_text())
    assert selection["config"]["selector_options"] == {"fisherrf_lambda": 1e-6, "fisherrf_params":
                                                       "means,log_scales,logit_opacities,sh_dc,sh_rest",
                                                       "fisherrf_variant": "exact"}
    for stage in selection["stages"]:
        m = stage["candidates"]
        assert stage["oracle_calls"]["conservative"] == stage["oracle_calls"]["evaluated"] == m + (m - 1)
        assert stage["fisher_views_computed"] == m and all(g > 0 for g in stage["gains"])


def facility_written_out(points, chosen, candidates, k, space):
    """Each pick: the candidate that lowers F(S) = sum over the pool of min(cap, nearest chosen cost) the most, the
    lowest id on ties; cost = distance (centers, cap = the pool's diameter) or (1 - cos) / 2 (directions, cap 1)."""
    pool = sorted(set(chosen) | set(candidates))

    def cost(a, b):
        if space == "centers":
            return math.dist(points[a], points[b])
        return (1.0 - sum(x * y for x, y in zip(points[a], points[b]))) / 2

    cap = 1.0 if space == "directions" else max(cost(a, b) for a in pool for b in pool)

    def objective(taken):
        return sum(min([cap] + [cost(c, s) for s in taken]) for c in pool)
    taken, picks = list(chosen), []
    for _ in range(min(k, len(candidates))):
        best = max((v for v in sorted(candidates) if v not in picks),
                   key=lambda v: (objective(taken) - objective(taken + [v]), -v))
        picks.append(best)
        taken.append(best)
    return picks


@pytest.mark.parametrize("space", ["centers", "directions"])
@pytest.mark.parametrize("seed", range(3))
def test_facility_location_picks_equal_the_written_out_twin(seed, space):
    from active.facility_location import facility_location_picks
    points = torch.randn(24, 3, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    if space == "directions":
        points = points / points.norm(dim=-1, keepdim=True)
    candidates = [v for v in range(24) if v % 5 != 2]
    for chosen in ([2, 7], []):
        expected = facility_written_out(points.tolist(), chosen, candidates, 5, space)
        assert facility_location_picks(points, chosen, candidates, 5, space) == expected
    assert sorted(facility_location_picks(points, [2], candidates, 99, space)) == sorted(candidates)


def test_pool_objective_is_cover_pool_with_the_model_at_the_look_at_point():
    """cover_pool's oracle over one Gaussian at the point every camera looks at, seen by every pose, is the facility
    location over the cameras' viewing directions: the same picks."""
    from active.pool_cover_oracle import PoolCoverageOracle
    from active.selectors.lazy_greedy import lazy_greedy_select
    from tests.test_fisher_cache import spiral_cameras
    cams = spiral_cameras(30)
    train, candidates = [0, 11, 23], [v for v in range(30) if v not in (0, 11, 23)]
    oracle = PoolCoverageOracle(torch.zeros(1, 3, dtype=torch.float64), torch.ones(1), cams, train,
                                inside=torch.ones(1, 30, dtype=torch.bool))
    expected = lazy_greedy_select(candidates, 6, oracle, lambda j, pool: pool).ids
    centers = camera_centers(torch.stack([c.viewmat for c in cams]))
    ctx = SelectionContext(candidates, None, torch.Generator(), 0, train_ids=tuple(train), camera_centers=centers,
                           scene_center=torch.zeros(3, dtype=torch.float64))
    sel = build_selector("coverage", coverage_space="directions", coverage_objective="pool").select(ctx, 6)
    assert sel.ids == expected and sel.conservative == 0
    assert sel.ids != build_selector("coverage", coverage_space="directions").select(ctx, 6).ids  # not k-centre
    with pytest.raises(UserError, match="--coverage_objective"):
        build_selector("coverage", coverage_objective="median")


def test_default_objective_keeps_the_summary_label():
    """The option added later defaults to "none", which the summaries leave out: coverage runs keep one label."""
    from dataclasses import asdict

    from active.selectors.coverage import CoverageConfig
    from experiments.summary import Run
    run = Run(path=None, setup="setup1", scene="lego", method="coverage", k=3, options=asdict(CoverageConfig()), seed=0)
    assert run.setting == "coverage K=3 coverage_space=centers"
    pool = Run(path=None, setup="setup1", scene="lego", method="coverage", k=3, seed=0,
               options=asdict(CoverageConfig(coverage_objective="pool")))
    assert pool.setting == "coverage K=3 coverage_objective=pool coverage_space=centers"
