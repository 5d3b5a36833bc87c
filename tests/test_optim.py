"""Optimizer groups and the 3DGS position LR schedule against its closed form."""
import math

import pytest
import torch

from scene.gaussian_model import GaussianModel
from training.optim import OptimConfig, PositionLRSchedule, create_optimizer


def test_schedule_closed_form():
    s = PositionLRSchedule.from_config(OptimConfig(), spatial_lr_scale=2.0)
    init, final = 1.6e-4 * 2.0, 1.6e-6 * 2.0
    assert s(0) == pytest.approx(init, rel=1e-12)  # float64 exp(log(.)) round trip
    assert s(15_000) == pytest.approx(math.sqrt(init * final), rel=1e-12)  # geometric midpoint
    assert s(7_500) == pytest.approx(init ** 0.75 * final ** 0.25, rel=1e-12)
    assert s(30_000) == pytest.approx(final, rel=1e-12)
    assert s(90_000) == pytest.approx(final, rel=1e-12)  # clamped after max_steps
    assert s(-1) == 0.0
    assert PositionLRSchedule(0.0, 0.0, 0.01, 100)(5) == 0.0


def test_schedule_delay():
    s = PositionLRSchedule(1.0, 0.01, delay_mult=0.1, max_steps=100, delay_steps=10)
    assert s(0) == pytest.approx(0.1, rel=1e-12)  # delay_mult * lr_init
    expected = (0.1 + 0.9 * math.sin(0.5 * math.pi * 0.5)) * 0.01 ** 0.05
    assert s(5) == pytest.approx(expected, rel=1e-12)
    assert s(10) == pytest.approx(0.01 ** 0.1, rel=1e-12)  # warm-up over: plain decay


def test_optimizer_groups_and_apply():
    m = GaussianModel.from_point_cloud(torch.rand(5, 3), torch.rand(5, 3), sh_degree=1)
    cfg = OptimConfig()
    opt = create_optimizer(m, cfg, spatial_lr_scale=3.0)
    lrs = {g["name"]: g["lr"] for g in opt.param_groups}
    assert lrs == {"means": 1.6e-4 * 3.0, "sh_dc": 2.5e-3, "sh_rest": 2.5e-3 / 20, "logit_opacities": 0.05,
                   "log_scales": 5e-3, "quats": 1e-3}
    for g in opt.param_groups:
        assert len(g["params"]) == 1 and g["params"][0] is m.params[g["name"]] and g["eps"] == 1e-15
    schedule = PositionLRSchedule.from_config(cfg, 3.0)
    assert schedule.apply(opt, 30_000) == pytest.approx(1.6e-6 * 3.0, rel=1e-12)
    assert {g["name"]: g["lr"] for g in opt.param_groups}["means"] == schedule(30_000)
    assert {g["name"]: g["lr"] for g in opt.param_groups}["sh_dc"] == 2.5e-3  # other groups untouched
