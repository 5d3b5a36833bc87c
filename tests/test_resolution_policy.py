"""Resolution policy: the CPU width cap, the 3DGS 1.6k rule on CUDA, bad values, and what train.py records."""
import json
from types import SimpleNamespace

import pytest
from PIL import Image

from scene.resolution_policy import choose_resolution, probe_image_size, training_resolution
from tests.conftest import run_cli
from utils.errors import UserError


@pytest.mark.parametrize("full, max_width, expected, size", [
    ((800, 800), 200, 4, (200, 200)),  # lego: the smallest factor that fits
    ((800, 800), 400, 2, (400, 400)),
    ((648, 420), 200, 4, (162, 105)),  # garden: 648 / 2 = 324 is too wide, / 4 fits
    ((3000, 2000), 200, 200, (200, 133)),  # even / 8 = 375 is too wide: a target width
])
def test_cpu_run_without_r_is_capped(full, max_width, expected, size):
    choice = choose_resolution(-1, full, "cpu", max_width)
    assert (choice.resolution, choice.size, choice.full_size) == (expected, size, full)
    assert f"-r {expected}" in choice.notice and "-r 1" in choice.notice and "\n" not in choice.notice


def test_small_images_and_explicit_r_are_left_alone():
    assert choose_resolution(-1, (128, 128), "cpu", 200).notice is None
    assert choose_resolution(-1, (128, 128), "cpu", 200).resolution == -1
    explicit = choose_resolution(1, (800, 800), "cpu", 200)
    assert (explicit.resolution, explicit.size, explicit.notice) == (1, (800, 800), None)
    assert choose_resolution(300, (800, 800), "cpu", 200).size == (300, 300)


def test_cuda_keeps_the_3dgs_rule():
    assert choose_resolution(-1, (800, 800), "cuda", 200).resolution == -1  # the CPU cap does not apply
    wide = choose_resolution(-1, (4000, 3000), "cuda", 200)
    assert (wide.resolution, wide.size) == (1600, (1600, 1200)) and "-r 1" in wide.notice


@pytest.mark.parametrize("requested, full, max_width, names", [
    (8, (100, 100), 200, ["-r 8", "12x12"]),
    (10, (800, 600), 200, ["-r 10", "10x8"]),
    (-1, (800, 800), 10, ["--cpu_max_width 10", "10x10"]),
    (-1, (800, 800), 0, ["--cpu_max_width", "0"]),
    (4, (800, 800), -5, ["--cpu_max_width", "-5"]),
    (0, (800, 800), 200, ["--resolution"]),
])
def test_bad_values_name_the_problem(requested, full, max_width, names):
    with pytest.raises(UserError) as err:
        choose_resolution(requested, full, "cpu", max_width)
    assert all(n in str(err.value) for n in names), str(err.value)


def test_probe_image_size(tiny_scene, tmp_path):
    assert probe_image_size(str(tiny_scene)) == (32, 32)
    assert probe_image_size(str(tmp_path / "missing")) is None


def _transforms_json_dataset(root, frame_extra=None, top_extra=None, image_size=(400, 300)):
    """A nerfstudio-style dataset: transforms.json at the root, its frames under frames/ (no images/ folder)."""
    (root / "frames").mkdir(parents=True)
    if image_size is not None:
        Image.new("RGB", image_size).save(root / "frames" / "frame_00001.jpg")
    frame = {"file_path": "frames/frame_00001.jpg", "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4],
                                                                          [0, 0, 0, 1]], **(frame_extra or {})}
    (root / "transforms.json").write_text(json.dumps({"fl_x": 300.0, **(top_extra or {}), "frames": [frame]}))
    return root


def test_probe_reads_a_transforms_json_frame_outside_images(tmp_path):
    # The image file wins; without it, the frame's w/h, else the file's top-level w/h.
    assert probe_image_size(str(_transforms_json_dataset(tmp_path / "a"))) == (400, 300)
    assert probe_image_size(str(_transforms_json_dataset(tmp_path / "b", {"w": 640, "h": 480}, None, None))) \
        == (640, 480)
    assert probe_image_size(str(_transforms_json_dataset(tmp_path / "c", None, {"w": 960, "h": 540}, None))) \
        == (960, 540)
    assert probe_image_size(str(_transforms_json_dataset(tmp_path / "d", None, None, None))) is None


def test_transforms_json_dataset_gets_the_cpu_cap(tmp_path):
    # 400 px wide on the CPU with the default 200 px cap: -r 2, with the one-line notice.
    cfg = SimpleNamespace(source_path=str(_transforms_json_dataset(tmp_path / "ns")), images="images", resolution=-1,
                          device="cpu", cpu_max_width=200)
    choice = training_resolution(cfg)
    assert choice is not None and (choice.resolution, choice.size) == (2, (200, 150)) and "-r 2" in choice.notice


def test_train_records_the_effective_resolution(tiny_scene, tmp_path):
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(tmp_path / "m"), "--iterations", "2",
                "--num_random_points", "100", "--quiet", "--cpu_max_width", "16")
    assert r.returncode == 0, r.stderr
    assert "-r 2" in r.stdout and "--cpu_max_width 16" in r.stdout
    assert json.loads((tmp_path / "m" / "cfg_args").read_text())["model"]["resolution"] == 2
    assert json.loads((tmp_path / "m" / "cameras.json").read_text())[0]["width"] == 16


@pytest.mark.parametrize("flags, names", [(["-r", "4"], ["-r 4", "8x8"]),
                                          (["--cpu_max_width", "0"], ["--cpu_max_width"])])
def test_train_rejects_bad_values_with_one_line(tiny_scene, tmp_path, flags, names):
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(tmp_path / "m"), "--quiet", *flags)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and r.stderr.startswith("error:"), r.stderr
    assert all(n in r.stderr for n in names)
