"""Lens undistortion: a rendered image distorted with known coefficients is recovered; bad coefficients refused;
the cache beside the dataset (and its fallback)."""
from __future__ import annotations

import logging

import numpy as np
import pytest
import torch

from gaussian_renderer import RasterSettings, rasterization
from scene.builtin import hemisphere_positions, scene_gaussians
from scene.cameras import look_at
from scene.lens import Lens, Undistorter, round_trip_error
from scene.phone_capture import capture_lens, render_distorted
from utils.errors import UserError

# The dataset generators (scene.builtin, scene.phone_capture) render with the default backend, as for a user;
# the rasterizer's backends are tested in test_rasterize.py and test_compiled_rasterizer.py.
pytestmark = pytest.mark.auto_backend


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float(10 * np.log10(255.0 ** 2 / mse))


def render_pinhole(gaussians, viewmat: torch.Tensor, lens: Lens) -> np.ndarray:
    """The pinhole render straight from the rasterizer (the ground truth undistortion must reach). [H, W, 3]"""
    means, quats, scales, opacities, colors = gaussians
    out = rasterization(means, quats, scales, opacities, colors, viewmat.float(),
                        torch.tensor([lens.fx, lens.fy, lens.cx, lens.cy]), lens.width, lens.height,
                        settings=RasterSettings(backend="compiled"))  # the pinhole truth; backends: test_rasterize
    return (out.image.clamp(0, 1).permute(1, 2, 0).numpy() * 255 + 0.5).astype(np.uint8)


@pytest.mark.parametrize("model, dist", [("OPENCV", (-0.2, 0.05, 0.002, -0.003)),
                                         ("OPENCV", (0.15, -0.02, 0.0, 0.0, 0.01)),
                                         ("OPENCV_FISHEYE", (0.08, 0.02, -0.01, 0.002))])
def test_distorted_render_is_recovered(model, dist):
    torch.set_num_threads(1)
    gaussians = scene_gaussians(0)
    viewmat = look_at(hemisphere_positions(6, 0.5)[2])
    base = capture_lens(96, 128)
    lens = Lens(base.width, base.height, base.fx, base.fy * 1.02, base.cx + 1.5, base.cy - 2.0, model, dist)
    distorted = render_distorted(gaussians, viewmat, lens)  # [H, W, 3]: pinhole render, then distorted
    undistorter = Undistorter(lens, "test")
    recovered = undistorter.apply(distorted)
    truth = render_pinhole(gaussians, viewmat, undistorter.pinhole)
    inner = (slice(3, -3), slice(3, -3))  # bilinear twice: the outermost pixels blend the border
    recovered_psnr = psnr(recovered[inner], truth[inner])
    assert recovered_psnr > 30, recovered_psnr
    # Failing twin: taking the distorted image for the pinhole one is far off.
    assert psnr(distorted[inner], truth[inner]) < recovered_psnr - 8


def test_pinhole_of_alpha_zero_has_no_border():
    lens = capture_lens(96, 128, {"k1": -0.2, "k2": 0.05})
    undistorter = Undistorter(lens, "test")
    # Every output pixel samples inside the input image (alpha = 0: no black border).
    assert (undistorter.map_x >= -0.5).all() and (undistorter.map_x <= lens.width - 0.5).all()
    assert (undistorter.map_y >= -0.5).all() and (undistorter.map_y <= lens.height - 0.5).all()
    assert round_trip_error(lens) < 1e-3


@pytest.mark.parametrize("model, dist, message", [
    ("OPENCV", (-1.0, 0.0, 0.0, 0.0), "folds over"),
    ("OPENCV", (-0.3, 0.0, 0.0, 0.0), "folds over"),
    ("OPENCV", (float("nan"), 0.0, 0.0, 0.0), "undistortion failed"),
    ("OPENCV_FISHEYE", (-5.0, 0.0, 0.0, 0.0), "folds over"),
    ("OPENCV_FISHEYE", (0.1, 0.0), "needs 4 coefficients"),
    ("KANNALA", (0.1,), "unknown camera model"),
])
def test_bad_coefficients_are_one_line_errors(model, dist, message):
    with pytest.raises(UserError, match=message) as err:
        Undistorter(Lens(120, 160, 120.0, 120.0, 60.0, 80.0, model, dist), "frame 3")
    assert str(err.value).startswith("frame 3: ") and "\n" not in str(err.value)


def test_cache_falls_back_to_home_when_dataset_dir_is_not_writable(tmp_path, monkeypatch, caplog):
    from scene.dataset_readers import load_scene_info
    from scene.phone_capture import make_phone_capture
    root = make_phone_capture(tmp_path / "cap", 18, 32, num_frames=3, missing=0)
    info = load_scene_info(str(root))
    assert len(list((root / ".undistorted").rglob("*.png"))) == 3  # beside the dataset
    again = load_scene_info(str(root))  # from the cache: same pixels
    torch.testing.assert_close(again.train_cameras[1].image, info.train_cameras[1].image, atol=0, rtol=0)
    # A dataset directory where the cache cannot go (here: a file in its way, which stops root too).
    other = make_phone_capture(tmp_path / "cap2", 18, 32, num_frames=3, missing=0)
    (other / ".undistorted").write_text("in the way")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    with caplog.at_level(logging.WARNING):
        moved = load_scene_info(str(other))
    assert any("not writable" in r.getMessage() and ".cache/litegs" in r.getMessage() for r in caplog.records)
    assert len(list((tmp_path / "home" / ".cache" / "litegs" / "undistorted").rglob("*.png"))) == 3
    torch.testing.assert_close(moved.train_cameras[1].image, info.train_cameras[1].image, atol=0, rtol=0)
