"""`--gain_weight area`: per-Gaussian area shares (active.gain_weights) and the log-det oracle that uses them."""
import math

import pytest
import torch

from active.base import SelectionContext
from active.fisher import build_oracle
from active.gain_weights import AREA_NEIGHBOURS, area_weights, gain_weights
from active.registry import build_selector
from tests.test_fisher_oracle import BG, bruteforce_blocks, cameras, settings, tiny_model
from utils.errors import UserError


def _plane(spacing: float, x0: float, x1: float) -> torch.Tensor:
    """A square grid of points on z = 0 over [x0, x1) x [0, 1). [P, 3]"""
    xs = torch.arange(x0, x1 - 1e-9, spacing, dtype=torch.float64)
    ys = torch.arange(0.0, 1.0 - 1e-9, spacing, dtype=torch.float64)
    gx, gy = torch.meshgrid(xs, ys, indexing="ij")
    return torch.stack([gx.reshape(-1), gy.reshape(-1), torch.zeros(gx.numel(), dtype=torch.float64)], dim=1)


def test_area_weights_are_squared_kth_neighbour_distances_of_mean_one():
    points = torch.rand(200, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    d2 = torch.cdist(points, points).square()
    d2.fill_diagonal_(math.inf)
    kth = d2.sort(dim=1).values[:, AREA_NEIGHBOURS - 1]  # brute force: all pairs
    weights = area_weights(points)
    torch.testing.assert_close(weights, kth / kth.mean())
    assert math.isclose(float(weights.mean()), 1.0, rel_tol=1e-12)


def test_a_densified_patch_weighs_as_much_as_an_equal_area_of_coarse_gaussians():
    """Two unit squares of one plane, one sampled four times as densely: unweighted, the dense one counts 4x; with
    area weights their totals agree (up to the seam), which is what the option is for."""
    coarse, dense = _plane(0.05, 0.0, 1.0), _plane(0.025, 1.0, 2.0)
    weights = area_weights(torch.cat([coarse, dense]))
    coarse_total, dense_total = float(weights[:len(coarse)].sum()), float(weights[len(coarse):].sum())
    assert len(dense) == 4 * len(coarse)
    assert dense_total == pytest.approx(coarse_total, rel=0.1)


def test_degenerate_clouds_get_unit_weights():
    assert torch.equal(area_weights(torch.zeros(1, 3)), torch.ones(1, dtype=torch.float64))
    assert torch.equal(area_weights(torch.zeros(5, 3)), torch.ones(5, dtype=torch.float64))  # all coincide
    few = area_weights(torch.tensor([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]]))  # k > P - 1: the farthest neighbour
    torch.testing.assert_close(few, torch.tensor([9.0, 4.0, 9.0], dtype=torch.float64) / (22.0 / 3.0))


def test_unknown_gain_weight_is_one_error_line():
    with pytest.raises(UserError, match="--gain_weight must be one of none, opacity, area"):
        build_selector("lite_gs", gain_weight="volume")


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_area_weighted_pop_gs_is_greedy_on_weighted_dense_logdets(backend):
    """The `logdet_area` oracle's gains and pop_gs's picks against dense torch.logdet of brute-force Jacobian blocks,
    each Gaussian's term weighted by its area share."""
    model = tiny_model(seed=2)
    weights = area_weights(model.means)
    assert weights.max() / weights.min() > 1.5  # the weights matter on this model
    blocks = [bruteforce_blocks(model, cam).double() for cam in cameras()]
    selector = build_selector("pop_gs", gain_weight="area")
    oracle = build_oracle(selector.oracle_kind, model, cameras(), [0, 3], BG, settings(backend))
    torch.testing.assert_close(oracle.weights, gain_weights(model, "area"))
    prior = oracle.information.matrix.clone()  # the ridged prior blocks [N, P, P]
    chosen: list[int] = []
    for _ in range(2):
        a = prior + sum((blocks[v] for v in chosen), torch.zeros_like(prior))
        def gain(v):
            return float(sum(w * (torch.logdet(a[i] + blocks[v][i]) - torch.logdet(a[i])) for i, w in enumerate(weights)))
        chosen.append(max((v for v in [1, 2, 4, 5] if v not in chosen), key=lambda v: (gain(v), -v)))
    selection = selector.select(SelectionContext([1, 2, 4, 5], oracle, torch.Generator().manual_seed(0), 0), 2)
    assert selection.ids == chosen
