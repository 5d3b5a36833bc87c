"""The live viewer behind view.py: a model's Gaussians as splats in the browser (viser), its cameras as frusta in
the report's colours; clicking a camera shows its image, a render from it and its uncertainty map of one kind (where
render.py --uncertainty wrote one: SPLIT/ours_N/uncertainty/KIND/NNNNN.png)."""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import torch

from gaussian_renderer import render
from gaussian_renderer.projection import covariance_3d
from reports import colors
from reports.cameras import CameraView, frustum_depth, read_cameras_json
from reports.images import open_rgb
from reports.run_data import latest, run_cameras
from scene.trained import TrainedModel
from utils.io import read_json
from utils.model_dir import CAMERAS, SELECTION

log = logging.getLogger(__name__)


def rotmat_to_wxyz(rot: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix [3, 3] (Shepperd's method, w >= 0). [4]"""
    m = np.asarray(rot, dtype=np.float64)
    t = np.trace(m)
    if t > 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0] * 4
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    q = np.asarray(q)
    return q * (1 if q[0] >= 0 else -1) / np.linalg.norm(q)


def to_uint8(image: torch.Tensor) -> np.ndarray:
    """[3, H, W] float in [0, 1] -> [H, W, 3] uint8, clamped and rounded as utils.image.save_image does."""
    return (image.detach().float().clamp(0, 1).permute(1, 2, 0).cpu().numpy() * 255.0 + 0.5).astype(np.uint8)


def splat_arrays(trained: TrainedModel) -> dict[str, np.ndarray]:
    """Centres [N,3], covariances [N,3,3], degree-0 colours [N,3] in [0,1] and opacities [N,1] (float32)."""
    g = trained.gaussians
    with torch.no_grad():
        cov = covariance_3d(g.unit_quats, g.scales)
        rgb = torch.clamp(g.sh_coeffs[:, 0, :] * 0.28209479177387814 + 0.5, 0.0, 1.0)
        return {"centers": g.params["means"].detach().cpu().float().numpy(),
                "covariances": cov.detach().cpu().float().numpy(), "rgbs": rgb.cpu().float().numpy(),
                "opacities": g.opacities.detach().cpu().float().numpy()[:, None]}


def viewer_cameras(trained: TrainedModel) -> list[CameraView]:
    """The run's cameras grouped and coloured as in its report (test cameras first, then training views)."""
    entries = read_cameras_json(trained.path / CAMERAS)
    selection = read_json(trained.path / SELECTION, missing="none")
    return run_cameras(entries, len(trained.scene.test_cameras), selection)


KIND_PREFERENCE = ("fisherrf_view", "fisherrf", "position_variance")  # view.py's default: the first one written


def written_kinds(model_path: Path) -> list[str]:
    """The map kinds of KIND_PREFERENCE that render.py --uncertainty wrote for the test or train split, in that
    order."""
    folders = [model_path / split / d.name / "uncertainty" for split in ("test", "train")
               for d in (model_path / split).glob("ours_*")]
    return [k for k in KIND_PREFERENCE if any(any((f / k).glob("*.png")) for f in folders)]


def uncertainty_png(model_path: Path, index: int, num_test: int, kind: str) -> Path | None:
    """render.py --uncertainty's colour map of kind `kind` of cameras.json entry `index` (test or train split),
    if written."""
    split, i = ("test", index) if index < num_test else ("train", index - num_test)
    method = latest([d for d in (model_path / split).glob("ours_*") if (d / "uncertainty" / kind).is_dir()])
    path = method / "uncertainty" / kind / f"{i:05d}.png" if method is not None else None
    return path if path is not None and path.is_file() else None


class Viewer:
    """A viser server showing one trained model. `Viewer(trained, port, uncertainty_kind)`; `.port`, `.stop()`.

    `uncertainty_kind`: the map kind shown (None: the first of KIND_PREFERENCE that was written, if any)."""

    def __init__(self, trained: TrainedModel, port: int, uncertainty_kind: str | None = None,
                 host: str = "127.0.0.1"):
        import viser

        self.trained = trained
        if uncertainty_kind is None:
            uncertainty_kind = next(iter(written_kinds(trained.path)), None)
        self.uncertainty_kind = uncertainty_kind
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.port = self.server.get_port()
        self.cameras = viewer_cameras(trained)
        self.scene_cameras = trained.scene.test_cameras + trained.scene.train_cameras  # cameras.json order
        splats = splat_arrays(trained)
        self.server.scene.add_gaussian_splats("/gaussians", **splats)
        center = np.median(splats["centers"], axis=0)  # [3]
        depth = 0.5 * frustum_depth(self.cameras, center)
        self.frame_view(center)
        self.title = self.server.gui.add_markdown("Click a camera to see its image, a render and its uncertainty.")
        blank = np.full((8, 8, 3), 255, np.uint8)
        self.images = {k: self.server.gui.add_image(blank, label=k) for k in ("image", "render", "uncertainty")}
        for i, cam in enumerate(self.cameras):
            frustum = self.server.scene.add_camera_frustum(
                f"/cameras/{i:04d}", fov=float(2 * np.arctan(cam.height / (2 * cam.fy))),
                aspect=cam.width / cam.height, scale=depth, color=colors.hex_to_rgb(cam.color),
                wxyz=rotmat_to_wxyz(cam.rotation), position=cam.position, thickness=1.5, thickness_units="screen")
            if cam.label:
                self.server.scene.add_label(f"/cameras/{i:04d}/pick", cam.label)
            frustum.on_click(lambda event, i=i: self.show(i))

    def frame_view(self, center: np.ndarray) -> None:
        """Start the browser's camera outside all cameras, looking at `center` [3], up = the cameras' mean up."""
        if not self.cameras:
            return
        pos = np.stack([c.position for c in self.cameras])  # [C, 3]
        up = -np.mean([c.rotation[:, 1] for c in self.cameras if c.rotation is not None], axis=0)  # OpenCV y is down
        up = up / max(np.linalg.norm(up), 1e-9)
        reach = np.linalg.norm(pos - center, axis=1).max()
        away = pos[0] - center
        away = away / max(np.linalg.norm(away), 1e-9)
        self.server.initial_camera.position = center + 1.6 * reach * away + 0.4 * reach * up
        self.server.initial_camera.look_at = center
        self.server.initial_camera.up = up

    def show(self, index: int) -> None:
        """Fill the GUI panel with camera `index` (cameras.json order): its image, a render, its uncertainty."""
        cam, view = self.cameras[index], self.scene_cameras[index]
        gain = f", gain {cam.gain:.4g}" if cam.gain is not None else ""
        self.title.content = f"**{cam.name}** ({cam.group}{gain})"
        if view.image is not None:
            self.images["image"].image = to_uint8(view.image)
        with torch.no_grad():
            out = render(view, self.trained.gaussians, self.trained.background, self.trained.settings)
        self.images["render"].image = to_uint8(out.image)
        kind = self.uncertainty_kind
        unc = uncertainty_png(self.trained.path, index, len(self.trained.scene.test_cameras), kind) if kind else None
        self.images["uncertainty"].image = open_rgb(unc) if unc else np.full((8, 8, 3), 200, np.uint8)
        self.images["uncertainty"].label = (f"uncertainty: {kind}" if unc else
                                            f"uncertainty: {kind or 'none'} (not written; render.py --uncertainty)")

    def stop(self) -> None:
        """Stop the server (closes its sockets and threads)."""
        self.server.stop()
