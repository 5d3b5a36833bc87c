"""Built-in scene: reload through the Blender loader, re-render from the loaded cameras, determinism, stamp."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest
import torch

from gaussian_renderer import RasterSettings, rasterization
from scene.builtin import CAMERA_ANGLE_X, CAMERA_RADIUS, STAMP, _object_points, make_builtin_scene, scene_gaussians
from scene.clutter import NUM_OBJECTS, clutter_points
from scene.dataset_readers import load_scene_info
from tests.conftest import run_cli
from utils.errors import UserError

# The dataset generators (scene.builtin, scene.phone_capture) render with the default backend, as for a user;
# the rasterizer's backends are tested in test_rasterize.py and test_compiled_rasterizer.py.
pytestmark = pytest.mark.auto_backend

RES, NUM_TRAIN, NUM_TEST = 32, 6, 3
MINI = {"seed": 5, "resolution": 16, "num_train": 2, "num_test": 1}  # for tests that generate repeatedly


@pytest.fixture(scope="module")
def small_scene(tmp_path_factory) -> Path:
    return make_builtin_scene(tmp_path_factory.mktemp("builtin") / "s", seed=3, resolution=RES,
                              num_train=NUM_TRAIN, num_test=NUM_TEST)


@pytest.fixture(scope="module")
def mini_scene(tmp_path_factory) -> Path:
    return make_builtin_scene(tmp_path_factory.mktemp("builtin") / "mini", **MINI)


def test_reloads_as_blender(small_scene):
    info = load_scene_info(str(small_scene))
    assert info.kind == "blender" and info.point_cloud is None
    assert (len(info.train_cameras), len(info.test_cameras)) == (NUM_TRAIN, NUM_TEST)
    focal = 0.5 * RES / math.tan(0.5 * CAMERA_ANGLE_X)
    for cam in info.train_cameras + info.test_cameras:
        assert (cam.width, cam.height) == (RES, RES) and cam.fx == pytest.approx(focal)
        center = cam.camera_center.double()
        assert center.norm().item() == pytest.approx(CAMERA_RADIUS, rel=1e-6)  # float32 viewmat
        assert center[2] > 0  # upper hemisphere
        origin = cam.viewmat.double() @ torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=torch.float64)
        assert origin[2] > 0 and abs(origin[0]) < 1e-5 and abs(origin[1]) < 1e-5  # looks at the origin
        assert 0.05 < cam.image.mean() < 0.95  # objects are in view, not an empty or saturated frame
    train = torch.stack([c.camera_center for c in info.train_cameras])
    test = torch.stack([c.camera_center for c in info.test_cameras])
    assert torch.cdist(test, train).min() > 0.3  # held-out views are new positions
    assert torch.pdist(train).min() > 0.3


def test_images_match_a_render_from_the_loaded_cameras(small_scene):
    """The Blender-convention poses written and read back reproduce the images: checks both conversions."""
    info = load_scene_info(str(small_scene))
    means, colors, scales = _object_points(torch.Generator().manual_seed(3))
    quats = torch.zeros(means.shape[0], 4)
    quats[:, 0] = 1
    opacities = torch.full((means.shape[0],), 0.9)
    for cam in (info.train_cameras[0], info.test_cameras[-1]):
        out = rasterization(means, quats, scales[:, None].repeat(1, 3), opacities, colors, cam.viewmat,
                            cam.intrinsics, cam.width, cam.height, settings=RasterSettings(backend="torch"))
        # 8-bit straight colour and 8-bit alpha, composited again: at most about one level of 1/255.
        torch.testing.assert_close(cam.image, out.image, atol=1.5 / 255, rtol=0)


def test_deterministic_for_a_seed(mini_scene, tmp_path):
    again = make_builtin_scene(tmp_path / "again", **MINI)
    files = sorted(p.relative_to(mini_scene) for p in mini_scene.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    assert len(files) == MINI["num_train"] + MINI["num_test"] + 3  # images, two transforms files, the stamp
    for rel in files:
        assert (mini_scene / rel).read_bytes() == (again / rel).read_bytes(), rel
    # Another seed places the Gaussians differently.
    assert not torch.equal(_object_points(torch.Generator().manual_seed(5))[0],
                           _object_points(torch.Generator().manual_seed(6))[0])


def test_stamp_skips_and_regenerates(mini_scene, tmp_path):
    out = Path(shutil.copytree(mini_scene, tmp_path / "s"))
    marker = out / "train" / "r_0.png"
    original = marker.read_bytes()
    marker.write_bytes(b"edited")
    make_builtin_scene(out, **MINI)
    assert marker.read_bytes() == b"edited"  # same parameters: left alone
    (out / STAMP).write_text("{")  # an unreadable stamp means an incomplete scene
    make_builtin_scene(out, **MINI)
    assert marker.read_bytes() == original
    make_builtin_scene(out, **{**MINI, "num_train": 1})
    assert json.loads((out / STAMP).read_text())["num_train"] == 1
    assert len(json.loads((out / "transforms_train.json").read_text())["frames"]) == 1


@pytest.mark.parametrize("kwargs, flag", [({"resolution": 4}, "--resolution"), ({"num_train": 0}, "--num_train"),
                                          ({"num_test": 0}, "--num_test"), ({"layout": "maze"}, "--layout")])
def test_bad_arguments(tmp_path, kwargs, flag):
    with pytest.raises(UserError, match=flag):
        make_builtin_scene(tmp_path / "s", **{"resolution": 16, "num_train": 2, "num_test": 1, **kwargs})


def test_cli(mini_scene, tmp_path):
    # On a complete scene with the same parameters the CLI only reports it (generation is tested above).
    ok = run_cli("-m", "scene.builtin", str(mini_scene), "--seed", str(MINI["seed"]), "--resolution",
                 str(MINI["resolution"]), "--num_train", str(MINI["num_train"]), "--num_test", str(MINI["num_test"]))
    assert ok.returncode == 0 and "ready" in ok.stdout, ok.stderr
    bad = run_cli("-m", "scene.builtin", str(tmp_path / "d"), "--resolution", "2")
    assert bad.returncode == 2 and bad.stderr.strip().startswith("error: --resolution")


def test_clutter_layout_draws_a_new_scene_per_seed_without_overlaps():
    """`clutter`: the seed draws the objects (kinds, places, sizes), footprints keep their gap, every kind appears."""
    import math

    layouts = [clutter_points(torch.Generator().manual_seed(seed))[3] for seed in range(40)]
    for placed in layouts:
        assert len(placed) == NUM_OBJECTS and {o["kind"] for o in placed} == {"sphere", "box", "ring", "column"}
        for i, a in enumerate(placed):
            assert math.hypot(*a["centre"]) <= 0.85
            for b in placed[:i]:
                assert math.dist(a["centre"], b["centre"]) > a["reach"] + b["reach"], (a, b)
    centres = {tuple(round(c, 6) for o in placed for c in o["centre"]) for placed in layouts}
    assert len(centres) == len(layouts)  # 40 seeds, 40 arrangements
    # objects: the seed only resamples points of the same objects (their centroid barely moves)
    a, b = (scene_gaussians(seed)[0].mean(0) for seed in (1, 2))
    assert (a - b).norm() < 0.05
    a, b = (scene_gaussians(seed, "clutter")[0].mean(0) for seed in (1, 2))
    assert (a - b).norm() > 0.05


def test_clutter_dataset_loads_and_stamps_its_layout(tmp_path):
    out = make_builtin_scene(tmp_path / "c", **{**MINI, "resolution": 24}, layout="clutter")
    assert json.loads((out / STAMP).read_text())["layout"] == "clutter"
    info = load_scene_info(str(out))
    assert len(info.train_cameras) == MINI["num_train"] and all(0.05 < c.image.mean() < 0.95
                                                                 for c in info.train_cameras)
    default = make_builtin_scene(tmp_path / "d", **MINI)
    assert "layout" not in json.loads((default / STAMP).read_text())  # stamps written before layouts stay valid


def test_default_layout_is_the_scene_every_recorded_result_used():
    """The `objects` layout's Gaussians for seed 0, as generated before layouts existed (sums recorded then): a change
    here would silently change the quickstart's dataset and every built-in result."""
    means, colors, scales = _object_points(torch.Generator().manual_seed(0))
    assert means.shape == (4000, 3)
    assert means.double().sum().item() == pytest.approx(1268.8504665239016, abs=1e-9)
    assert colors.double().sum().item() == pytest.approx(5982.2797727026045, abs=1e-9)
    assert scales.double().sum().item() == pytest.approx(203.49999964237213, abs=1e-9)
    # and the order: the ground disc's light squares, then its dark ones, last
    assert means[2500].tolist() == pytest.approx([-0.101492740213871, -0.8462867140769958, 0.0], abs=1e-7)
    assert means[-1].tolist() == pytest.approx([-0.5065761804580688, 1.0479389429092407, 0.0], abs=1e-7)
