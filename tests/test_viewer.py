"""view.py (viser): quaternions of the frusta, and in headless Chromium: the page connects its websocket and draws
the splats; a port in use is replaced by a free one (said on stdout); SIGINT stops it cleanly."""
from __future__ import annotations

import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import torch

from gaussian_renderer.projection import quat_to_rotmat
from tests.browser import browser_or_skip, close, console_errors, element_pixels, is_drawn
from tests.conftest import ROOT


def test_rotmat_to_wxyz_inverts_quat_to_rotmat():
    from reports.viewer import rotmat_to_wxyz

    q = torch.randn(64, 4, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    q = q / q.norm(dim=1, keepdim=True)
    q = q * torch.sign(q[:, :1])
    q[0] = torch.tensor([0.0, 1.0, 0.0, 0.0])  # 180 degrees: trace -1, the w = 0 branch
    rots = quat_to_rotmat(q).numpy()  # [64, 3, 3]
    got = np.stack([rotmat_to_wxyz(r) for r in rots])
    np.testing.assert_allclose(np.abs(np.sum(got * q.numpy(), axis=1)), 1.0, atol=1e-9)  # same rotation (±q)


def _lines(proc: subprocess.Popen) -> "queue.Queue[str]":
    out: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [out.put(line) for line in proc.stdout], daemon=True).start()
    return out


def _wait_line(lines: "queue.Queue[str]", needle: str, timeout: float, seen: list[str]) -> str:
    deadline = time.time() + timeout
    while time.time() < deadline:
        try:
            line = lines.get(timeout=0.5)
        except queue.Empty:
            continue
        seen.append(line)
        if needle in line:
            return line
    raise AssertionError(f"no line with {needle!r} within {timeout} s; got {seen}")


def test_viewer_in_browser(active_model):
    driver = browser_or_skip()
    blocker = socket.socket()
    blocker.bind(("127.0.0.1", 0))
    blocker.listen(1)
    busy = blocker.getsockname()[1]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "view.py", "-m", str(active_model), "--port", str(busy)], cwd=ROOT,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen: list[str] = []
    try:
        lines = _lines(proc)
        assert f"port {busy} is in use" in _wait_line(lines, "in use", 90, seen)
        url = re.search(r"http://localhost:\d+", _wait_line(lines, "http://localhost:", 30, seen)).group(0)
        assert not url.endswith(f":{busy}")
        driver.get(url)
        _wait_line(lines, "connected", 30, seen)  # the page's websocket reached the server
        canvas = driver.find_element("css selector", "canvas")
        deadline = time.time() + 30
        while not is_drawn(element_pixels(canvas)):
            assert time.time() < deadline, "the viewer's canvas stayed uniform"
            time.sleep(0.5)
        # viser's splat mesh logs this for its own geometry with any splats (random finite ones too)
        assert [e for e in console_errors(driver) if "computeBoundingSphere(): Computed radius is NaN" not in e] == []
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 0
        _wait_line(lines, "viewer stopped", 5, seen)
        assert "Traceback" not in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
        blocker.close()
        close(driver)


@pytest.mark.auto_backend  # the viewer renders with the model's settings, as view.py does
def test_clicking_a_camera_shows_its_image_render_and_uncertainty(active_model):
    from reports.images import open_rgb
    from reports.viewer import Viewer
    from scene.trained import load_trained

    trained = load_trained(active_model, device="cpu")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    for kind, shown in ((None, "fisherrf_view"), ("position_variance", "position_variance")):  # None: the default
        viewer = Viewer(trained, port, kind)
        try:
            assert len(viewer.cameras) == 4 + 14
            for index, split, i in ((1, "test", 1), (4 + 2, "train", 2)):  # test camera 1, training view 2
                viewer.show(index)
                folder = active_model / split / "ours_70"
                assert viewer.cameras[index].name in viewer.title.content
                np.testing.assert_array_equal(viewer.images["image"].image, open_rgb(folder / "gt" / f"{i:05d}.png"))
                diff = viewer.images["render"].image.astype(int) - open_rgb(folder / "renders" / f"{i:05d}.png")
                assert np.abs(diff).max() <= 1  # render.py's PNG of the same camera (rounding)
                np.testing.assert_array_equal(viewer.images["uncertainty"].image,
                                              open_rgb(folder / "uncertainty" / shown / f"{i:05d}.png"))
                assert viewer.images["uncertainty"].label == f"uncertainty: {shown}"
        finally:
            viewer.stop()


def test_kind_preference_covers_every_map_kind():
    from active.uncertainty import UNCERTAINTY_KINDS
    from reports.viewer import KIND_PREFERENCE

    assert sorted(KIND_PREFERENCE) == sorted(UNCERTAINTY_KINDS) == ["fisherrf", "fisherrf_view", "position_variance"]
