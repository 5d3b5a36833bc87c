"""`active.blend_weights`: each Gaussian's blend weight summed over a view's pixels, against the twin that renders
one Gaussian's colour at a time (the image is linear in the colours), on both rasterizer backends; the weights
split the view's summed alpha, and an occluded Gaussian paints almost nothing."""
import pytest
import torch

from active.blend_weights import blend_weights
from gaussian_renderer import rasterization
from gaussian_renderer.settings import RasterSettings
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from tests.scenes import intrinsics_for, look_at_viewmat
from tests.test_fisher_cache import spiral_cameras
from tests.test_view_factors import model

pytestmark = pytest.mark.usefixtures("single_torch_thread")


def one_at_a_time(gaussians, camera, settings):
    """sum_px alpha_i T_i by rendering Gaussian i with colour 1 and every other with colour 0. [N]"""
    n = gaussians.means.shape[0]
    out = []
    with torch.no_grad():
        for i in range(n):
            colors = torch.zeros(n, 1)
            colors[i] = 1.0
            image = rasterization(gaussians.means, gaussians.quats, gaussians.scales, gaussians.opacities, colors,
                                  camera.viewmat, camera.intrinsics, camera.width, camera.height,
                                  background=torch.zeros(1), settings=settings).image
            out.append(float(image.sum()))
    return torch.tensor(out, dtype=torch.float64)


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_weights_equal_rendering_one_gaussian_at_a_time(backend):
    settings = RasterSettings(tile_size=8, chunk_size=8, backend=backend)
    gaussians, camera = model(n=40), spiral_cameras(6)[2]
    weights = blend_weights(gaussians, camera, settings)
    torch.testing.assert_close(weights, one_at_a_time(gaussians, camera, settings), rtol=1e-4, atol=1e-6)
    alpha = rasterization(gaussians.means, gaussians.quats, gaussians.scales, gaussians.opacities,
                          torch.ones(40, 1), camera.viewmat, camera.intrinsics, camera.width, camera.height,
                          background=torch.zeros(1), settings=settings).alpha
    assert float(weights.sum()) == pytest.approx(float(alpha.detach().sum()), rel=1e-4)
    assert (weights >= 0).all() and (weights > 0).any()


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_an_occluded_gaussian_paints_almost_nothing(backend):
    """A small Gaussian on the camera's axis behind a large, nearly opaque one: it paints a few % of what it paints
    alone (3DGS caps alpha at 0.99)."""
    means = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    params = {"means": means, "quats": torch.tensor([[1.0, 0, 0, 0]] * 2),
              "log_scales": torch.tensor([[0.1] * 3, [0.8] * 3]).log(), "logit_opacities": torch.full((2,), 8.0),
              "sh_dc": torch.zeros(2, 1, 3), "sh_rest": torch.zeros(2, 0, 3)}
    camera = Camera(0, "front", look_at_viewmat((0.0, 0.0, 4.0), up=(0.0, 1.0, 0.0), dtype=torch.float32),
                    *intrinsics_for(24, 24, 40.0).tolist(), 24, 24)
    settings = RasterSettings(backend=backend)
    both = blend_weights(GaussianModel(0, params), camera, settings)
    alone = blend_weights(GaussianModel(0, {k: v[:1] for k, v in params.items()}), camera, settings)
    assert both[1] > 10.0  # the near one (z = 1, facing the camera at z = 4) paints many pixels
    assert both[0] < 0.05 * alone[0] and alone[0] > 1.0
