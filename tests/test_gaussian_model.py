"""GaussianModel: 3DGS initialisation values, activations, versioned state."""
import math

import pytest
import torch

from scene.gaussian_model import GaussianModel
from utils.errors import UserError


def test_from_point_cloud_init_values():
    # Points on the axes: point 0's three nearest neighbours are at squared distances 1, 4 and 9.
    points = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3], [10, 10, 10]])
    colors = torch.tensor([[0.0, 0.5, 1.0]]).repeat(5, 1)
    m = GaussianModel.from_point_cloud(points, colors, sh_degree=2)
    assert m.num_gaussians == 5 and m.max_sh_degree == 2 and m.active_sh_degree == 0
    assert torch.equal(m.means, points)
    # sh_dc = (rgb - 0.5) / C0 with C0 = 1 / (2 sqrt(pi)); float32 rounding of the constant: 1e-6
    c0 = 0.5 / math.sqrt(math.pi)
    assert torch.allclose(m.params["sh_dc"][0, 0], (colors[0] - 0.5) / c0, atol=1e-6)
    assert m.sh_coeffs.shape == (5, 9, 3) and torch.count_nonzero(m.params["sh_rest"]) == 0
    # scale = sqrt(mean of the 3 nearest squared distances), the same on every axis
    assert torch.allclose(m.scales[0], torch.full((3,), math.sqrt(14 / 3)), rtol=1e-6)  # float32 exp/log: 1e-6
    far = torch.tensor([[10.0, 10, 10]]) - points[:4]  # point 4's neighbours are the other four
    expected = far.square().sum(1).sort().values[:3].mean().sqrt()
    assert torch.allclose(m.scales[4], expected.repeat(3), rtol=1e-6)  # float32 exp/log: 1e-6
    assert torch.equal(m.unit_quats, torch.tensor([[1.0, 0, 0, 0]]).repeat(5, 1))
    assert torch.allclose(m.opacities, torch.full((5,), 0.1), atol=1e-7)  # sigmoid(logit(0.1)) in float32
    assert m.opacities.shape == (5,)
    assert all(isinstance(p, torch.nn.Parameter) and p.is_leaf for p in m.params.values())


def test_coincident_points_get_finite_scales():
    m = GaussianModel.from_point_cloud(torch.zeros(4, 3), torch.rand(4, 3), sh_degree=0)
    assert torch.isfinite(m.params["log_scales"]).all()
    assert torch.allclose(m.scales, torch.full((4, 3), math.sqrt(1e-7)), rtol=1e-6)  # the 3DGS clamp


def test_activations_follow_raw_parameters():
    m = GaussianModel.from_point_cloud(torch.rand(6, 3), torch.rand(6, 3), sh_degree=1)
    with torch.no_grad():
        m.params["quats"].mul_(3.0)
        m.params["log_scales"].fill_(math.log(0.25))
        m.params["logit_opacities"].fill_(0.0)
    assert torch.allclose(m.unit_quats.norm(dim=1), torch.ones(6))  # float32 normalisation: default tolerance
    assert torch.equal(m.scales, torch.full((6, 3), 0.25))
    assert torch.equal(m.opacities, torch.full((6,), 0.5))
    assert torch.equal(m.sh_coeffs[:, 1:], m.params["sh_rest"])


def test_sh_degree_steps_and_limits():
    m = GaussianModel.from_point_cloud(torch.rand(4, 3), torch.rand(4, 3), sh_degree=2)
    for expected in (1, 2, 2):
        m.increase_sh_degree()
        assert m.active_sh_degree == expected
    with pytest.raises(UserError, match="SH degree 4"):
        GaussianModel(4)


def test_bad_point_clouds():
    with pytest.raises(UserError, match="non-empty"):
        GaussianModel.from_point_cloud(torch.zeros(0, 3), torch.zeros(0, 3), 0)
    with pytest.raises(UserError, match="colours"):
        GaussianModel.from_point_cloud(torch.zeros(3, 3), torch.zeros(2, 3), 0)
    with pytest.raises(UserError, match="NaN"):
        GaussianModel.from_point_cloud(torch.tensor([[0.0, float("nan"), 0], [1, 1, 1]]), torch.zeros(2, 3), 0)


def test_state_dict_roundtrip_and_version():
    m = GaussianModel.from_point_cloud(torch.rand(7, 3), torch.rand(7, 3), sh_degree=3)
    m.increase_sh_degree()
    state = m.state_dict()
    assert state["format_version"] == 1 and set(state["params"]) == set(m.params)
    with torch.no_grad():
        m.params["means"].add_(1.0)  # the snapshot is a copy, not a view
    other = GaussianModel(0)
    other.load_state_dict(state)
    assert other.max_sh_degree == 3 and other.active_sh_degree == 1
    assert torch.equal(other.means, state["params"]["means"]) and not torch.equal(other.means, m.means)
    with pytest.raises(UserError, match="version 99"):
        other.load_state_dict({**state, "format_version": 99})
