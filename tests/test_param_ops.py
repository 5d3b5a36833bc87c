"""Parameter surgery keeps Adam aligned: after each op, training equals a reference that never needed surgery.

Adam is elementwise, so a row's trajectory depends only on its own gradients and the shared step count; the
reference therefore runs on the surviving rows alone (prune), or from the start with zero gradients for rows that
are added or reset later (a zero gradient with zero moments leaves a row unchanged). Same float64 elementwise
arithmetic on both sides, so results must be bitwise equal.
"""
import pytest
import torch

from scene.gaussian_model import GaussianModel
from training.optim import OptimConfig, create_optimizer
from training.param_ops import append_params, prune_params, replace_param

SHAPES = {"means": (3,), "sh_dc": (1, 3), "sh_rest": (3, 3), "log_scales": (3,), "quats": (4,),
          "logit_opacities": ()}


def _rows(n: int, g: torch.Generator) -> dict[str, torch.Tensor]:
    return {k: torch.randn(n, *s, generator=g, dtype=torch.float64) for k, s in SHAPES.items()}


def _setup(params: dict[str, torch.Tensor], amsgrad: bool = False):
    model = GaussianModel(1, params)
    opt = create_optimizer(model, OptimConfig(), spatial_lr_scale=1.0)
    for group in opt.param_groups:
        group["amsgrad"] = amsgrad
    return model, opt


def _step(model: GaussianModel, opt: torch.optim.Optimizer, grads: dict[str, torch.Tensor]) -> None:
    for name, p in model.params.items():
        p.grad = grads[name].clone()
    opt.step()


def _assert_aligned(model: GaussianModel, opt: torch.optim.Optimizer) -> None:
    for group in opt.param_groups:
        p = group["params"][0]
        assert p is model.params[group["name"]]
        for key, value in opt.state.get(p, {}).items():
            if key != "step":
                assert value.shape == p.shape, (group["name"], key)


def _assert_same(a: GaussianModel, b: GaussianModel) -> None:
    for name in SHAPES:
        assert torch.equal(a.params[name], b.params[name]), name


@pytest.mark.parametrize("amsgrad", [False, True])
def test_prune_matches_reference(amsgrad):
    g = torch.Generator().manual_seed(0)
    init, grads = _rows(6, g), [_rows(6, g) for _ in range(3)]
    keep = torch.tensor([True, False, True, True, False, True])
    model, opt = _setup(init, amsgrad)
    _step(model, opt, grads[0])
    _step(model, opt, grads[1])
    prune_params(model, opt, keep)
    _assert_aligned(model, opt)
    _step(model, opt, {k: v[keep] for k, v in grads[2].items()})
    ref, ref_opt = _setup({k: v[keep] for k, v in init.items()}, amsgrad)
    for grad in grads:
        _step(ref, ref_opt, {k: v[keep] for k, v in grad.items()})
    assert model.num_gaussians == 4
    _assert_same(model, ref)


def test_append_matches_reference():
    g = torch.Generator().manual_seed(1)
    init, new = _rows(5, g), _rows(2, g)
    grads = [_rows(7, g) for _ in range(3)]
    model, opt = _setup(init)
    for grad in grads[:2]:
        _step(model, opt, {k: v[:5] for k, v in grad.items()})
    append_params(model, opt, new)
    _assert_aligned(model, opt)
    _step(model, opt, grads[2])
    ref, ref_opt = _setup({k: torch.cat([init[k], new[k]]) for k in SHAPES})
    for grad in grads[:2]:  # the appended rows see zero gradients before they exist
        _step(ref, ref_opt, {k: torch.cat([v[:5], torch.zeros_like(v[5:])]) for k, v in grad.items()})
    _step(ref, ref_opt, grads[2])
    assert model.num_gaussians == 7
    _assert_same(model, ref)


def test_replace_resets_state():
    g = torch.Generator().manual_seed(2)
    init, value = _rows(4, g), _rows(4, g)["logit_opacities"]
    grads = [_rows(4, g) for _ in range(3)]
    model, opt = _setup(init)
    _step(model, opt, grads[0])
    _step(model, opt, grads[1])
    replace_param(model, opt, "logit_opacities", value)
    _assert_aligned(model, opt)
    assert torch.equal(model.params["logit_opacities"], value)
    state = opt.state[model.params["logit_opacities"]]
    assert not state["exp_avg"].any() and not state["exp_avg_sq"].any()
    _step(model, opt, grads[2])
    ref, ref_opt = _setup({**init, "logit_opacities": value})
    for grad in grads[:2]:  # as if this parameter had never had a gradient
        _step(ref, ref_opt, {**grad, "logit_opacities": torch.zeros(4, dtype=torch.float64)})
    _step(ref, ref_opt, grads[2])
    _assert_same(model, ref)


def test_surgery_before_first_step():
    g = torch.Generator().manual_seed(3)
    init, new, grad = _rows(3, g), _rows(2, g), _rows(4, g)
    model, opt = _setup(init)
    keep = torch.tensor([True, False, True])
    prune_params(model, opt, keep)
    append_params(model, opt, new)
    _step(model, opt, grad)
    ref, ref_opt = _setup({k: torch.cat([init[k][keep], new[k]]) for k in SHAPES})
    _step(ref, ref_opt, grad)
    _assert_same(model, ref)
