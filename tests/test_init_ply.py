"""train.py --init_ply: a run starts from a PLY's Gaussians (to continue a model on more views); bad PLYs are one
line."""
import pytest
import torch

from scene.gaussian_model import GaussianModel
from scene.scene import Scene
from training.config import parse_config
from training.state import fresh_state
from utils.errors import UserError


def _fresh(tiny_scene, tmp_path, *flags):
    cfg = parse_config(["-s", str(tiny_scene), "-m", str(tmp_path / "run"), "--num_random_points", "300", *flags])
    scene = Scene.from_config(cfg.model, tmp_path / "run")
    return fresh_state(scene, cfg, [0, 1], 10)


def test_init_ply_starts_from_the_ply_not_the_dataset_points(tiny_scene, tmp_path):
    g = torch.Generator().manual_seed(0)
    n = 57
    params = {"means": torch.randn(n, 3, generator=g), "quats": torch.randn(n, 4, generator=g),
              "log_scales": torch.randn(n, 3, generator=g) - 3, "logit_opacities": torch.randn(n, generator=g),
              "sh_dc": torch.randn(n, 1, 3, generator=g), "sh_rest": torch.randn(n, 15, 3, generator=g)}
    ply = tmp_path / "start.ply"
    GaussianModel(3, params).save_ply(ply)
    state = _fresh(tiny_scene, tmp_path, "--init_ply", str(ply))
    assert state.gaussians.num_gaussians == n
    for name, value in params.items():
        torch.testing.assert_close(state.gaussians.params[name].detach(), value, rtol=0, atol=1e-6)
    assert state.gaussians.active_sh_degree == 3  # a loaded PLY's bands are all active, as 3DGS loads one
    default = _fresh(tiny_scene, tmp_path)
    assert default.gaussians.num_gaussians == 300  # without the flag: the dataset's (random) initial points


def test_init_ply_bad_input_is_one_line(tiny_scene, tmp_path):
    with pytest.raises(UserError, match="does not exist"):
        _fresh(tiny_scene, tmp_path, "--init_ply", str(tmp_path / "missing.ply"))
    ply = tmp_path / "deg1.ply"
    GaussianModel(1, {"means": torch.zeros(4, 3), "quats": torch.tensor([[1.0, 0, 0, 0]] * 4),
                      "log_scales": torch.zeros(4, 3), "logit_opacities": torch.zeros(4),
                      "sh_dc": torch.zeros(4, 1, 3), "sh_rest": torch.zeros(4, 3, 3)}).save_ply(ply)
    with pytest.raises(UserError, match="SH degree 1.*--sh_degree 1"):
        _fresh(tiny_scene, tmp_path, "--init_ply", str(ply))
