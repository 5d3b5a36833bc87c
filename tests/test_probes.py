"""Probe Gaussians (active/probes.py) and probe_pop: the grid, the observed-space test against a hand-placed wall,
the model kept as it is with the probes appended, and probe_pop's picks against plain greedy on the augmented model."""
import math

import pytest
import torch

from active import build_selector
from active.acquisition import run_selection
from active.fisher import FisherOracle, build_oracle
from active.memory_budget import selection_work
from active.probes import PROBE_COUNT, PROBE_OPACITY, grid_centres, observed_probes, probe_box, with_probes
from active.selectors.pop_gs import exhaustive_greedy
from arguments import FisherSettings
from gaussian_renderer import RasterSettings
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from tests.test_fisher_cache import spiral_cameras
from tests.test_view_factors import BG, SETTINGS, model

pytestmark = pytest.mark.usefixtures("single_torch_thread")  # tiny batched linear algebra (tests/conftest.py)

W = H = 32


def wall(half: str = "both", depth: float = 3.0) -> GaussianModel:
    """Opaque Gaussians tiling the plane z = `depth` in front of the identity camera (x in [-2, 2], or one half)."""
    xs = torch.linspace(-2.0, 2.0, 41)
    if half == "left":
        xs = xs[xs < 0]
    grid = torch.stack(torch.meshgrid(xs, torch.linspace(-2.0, 2.0, 41), indexing="ij"), -1).reshape(-1, 2)
    n = grid.shape[0]
    means = torch.cat([grid, torch.full((n, 1), depth)], 1)
    gaussians = GaussianModel(0, {"means": means, "quats": torch.tensor([1.0, 0, 0, 0]).expand(n, 4).clone(),
                                  "log_scales": torch.full((n, 3), math.log(0.08)),
                                  "logit_opacities": torch.full((n,), 6.0), "sh_dc": torch.zeros(n, 1, 3),
                                  "sh_rest": torch.zeros(n, 0, 3)})
    return gaussians


def front_camera() -> Camera:
    """At the origin looking down +z (identity world-to-camera), 90 degrees wide."""
    return Camera(0, "front", torch.eye(4), W / 2, H / 2, W / 2, H / 2, W, H)


def test_the_grid_fills_the_box_with_about_count_cubic_cells():
    low, high = torch.tensor([0.0, 0.0, 0.0], dtype=torch.float64), torch.tensor([2.0, 1.0, 4.0], dtype=torch.float64)
    centres, side = grid_centres(low, high, 1000)
    assert 0.7 * 1000 <= centres.shape[0] <= 1.3 * 1000
    assert side == pytest.approx((8.0 / 1000) ** (1 / 3))
    assert bool(((centres > low) & (centres < high)).all())
    xs = centres[:, 0].unique()  # evenly spaced, a half step from the faces
    assert torch.allclose(xs.diff(), xs.diff()[:1].expand_as(xs.diff())) and float(xs[0]) == pytest.approx(xs.diff()[0] / 2)


def test_the_box_ignores_outlying_centres_and_adds_a_margin():
    means = torch.cat([torch.rand(1000, 3), torch.tensor([[100.0, 100.0, 100.0]])])
    low, high = probe_box(means)
    assert float(high.max()) < 2.0 and float(low.min()) > -0.5
    assert bool((low < means[:-1].min(0).values + 0.05).all())
    flat = torch.cat([torch.rand(500, 2), torch.zeros(500, 1)], 1)  # a plane: the box keeps a thickness
    low, high = probe_box(flat)
    assert float((high - low)[2]) > 0.1 and grid_centres(low, high, 300)[0].shape[0] < 600


def test_a_probe_is_observed_in_front_of_the_wall_or_where_the_render_is_transparent():
    points = torch.tensor([[0.5, 0.5, 1.5],   # in front of the wall: seen through
                           [0.5, 0.5, 4.5],   # behind it: hidden
                           [40.0, 0.0, 1.5],  # outside the frustum
                           [0.5, 0.5, -1.0],  # behind the camera
                           [0.5, 0.5, 2.9]],  # on the wall, within a cell of its depth
                          dtype=torch.float64)
    settings = RasterSettings(backend="compiled")
    seen = observed_probes(points, 0.2, wall(), [front_camera()], [0], settings)
    assert seen.tolist() == [True, False, False, False, False]
    half = observed_probes(points, 0.2, wall("left"), [front_camera()], [0], settings)  # x > 0: no wall, background
    assert half.tolist() == [True, True, False, False, True]
    assert observed_probes(points, 0.2, wall(), [front_camera()], [], settings).tolist() == [False] * 5


def test_the_model_is_kept_and_the_unobserved_cells_become_faint_probes():
    gaussians = wall()
    settings = RasterSettings(backend="compiled")
    merged, m = with_probes(gaussians, [front_camera()], [0], settings, count=500)
    n = gaussians.num_gaussians
    assert merged.num_gaussians == n + m and 0 < m < 500
    for name, value in gaussians.params.items():
        assert torch.equal(merged.params[name][:n], value.detach())
    torch.testing.assert_close(merged.opacities[n:], torch.full((m,), PROBE_OPACITY))
    centres, side = grid_centres(*probe_box(gaussians.means), 500)
    expected = centres[~observed_probes(centres, side, gaussians, [front_camera()], [0], settings)]
    torch.testing.assert_close(merged.means[n:].double(), expected, rtol=0, atol=1e-6)
    assert bool((merged.means[n:, 2] > 2.0).all())  # a wall seen from the front hides only what lies behind it


def test_probe_pop_is_plain_greedy_on_the_model_with_its_probes():
    gaussians, cams = model(n=120), spiral_cameras(12)
    train = [0, 6]
    candidates = [v for v in range(len(cams)) if v not in train]
    step = run_selection(build_selector("probe_pop"), gaussians, cams, train, candidates, 3, BG, SETTINGS)
    merged, m = with_probes(gaussians, cams, train, SETTINGS)
    assert m > 0
    plain = exhaustive_greedy(candidates, 3, FisherOracle.build(merged, cams, train, BG, SETTINGS,
                                                                 fisher=FisherSettings()))
    assert step.selection.ids == plain.ids
    assert step.selection.gains == pytest.approx(plain.gains, rel=1e-9)
    assert step.evaluated <= step.selection.conservative == 10 + 9 + 8
    without = build_oracle("logdet", gaussians, cams, train, BG, SETTINGS)
    with_space = build_oracle("logdet_probes", gaussians, cams, train, BG, SETTINGS)
    assert all(with_space.gain(v) > without.gain(v) for v in candidates[:3])  # unobserved space adds information


def test_the_memory_estimate_counts_the_probes():
    gaussians = model(n=50)
    plain = selection_work("logdet", gaussians, 100, 5, "default")
    probes = selection_work("logdet_probes", gaussians, 100, 5, "default")
    assert probes.num_gaussians == plain.num_gaussians + PROBE_COUNT
