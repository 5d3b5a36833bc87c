"""Densification on hand-built Gaussians: who is cloned, split, pruned; accumulators; opacity reset; caps."""
import math

import pytest
import torch

from training.densify import DensifyConfig, DensifyStrategy
from scene.gaussian_model import GaussianModel
from training.optim import OptimConfig, create_optimizer

W, H, EXTENT = 200, 100, 10.0  # percent_dense * extent = 0.1 separates clone from split
CFG = DensifyConfig(densify_from_iter=0, densification_interval=2, opacity_reset_interval=1000)


def _model(scales, opacities, quats=None, means=None):
    n = len(opacities)
    params = {
        "means": torch.tensor(means) if means is not None else torch.arange(3.0 * n).view(n, 3),
        "sh_dc": torch.arange(3 * n).float().view(n, 1, 3),
        "sh_rest": torch.zeros(n, 3, 3),
        "log_scales": torch.tensor(scales).log(),
        "quats": torch.tensor(quats) if quats is not None else torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
        "logit_opacities": torch.logit(torch.tensor(opacities)),
    }
    model = GaussianModel(1, params)
    return model, create_optimizer(model, OptimConfig(), EXTENT)


def _call(strategy, model, opt, grads_px, iteration, radii=None, visible=None):
    n = model.num_gaussians
    means2d = torch.zeros(n, 2, requires_grad=True)
    means2d.grad = torch.tensor(grads_px, dtype=torch.float32)
    radii = torch.tensor(radii) if radii is not None else torch.full((n,), 5, dtype=torch.int32)
    visible = torch.tensor(visible) if visible is not None else torch.ones(n, dtype=torch.bool)
    strategy.step_post_backward(model, opt, means2d, radii, visible, W, H, iteration, EXTENT)


def _assert_aligned(model, opt, strategy):
    n = model.num_gaussians
    assert strategy.grad_accum.shape == strategy.denom.shape == strategy.max_radii.shape == (n,)
    for group in opt.param_groups:
        p = group["params"][0]
        assert p is model.params[group["name"]] and p.shape[0] == n
        assert all(v.shape == p.shape for k, v in opt.state.get(p, {}).items() if k != "step")


def test_clone_split_prune():
    s45 = math.sqrt(0.5)
    scales = [[0.05] * 3, [1.0, 1e-3, 1e-3], [0.05] * 3, [0.05] * 3, [0.05] * 3]
    quats = [[1.0, 0, 0, 0], [s45, 0, 0, s45], [1.0, 0, 0, 0], [1.0, 0, 0, 0], [1.0, 0, 0, 0]]
    model, opt = _model(scales, [0.5, 0.5, 0.001, 0.5, 0.5], quats)
    before = {k: v.detach().clone() for k, v in model.params.items()}
    # x pixel gradient 3e-6 -> 3e-6 * W/2 = 3e-4 NDC (>= 2e-4); the same in y gives 3e-6 * H/2 = 1.5e-4 (below).
    grads = [[3e-6, 0], [0, 4e-6], [0, 0], [0, 1e-7], [0, 3e-6]]
    strategy = DensifyStrategy(CFG, total_iterations=100)
    torch.manual_seed(0)
    _call(strategy, model, opt, grads, iteration=1)
    assert model.num_gaussians == 5  # accumulate only
    assert torch.allclose(strategy.grad_accum, torch.tensor([3e-4, 2e-4, 0, 5e-6, 1.5e-4]), rtol=1e-6)  # float32
    _call(strategy, model, opt, grads, iteration=2)
    # survivors A, D, E in order, then A's clone, then B's two children; C (transparent) and B (split) are gone
    assert model.num_gaussians == 6
    _assert_aligned(model, opt, strategy)
    assert not strategy.grad_accum.any() and not strategy.denom.any()
    p = {k: v.detach() for k, v in model.params.items()}
    for name in before:
        assert torch.equal(p[name][:3], before[name][[0, 3, 4]]), name
        assert torch.equal(p[name][3], before[name][0]), name  # exact clone
        if name not in ("means", "log_scales"):
            assert torch.equal(p[name][4:], before[name][[1, 1]]), name
    # children: scale / (0.8 * 2), offsets along the rotated long axis (local x -> world y under 90 deg about z)
    assert torch.allclose(p["log_scales"][4:], before["log_scales"][[1, 1]] - math.log(1.6), atol=1e-6)  # float32
    offsets = p["means"][4:] - before["means"][1]
    assert offsets[:, 0].abs().max() < 0.01 and offsets[:, 1].abs().min() > 0.05  # std 1e-3 vs 1.0 (seed 0)


def test_accumulates_only_visible_and_averages():
    model, opt = _model([[0.05] * 3] * 3, [0.5] * 3)
    strategy = DensifyStrategy(CFG, total_iterations=100)
    _call(strategy, model, opt, [[1e-6, 0], [0, 2e-6], [1.0, 1.0]], 1, radii=[3, 7, 9], visible=[True, True, False])
    _call(strategy, model, opt, [[0, 1e-6], [0, 0], [1.0, 1.0]], 3, radii=[4, 2, 9], visible=[True, True, False])
    assert strategy.denom.tolist() == [2, 2, 0]
    expected = torch.tensor([(1e-4 + 5e-5) / 2, 1e-4 / 2, 0.0])  # NDC norms averaged over visible iterations
    assert torch.allclose(strategy.grad_accum / strategy.denom.clamp_min(1), expected, rtol=1e-6)  # float32
    assert strategy.max_radii.tolist() == [4, 7, 0]


def test_opacity_reset():
    model, opt = _model([[0.05] * 3] * 3, [0.5, 0.005, 0.9])
    strategy = DensifyStrategy(DensifyConfig(densify_from_iter=10_000, opacity_reset_interval=4), 100)
    quats = model.params["quats"].detach().clone()
    _call(strategy, model, opt, [[1e-3, 0]] * 3, iteration=1)
    model.params["logit_opacities"].grad = torch.ones(3)
    opt.step()  # populate Adam state (moves every logit by -lr)
    before = model.opacities.detach().clone()
    _call(strategy, model, opt, [[1e-3, 0]] * 3, iteration=4)
    assert before[1] < 0.01 < before[2]
    expected = torch.minimum(before, torch.tensor(0.01))
    assert torch.allclose(model.opacities, expected, rtol=1e-5)  # float32 sigmoid of logit(0.01)
    state = opt.state[model.params["logit_opacities"]]
    assert not state["exp_avg"].any() and not state["exp_avg_sq"].any()
    assert torch.equal(model.params["quats"].detach(), quats)
    _assert_aligned(model, opt, strategy)


@pytest.mark.parametrize("iteration, pruned", [(4, False), (8, True)])
def test_size_pruning_only_after_first_reset(iteration, pruned):
    cfg = DensifyConfig(densify_from_iter=0, densification_interval=4, opacity_reset_interval=5)
    # 0: ordinary; 1: 25 px wide on screen (> 20); 2: 2.0 wide in the world (> 0.1 * extent)
    model, opt = _model([[0.05] * 3, [0.05] * 3, [2.0] * 3], [0.5] * 3)
    strategy = DensifyStrategy(cfg, total_iterations=100)
    _call(strategy, model, opt, [[0, 0]] * 3, iteration, radii=[5, 25, 5])
    assert model.num_gaussians == (1 if pruned else 3)


def test_cap_prefers_largest_gradients():
    cfg = DensifyConfig(densify_from_iter=0, densification_interval=1, max_gaussians=4)
    model, opt = _model([[0.05] * 3] * 3, [0.5] * 3)
    strategy = DensifyStrategy(cfg, total_iterations=100)
    _call(strategy, model, opt, [[3e-6, 0], [9e-6, 0], [0, 0]], iteration=1)  # two candidates, room for one
    assert model.num_gaussians == 4
    assert torch.equal(model.params["means"][3], model.params["means"][1])  # the larger gradient was cloned


def test_stops_after_until_and_state_roundtrip():
    model, opt = _model([[0.05] * 3] * 2, [0.5] * 2)
    strategy = DensifyStrategy(DensifyConfig(densify_from_iter=0, densification_interval=1000), total_iterations=10)
    assert strategy.until == 5  # -1: half of the run
    _call(strategy, model, opt, [[1e-6, 0]] * 2, iteration=1)
    _call(strategy, model, opt, [[1e-6, 0]] * 2, iteration=5)  # past until: ignored
    assert strategy.denom.tolist() == [1, 1]
    restored = DensifyStrategy(DensifyConfig(), total_iterations=999)
    restored.load_state_dict(strategy.state_dict())
    assert restored.until == 5 and torch.equal(restored.grad_accum, strategy.grad_accum)
    with pytest.raises(Exception, match="version 7"):
        restored.load_state_dict({**strategy.state_dict(), "format_version": 7})
