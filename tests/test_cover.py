"""COVER's geometric oracle (`active.cover_oracle`) against a per-Gaussian, per-camera loop; its gains only shrink
as views are committed, so lazy greedy over it makes exhaustive greedy's picks; the `cover` selector's counts."""
import math

import pytest
import torch

from active.base import SelectionContext
from active.cover_oracle import CoverageOracle, frustum_directions, pixel_coordinates
from active.registry import build_selector
from active.selectors.lazy_greedy import lazy_greedy_select
from active.selectors.pop_gs import exhaustive_greedy
from scene.cameras import Camera
from tests.scenes import intrinsics_for, look_at_viewmat

pytestmark = pytest.mark.usefixtures("single_torch_thread")


def ring_cameras(count, radius=3.0, height=1.0, size=(40, 30), fov=50.0):
    """`count` cameras on a ring around the origin, looking at it."""
    fx, fy, cx, cy = intrinsics_for(*size, fov_x_deg=fov).tolist()
    cams = []
    for i in range(count):
        a = 2 * math.pi * i / count
        eye = (radius * math.cos(a), radius * math.sin(a), height * (1 if i % 2 else -0.5))
        cams.append(Camera(i, f"c{i}", look_at_viewmat(eye).float(), fx, fy, cx, cy, *size))
    return cams


def reference_gain(means, weights, cameras, committed, view):
    """The definition, one Gaussian and one committed camera at a time."""
    total = 0.0
    for i in range(means.shape[0]):
        p = means[i]
        inside, _ = in_frustum(p, cameras[view])
        if not inside:
            continue
        d_v = direction(p, cameras[view])
        novelty = 1.0
        for c in committed:
            seen, _ = in_frustum(p, cameras[c])
            if seen:
                novelty = min(novelty, 0.5 * (1.0 - float(d_v @ direction(p, cameras[c]))))
        total += float(weights[i]) * max(0.0, novelty)
    return total


def in_frustum(p, cam):
    x, y, z = (cam.viewmat.double()[:3, :3] @ p + cam.viewmat.double()[:3, 3]).tolist()
    if z <= 1e-6:
        return False, None
    u, v = cam.fx * x / z + cam.cx, cam.fy * y / z + cam.cy
    return 0 <= u < cam.width and 0 <= v < cam.height, (u, v)


def direction(p, cam):
    d = p - cam.camera_center.double()
    return d / d.norm()


def scene(n=60, seed=0):
    g = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=g, dtype=torch.float64) * 2 - 1) * 1.2  # some leave the narrow frusta
    weights = torch.rand(n, generator=g, dtype=torch.float64)
    return means, weights, ring_cameras(10)


def test_frustum_keeps_points_in_front_and_inside_the_image_only():
    cam = ring_cameras(1)[0]  # at (3, 0, -0.5) looking at the origin
    points = torch.tensor([[0.0, 0.0, 0.0], [6.0, 0.0, -1.0], [0.0, 3.0, 0.0], [0.1, 0.1, 0.1]], dtype=torch.float64)
    inside, dirs = frustum_directions(points, cam)
    assert inside.tolist() == [True, False, False, True]  # behind the camera; far off to the side
    torch.testing.assert_close(dirs.norm(dim=-1), torch.ones(4, dtype=torch.float64))


def test_a_point_straight_behind_the_camera_is_not_in_the_image():
    """Behind the camera on its axis the clamped depth projects to the principal point: only the depth test says no."""
    cam = Camera(0, "axis", torch.eye(4), 50.0, 50.0, 32.0, 24.0, 64, 48)  # at the origin looking along +z
    u, v, inside = pixel_coordinates(torch.tensor([[0.0, 0.0, -2.0], [0.0, 0.0, 2.0]], dtype=torch.float64), cam)
    assert inside.tolist() == [False, True]
    assert (float(u[1]), float(v[1])) == (32.0, 24.0)


def test_gains_equal_the_per_gaussian_definition_through_commits():
    means, weights, cams = scene()
    oracle = CoverageOracle(means, weights, cams, [0, 3])
    committed = [0, 3]
    for view in (5, 7, 1):
        for candidate in (1, 2, 5, 7, 8):
            assert math.isclose(oracle.gain(candidate), reference_gain(means, weights, cams, committed, candidate),
                                rel_tol=1e-12, abs_tol=1e-12)
        oracle.commit(view)
        committed.append(view)
    assert oracle.evaluated == 15


def test_a_taken_view_gains_nothing_and_gains_only_shrink():
    means, weights, cams = scene(seed=1)
    oracle = CoverageOracle(means, weights, cams, [0])
    assert abs(oracle.gain(0)) < 1e-12  # every Gaussian it sees is seen from exactly its own directions
    unseen = CoverageOracle(means, weights, cams, [])
    inside, _ = frustum_directions(means, cams[4])
    assert math.isclose(unseen.gain(4), float(weights[inside].sum()), rel_tol=1e-12)  # nothing taken: all novel
    before = [oracle.gain(v) for v in range(1, 10)]
    oracle.commit(2)
    oracle.commit(6)
    after = [oracle.gain(v) for v in range(1, 10)]
    assert all(a <= b + 1e-12 for a, b in zip(after, before)) and sum(after) < sum(before)


@pytest.mark.parametrize("seed", range(4))
def test_lazy_greedy_over_cover_makes_exhaustive_greedys_picks(seed):
    means, weights, cams = scene(n=80, seed=seed)
    plain = exhaustive_greedy(list(range(2, 10)), 4, CoverageOracle(means, weights, cams, [0, 1]))
    lazy_oracle = CoverageOracle(means, weights, cams, [0, 1])
    lazy = lazy_greedy_select(list(range(2, 10)), 4, lazy_oracle, lambda j, pool: pool)
    assert lazy.ids == plain.ids
    assert lazy_oracle.evaluated <= plain.conservative


def test_cover_selector_counts_exhaustively():
    means, weights, cams = scene(seed=2)
    oracle = CoverageOracle(means, weights, cams, [0])
    selector = build_selector("cover")
    assert selector.oracle_kind == "coverage" and selector.uses_oracle
    ctx = SelectionContext(list(range(1, 10)), oracle, torch.Generator().manual_seed(0), 0, (0,))
    sel = selector.select(ctx, 3)
    assert sel.conservative == selector.conservative_count(9, 3) == 9 + 8 + 7 == oracle.evaluated
    assert len(set(sel.ids)) == 3 and all(g > 0 for g in sel.gains) and sel.gains == sorted(sel.gains, reverse=True)
