"""cameras.json + point_cloud.ply as 3DGS tools read them: an independent reader (json, numpy, plyfile and the
closed-form SH of degree <= 1, none of our loaders) reproduces our renders of both splits."""
from __future__ import annotations

import json

import numpy as np
import torch
from plyfile import PlyData

from gaussian_renderer import RasterSettings, rasterization, render
from scene.scene import Scene

SH_C0, SH_C1 = 0.28209479177387814, 0.4886025119029199


def read_ply_independently(path) -> dict[str, np.ndarray]:
    """Activated Gaussians of a 3DGS PLY of SH degree 1 (f_rest channel-major: 3 channels x 3 bases)."""
    v = PlyData.read(str(path))["vertex"]
    col = lambda *names: np.stack([np.asarray(v[n], dtype=np.float64) for n in names], axis=1)
    rest = col(*[f"f_rest_{i}" for i in range(9)]).reshape(-1, 3, 3).transpose(0, 2, 1)  # [N, 3 bases, 3 ch]
    quats = col("rot_0", "rot_1", "rot_2", "rot_3")
    return {"means": col("x", "y", "z"), "dc": col("f_dc_0", "f_dc_1", "f_dc_2"), "rest": rest,
            "opacities": 1 / (1 + np.exp(-col("opacity")[:, 0])),
            "scales": np.exp(col("scale_0", "scale_1", "scale_2")),
            "quats": quats / np.linalg.norm(quats, axis=1, keepdims=True)}


def render_from_files(g: dict[str, np.ndarray], entry: dict) -> torch.Tensor:
    """Render one cameras.json entry: position = camera centre, rotation = camera-to-world (OpenCV axes), the
    principal point at the image centre as 3DGS assumes. [3, H, W]"""
    rot, pos = np.array(entry["rotation"]), np.array(entry["position"])
    viewmat = np.eye(4)
    viewmat[:3, :3], viewmat[:3, 3] = rot.T, -rot.T @ pos
    dirs = g["means"] - pos
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    x, y, z = dirs[:, :1], dirs[:, 1:2], dirs[:, 2:3]
    sh = SH_C0 * g["dc"] - SH_C1 * y * g["rest"][:, 0] + SH_C1 * z * g["rest"][:, 1] - SH_C1 * x * g["rest"][:, 2]
    colors = np.maximum(sh + 0.5, 0)
    t = lambda a: torch.tensor(a, dtype=torch.float32)
    w, h = entry["width"], entry["height"]
    out = rasterization(t(g["means"]), t(g["quats"]), t(g["scales"]), t(g["opacities"]), t(colors), t(viewmat),
                        t([entry["fx"], entry["fy"], w / 2, h / 2]), w, h, settings=RasterSettings(backend="torch"))
    return out.image


def test_ply_and_cameras_json_reproduce_both_splits(tiny_scene, tmp_path):
    scene = Scene.load(str(tiny_scene), tmp_path, white_background=False, resolution=-1, eval=True)
    gaussians = scene.new_gaussians(scene.initial_point_cloud(400, seed=0), sh_degree=1, device="cpu")
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():  # a non-trivial model: view-dependent colour, anisotropic, rotated, varied opacity
        gaussians.params["sh_rest"].copy_(0.3 * torch.randn(gaussians.params["sh_rest"].shape, generator=g))
        gaussians.params["log_scales"].add_(0.3 * torch.randn(gaussians.params["log_scales"].shape, generator=g))
        gaussians.params["quats"].copy_(torch.randn(gaussians.params["quats"].shape, generator=g))
        gaussians.params["logit_opacities"].copy_(torch.randn(gaussians.num_gaussians, generator=g) + 1)
    gaussians.active_sh_degree = 1
    scene.write_cameras_json()
    gaussians.save_ply(tmp_path / "point_cloud.ply")

    entries = json.loads((tmp_path / "cameras.json").read_text())
    cameras = scene.test_cameras + scene.train_cameras  # 3DGS order: test views first
    assert [e["id"] for e in entries] == list(range(4 + 14))
    assert [e["img_name"] for e in entries] == [c.image_name for c in cameras]
    assert set(entries[0]) >= {"id", "img_name", "width", "height", "position", "rotation", "fx", "fy"}
    files = read_ply_independently(tmp_path / "point_cloud.ply")
    for entry, cam in zip(entries, cameras):
        ours = render(cam, gaussians, torch.zeros(3), RasterSettings(backend="compiled")).image.detach()  # vs torch
        theirs = render_from_files(files, entry)
        assert ours.abs().max() > 0.05  # something is in view
        torch.testing.assert_close(theirs, ours, atol=2e-5, rtol=0)  # float32 PLY and json round trips
