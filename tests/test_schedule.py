"""Acquisition schedule: seed views by farthest-point sampling, stage layout and flag validation."""
import pytest
import torch

from active.schedule import farthest_point_views, plan_stages
from utils.errors import UserError


def test_farthest_point_views_picks_opposite_then_spread():
    # Points on a line: from 0 the farthest is 10, then the middle one.
    centers = torch.tensor([[0.0, 0, 0], [1, 0, 0], [5, 0, 0], [10, 0, 0], [9, 0, 0]])
    assert farthest_point_views(centers, 3) == [0, 3, 2]


def test_farthest_point_views_matches_brute_force():
    g = torch.Generator().manual_seed(1)
    centers = torch.randn(30, 3, generator=g)
    chosen = farthest_point_views(centers, 6)
    # Slow twin: recompute the max-min distance choice explicitly.
    ref = [0]
    while len(ref) < 6:
        best, best_d = None, -1.0
        for v in range(30):
            if v in ref:
                continue
            d = min(float((centers[v] - centers[u]).norm()) for u in ref)
            if d > best_d:
                best, best_d = v, d
        ref.append(best)
    assert chosen == ref


def test_plan_stages_setup1():
    plan = plan_stages(num_init=2, k=3, max_views=11, pool=100, iters_per_view=100, total_iterations=11_000)
    assert plan.adds == (3, 3, 3)
    assert plan.views_in_stage == (2, 5, 8, 11)
    assert plan.stage_end == (200, 700, 1500, 11_000)


def test_plan_stages_remainder_and_short_total():
    plan = plan_stages(num_init=3, k=5, max_views=15, pool=100, iters_per_view=10, total_iterations=10)
    assert plan.adds == (5, 5, 2)  # the last step adds the remainder
    assert plan.stage_end[-1] == plan.total_iterations == 30 + 80 + 130  # never shorter than the acquisitions


@pytest.mark.parametrize("kwargs, needle", [
    (dict(k=0), "--views_per_step"),
    (dict(num_init=100), "--num_init_views"),
    (dict(max_views=101), "--max_views"),
    (dict(max_views=1), "--max_views"),
    (dict(iters_per_view=0), "--iters_per_view"),
])
def test_plan_stages_rejects_bad_flags(kwargs, needle):
    args = dict(num_init=2, k=3, max_views=11, pool=100, iters_per_view=100, total_iterations=1000)
    args.update(kwargs)
    with pytest.raises(UserError, match=needle):
        plan_stages(**args)
