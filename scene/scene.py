"""`Scene`: the cameras of a dataset, its initial point cloud and the model directory's standard files."""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import torch

from scene.cameras import Camera
from scene.dataset_readers import PointCloud, SceneInfo, load_scene_info
from scene.gaussian_model import GaussianModel
from utils.io import write_json

log = logging.getLogger(__name__)

# Random initial points for synthetic scenes fill the cube [-h, h]^3 (the original 3DGS uses h = 1.3 for the
# NeRF-synthetic scenes, whose objects sit inside it); we scale h with the camera distance relative to those
# scenes (cameras at radius ~4.03), so a scene captured from farther away gets a proportionally larger cube.
BLENDER_RANDOM_CUBE_HALF_SIZE = 1.3
BLENDER_CAMERA_RADIUS = 4.031


@dataclass
class Scene:
    """Cameras (train/test), the initial point cloud and the scene's spatial extent."""

    info: SceneInfo
    model_path: Path

    @classmethod
    def load(cls, source_path: str, model_path: str | os.PathLike, *, white_background: bool, resolution: int,
             eval: bool, images: str = "images", device: str = "cpu") -> "Scene":
        """Read a Blender or COLMAP dataset (raises `UserError` on bad input)."""
        info = load_scene_info(source_path, white_background=white_background, resolution=resolution,
                               eval=eval, images=images, device=device)
        return cls(info, Path(model_path))

    @property
    def train_cameras(self) -> list[Camera]:
        return self.info.train_cameras

    @property
    def test_cameras(self) -> list[Camera]:
        return self.info.test_cameras

    @property
    def extent(self) -> float:
        return self.info.scene_extent

    def initial_point_cloud(self, num_random_points: int, seed: int) -> PointCloud:
        """SfM points when the dataset has them, else uniform random points in a cube around the origin."""
        if self.info.point_cloud is not None:
            return self.info.point_cloud
        centers = torch.stack([c.camera_center for c in self.train_cameras])  # [V, 3]
        radius = float(centers.norm(dim=-1).mean())
        half = BLENDER_RANDOM_CUBE_HALF_SIZE * radius / BLENDER_CAMERA_RADIUS
        g = torch.Generator().manual_seed(seed)
        points = (torch.rand(num_random_points, 3, generator=g) * 2 - 1) * half
        colors = torch.rand(num_random_points, 3, generator=g)
        return PointCloud(points=points, colors=colors)

    def new_gaussians(self, point_cloud: PointCloud, sh_degree: int, device: str) -> GaussianModel:
        """A fresh model initialised from `point_cloud`."""
        return GaussianModel.from_point_cloud(point_cloud.points, point_cloud.colors, sh_degree, device=device)

    def write_cameras_json(self) -> None:
        """`cameras.json` in the 3DGS format (train cameras; `id` is the view id used in selection.json)."""
        write_json(self.model_path / "cameras.json", [c.to_json(i) for i, c in enumerate(self.train_cameras)])

    def save_gaussians(self, gaussians: GaussianModel, iteration: int) -> Path:
        """Write `point_cloud/iteration_N/point_cloud.ply` and return its path."""
        path = self.model_path / "point_cloud" / f"iteration_{iteration}" / "point_cloud.ply"
        path.parent.mkdir(parents=True, exist_ok=True)
        gaussians.save_ply(path)
        return path
