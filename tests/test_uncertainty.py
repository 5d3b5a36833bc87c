"""Uncertainty: Spearman and AUSE on small arrays worked out by hand, per-Gaussian positional variance against a
dense inverse of brute-force blocks, the composited map, the recorded training views, render.py + metrics.py."""
import json
import math

import numpy as np
import pytest
import torch

from active.logdet import BlockInformation
from active.uncertainty import (camera_depths, fisherrf_information, fisherrf_map, gaussian_uncertainty,
                                parse_uncertainty_kinds, uncertainty_map, view_information)
from arguments import FisherSettings
from gaussian_renderer import render
from scene.trained import recorded_train_views
from tests.conftest import run_cli
from tests.test_fisher_oracle import BG, bruteforce_blocks, cameras, settings, tiny_model
from tests.test_fisherrf import bruteforce_diagonals, bruteforce_reference_diagonals
from utils.errors import UserError
from utils.uncertainty_metrics import ause, average_ranks, spearman


def test_spearman_on_known_arrays():
    # scipy.stats.spearmanr([1, 2, 3, 4, 5], [5, 6, 7, 8, 7]): ranks of y 1, 2, 3.5, 5, 3.5 -> 8 / sqrt(10 * 9.5)
    assert spearman(np.array([1, 2, 3, 4, 5]), np.array([5, 6, 7, 8, 7])) == pytest.approx(8 / math.sqrt(95))
    assert average_ranks(np.array([5.0, 6, 7, 8, 7])).tolist() == [1, 2, 3.5, 5, 3.5]
    x = np.array([[0.1, 3.0], [2.0, 0.5]])
    assert spearman(x, x ** 3) == pytest.approx(1.0)
    assert spearman(x, -x) == pytest.approx(-1.0)
    assert spearman(x, np.ones_like(x)) is None


def test_ause_on_known_arrays():
    errors = np.array([1.0, 2.0, 3.0, 4.0])
    assert ause(errors * 10, errors, bins=4) == pytest.approx(0.0, abs=1e-12)  # same order as the error
    # Reversed order, 4 bins: after removing 0..3 pixels the RMSE left is
    # oracle    sqrt(30/4), sqrt(14/3), sqrt(5/2), 1
    # reversed  sqrt(30/4), sqrt(29/3), sqrt(25/2), 4
    gap = [0.0, math.sqrt(29 / 3) - math.sqrt(14 / 3), math.sqrt(25 / 2) - math.sqrt(5 / 2), 4 - 1]
    expected = sum(0.25 * (gap[i] + gap[i + 1]) / 2 for i in range(3))
    assert ause(-errors, errors, bins=4) == pytest.approx(expected)
    assert ause(-errors, errors, bins=4) > ause(np.array([2.0, 1.0, 4.0, 3.0]), errors, bins=4) > 0


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_gaussian_uncertainty_equals_a_dense_inverse_of_bruteforce_blocks(backend):
    model, cams = tiny_model(seed=3), cameras()
    u = gaussian_uncertainty(model, cams, [0, 2, 4], BG, settings(backend), fisher=FisherSettings(sigma=0.5))
    prior = sum(bruteforce_blocks(model, cams[v], sigma=0.5) for v in (0, 2, 4))  # [N, 14, 14]
    a = BlockInformation(prior).matrix  # the same ridge, added to the brute-force prior
    expected = torch.stack([torch.trace(torch.linalg.inv(block)[:3, :3]) for block in a])
    torch.testing.assert_close(u, expected, rtol=1e-3, atol=0.0)
    assert bool((u > 0).all())
    more = gaussian_uncertainty(model, cams, [0, 1, 2, 3, 4, 5], BG, settings(backend),
                                fisher=FisherSettings(sigma=0.5))
    assert bool((more <= u * (1 + 1e-6)).all())  # more views: no Gaussian more uncertain


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_uncertainty_map_composites_like_a_colour(backend):
    model, cam = tiny_model(seed=1), cameras()[1]
    raster = settings(backend)
    alpha = render(cam, model, BG.float(), raster).alpha
    torch.testing.assert_close(uncertainty_map(cam, model, torch.full((6,), 2.5), raster), 2.5 * alpha.float(),
                               rtol=1e-5, atol=1e-6)
    u1, u2 = torch.rand(6), torch.rand(6)
    torch.testing.assert_close(uncertainty_map(cam, model, u1 + u2, raster),
                               uncertainty_map(cam, model, u1, raster) + uncertainty_map(cam, model, u2, raster),
                               rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_fisherrf_information_and_maps_follow_fisherrfs_recipe(backend):
    raster = settings(backend)
    model, cams = tiny_model(seed=4), cameras()
    expected = sum(bruteforce_diagonals(model, cams[v])[:, 11:].sum(1) for v in (0, 2, 5))  # sh_dc + sh_rest columns
    info = fisherrf_information(model, cams, [0, 2, 5], BG, raster)
    torch.testing.assert_close(info, expected, rtol=1e-4, atol=1e-6 * float(expected.max()))
    cam = cams[1]
    view = camera_depths(model, cam)
    manual = (model.means.detach() @ cam.viewmat[:3, :3].T + cam.viewmat[:3, 3])[:, 2]
    torch.testing.assert_close(view, manual)
    drawn = uncertainty_map(cam, model, info * view.clamp_min(0), raster)
    m = fisherrf_map(cam, model, info, raster)
    empty = drawn == 0
    assert empty.any() and (~empty).any()
    torch.testing.assert_close(m[~empty], drawn[~empty])
    assert bool((m[empty] == drawn.max()).all())  # nothing drawn: as uncertain as the most uncertain pixel
    own = view_information(model, cam, BG, raster)
    torch.testing.assert_close(own, bruteforce_reference_diagonals(model, cam).sum(1), rtol=1e-4,
                               atol=1e-6 * float(own.max()))


def test_unknown_uncertainty_kind_is_one_line_listing_the_valid():
    assert parse_uncertainty_kinds("fisherrf, position_variance") == ("fisherrf", "position_variance")
    for text in ("fisherrf,variance", "", "fisherrf,fisherrf"):
        with pytest.raises(UserError, match="position_variance, fisherrf, fisherrf_view") as err:
            parse_uncertainty_kinds(text)
        assert "\n" not in str(err.value)


def test_recorded_train_views(tmp_path):
    assert recorded_train_views(tmp_path, 500, 4, "") == [0, 1, 2, 3]
    with pytest.raises(UserError, match="no training views recorded"):
        recorded_train_views(tmp_path, 500, 4, "coverage")
    stages = [{"iteration": 20, "train_views": [0, 5]}, {"iteration": 70, "train_views": [0, 5, 2]}]
    (tmp_path / "selection.json").write_text(json.dumps({"stages": stages}))
    assert recorded_train_views(tmp_path, 20, 9, "coverage") == [0, 5]
    assert recorded_train_views(tmp_path, 50, 9, "coverage") == [0, 5, 2]
    with pytest.raises(UserError, match="no training views recorded"):  # unfinished: no final record
        recorded_train_views(tmp_path, 90, 9, "coverage")
    (tmp_path / "selection.json").write_text(json.dumps({"stages": stages, "final": {"train_views": [0, 5, 2, 7]}}))
    assert recorded_train_views(tmp_path, 90, 9, "coverage") == [0, 5, 2, 7]


# Slow (a training run, then render.py --uncertainty and metrics.py in subprocesses): the per-Gaussian variance
# and the composited map are checked above, the CLIs' pipeline by tests/test_train_e2e.py.
@pytest.mark.slow
def test_render_uncertainty_then_metrics(tiny_scene, tmp_path):
    model = tmp_path / "m"
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(model), "--eval", "--iterations", "30",
                "--num_random_points", "300", "--quiet")
    assert r.returncode == 0, r.stderr
    r = run_cli("render.py", "-m", str(model), "--skip_train", "--uncertainty", "--quiet")
    assert r.returncode == 0, r.stderr
    out = model / "test" / "ours_30" / "uncertainty"
    assert sorted(p.name for p in out.iterdir()) == ["fisherrf", "fisherrf_view", "object_mask", "position_variance"]
    for kind in ("fisherrf", "fisherrf_view", "position_variance"):
        assert sorted(p.name for p in (out / kind).iterdir()) == [
            "00000.npy", "00000.png", "00001.npy", "00001.png", "00002.npy", "00002.png", "00003.npy", "00003.png",
            "colorbar.png"]
        values = np.load(out / kind / "00000.npy")
        assert values.dtype == np.float32 and values.shape == (32, 32) and values.max() > 0
    r = run_cli("metrics.py", "-m", str(model), "--quiet")
    assert r.returncode == 0, r.stderr
    results = json.loads((model / "results.json").read_text())["ours_30"]
    per_view = json.loads((model / "per_view.json").read_text())["ours_30"]
    assert results["uncertainty_object_region"].startswith("pixels where the ground truth or the render")
    for kind in ("fisherrf", "fisherrf_view", "position_variance"):
        for region in ("image", "object"):
            key = f"Spearman/{kind}/{region}"
            assert results[key] is None or -1 <= results[key] <= 1
            for variant in ("AUSE_RMSE", "AUSE_MAE", "AUSE_RMSE_norm", "AUSE_MAE_norm"):
                key = f"{variant}/{kind}/{region}"
                assert results[key] == pytest.approx(sum(per_view[key].values()) / 4)
    assert "fisherrf_view" in r.stdout and "AUSE_MAE_norm" in r.stdout
    r = run_cli("metrics.py", "-m", str(model), "--quiet", "--ause", "mae,auc")
    assert r.returncode != 0 and r.stderr.strip().splitlines()[-1].startswith("error: unknown AUSE variant auc")
    r = run_cli("render.py", "-m", str(model), "--skip_train", "--uncertainty", "--uncertainty_kind", "depth")
    assert r.returncode != 0 and "valid" not in r.stdout and "fisherrf_view" in r.stderr.strip().splitlines()[-1]
    r = run_cli("scripts/uncertainty_figure.py", str(model), "--view", "2", "--kind", "fisherrf", "--out",
                str(tmp_path / "fig.png"))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "fig.png").stat().st_size > 0
