"""train.py --seed_start: farthest-point seeding from the first allowed view (the default: the same seed views for
every --seed) or from one drawn with --seed (seed views that vary with the seed, the same for the same seed)."""
from types import SimpleNamespace

import torch

from active.schedule import farthest_point_views
from training.acquisition import seed_views
from training.config import parse_config

CENTERS = torch.randn(30, 3, generator=torch.Generator().manual_seed(0))  # [V, 3]
SCENE = SimpleNamespace(train_cameras=[SimpleNamespace(camera_center=c) for c in CENTERS])


def seeds_for(*flags: str) -> list[int]:
    return seed_views(SCENE, parse_config(["-s", "unused", "--method", "coverage", "--num_init_views", "3", *flags]))


def test_first_gives_every_seed_the_same_views():
    assert {tuple(seeds_for("--seed", str(s))) for s in range(5)} == {tuple(farthest_point_views(CENTERS, 3))}


def test_random_start_varies_with_the_seed_and_spreads_from_there():
    drawn = [seeds_for("--seed_start", "random", "--seed", str(s)) for s in range(8)]
    assert len({views[0] for views in drawn}) > 1  # the start depends on the seed
    for s, views in enumerate(drawn):
        assert views == farthest_point_views(CENTERS, 3, views[0])  # farthest points from the drawn start
        assert seeds_for("--seed_start", "random", "--seed", str(s)) == views  # the same seed, the same views


def test_random_start_only_from_allowed_views():
    excluded = [str(v) for v in range(0, 30, 2)]
    for s in range(8):
        views = seeds_for("--seed_start", "random", "--seed", str(s), "--exclude_views", *excluded)
        assert all(v % 2 == 1 for v in views)
