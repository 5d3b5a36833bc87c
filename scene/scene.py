"""`Scene`: the cameras of a dataset, its initial point cloud and the model directory's standard files."""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import torch

from arguments import ModelConfig
from scene.cameras import Camera
from scene.dataset_readers import PointCloud, SceneInfo, load_scene_info
from scene.gaussian_model import GaussianModel
from utils.io import write_json
from utils.model_dir import CAMERAS, point_cloud_ply

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
             eval: bool, images: str = "images", device: str = "cpu", skip_missing_images: bool = False,
             ignore_distortion: bool = False) -> "Scene":
        """Read a Blender, nerfstudio or COLMAP dataset (raises `UserError` on bad input)."""
        info = load_scene_info(source_path, white_background=white_background, resolution=resolution,
                               eval=eval, images=images, device=device, skip_missing_images=skip_missing_images,
                               ignore_distortion=ignore_distortion)
        return cls(info, Path(model_path))

    @classmethod
    def from_config(cls, model: ModelConfig, model_path: str | os.PathLike, source_path: str | None = None,
                    device: str | torch.device | None = None) -> "Scene":
        """`load` with the dataset options of a `ModelConfig` (`source_path`, `device` override the config's)."""
        return cls.load(source_path or model.source_path, model_path, white_background=model.white_background,
                        resolution=model.resolution, eval=model.eval, images=model.images,
                        device=device or model.device, skip_missing_images=model.skip_missing_images,
                        ignore_distortion=model.ignore_distortion)

    def dataset_record(self) -> dict:
        """What the loader did with the dataset, for cfg_args: its kind and the frames dropped as missing."""
        return {"kind": self.info.kind, "num_train": len(self.train_cameras), "num_test": len(self.test_cameras),
                "dropped_images": list(self.info.dropped_images)}

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
        if self.info.kind != "blender":  # synthetic scenes start from random points by design; say so for others
            log.info("no initial point file in the dataset (sparse_pc.ply, ply_file_path or points3D): starting "
                     "from %d random points", num_random_points)
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
        """`cameras.json` as 3DGS writes it: test cameras, then training cameras, `id` their index in that list.

        The training view with view id v (selection.json, --init_views) therefore has id `len(test_cameras) + v`.
        """
        cameras = self.test_cameras + self.train_cameras
        write_json(self.model_path / CAMERAS, [c.to_json(i) for i, c in enumerate(cameras)])

    def save_gaussians(self, gaussians: GaussianModel, iteration: int) -> Path:
        """Write `point_cloud/iteration_N/point_cloud.ply` and return its path."""
        path = point_cloud_ply(self.model_path, iteration)
        path.parent.mkdir(parents=True, exist_ok=True)
        gaussians.save_ply(path)
        return path
