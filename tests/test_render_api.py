"""The public `rasterization` / `render` / `projection_jacobian` against compositions of their twins."""
import pytest
import torch

from gaussian_renderer import RasterSettings, project_gaussians, projection_jacobian, rasterization, render
from gaussian_renderer import camera_center
from gaussian_renderer.reference import rasterize_reference
from gaussian_renderer.sh import C0, sh_to_colors
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from tests.scenes import intrinsics_for, look_at_viewmat, random_gaussians
from utils.errors import UserError

F64 = torch.float64
W, H = 20, 13
VIEW = look_at_viewmat((0.5, -2.6, 0.9))
K = intrinsics_for(W, H, 50.0, cx=8.7, cy=7.2)
SETTINGS = RasterSettings(tile_size=8, chunk_size=3, backend="torch")  # the dense reference ignores the backend
BACKENDS = ["torch", "compiled"]  # every test that rasterizes runs on both (backend "auto" would pick one)


def settings(backend):
    return RasterSettings(tile_size=8, chunk_size=3, backend=backend)
BG = torch.tensor([0.1, 0.3, 0.6], dtype=F64)


def _activated(p):
    return p["means"], p["quats"], torch.exp(p["log_scales"]), torch.sigmoid(p["logit_opacities"])


def _reference_render(means, quats, scales, opacities, sh_coeffs, degree):
    """projection + SH colour + the dense reference compositing, all plain autograd."""
    proj = project_gaussians(means, quats, scales, VIEW, K, W, H)
    colors = sh_to_colors(sh_coeffs, means, camera_center(VIEW), degree)
    image, alpha = rasterize_reference(proj.means2d, proj.conics, opacities, colors, proj.depths, proj.radii, W, H,
                                       BG, SETTINGS)
    return image, alpha, proj


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("degree", [0, 2])
def test_rasterization_matches_reference_forward_and_backward(degree, backend):
    p = random_gaussians(12, seed=4, sh_degree=degree, scale=0.2)
    leaves = [t.clone().requires_grad_(True) for t in _activated(p)] + [p["sh_coeffs"].clone().requires_grad_(True)]
    out = rasterization(*leaves, VIEW, K, W, H, sh_degree=degree, background=BG, settings=settings(backend))
    ref_image, ref_alpha, ref_proj = _reference_render(*leaves, degree)
    assert out.image.shape == (3, H, W) and out.alpha.shape == (H, W)
    assert out.visible.sum() >= 8 and out.alpha.max() > 0.5  # most Gaussians land in view
    # float64: different summation orders only.
    torch.testing.assert_close(out.image, ref_image, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(out.alpha, ref_alpha, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(out.radii, ref_proj.radii, rtol=0, atol=0)
    torch.testing.assert_close(out.visible, ref_proj.radii > 0, rtol=0, atol=0)
    torch.testing.assert_close(out.depths, ref_proj.depths)

    cot_image, cot_alpha = torch.randn_like(ref_image), torch.randn_like(ref_alpha)
    ref_proj.means2d.retain_grad()
    ((ref_image * cot_image).sum() + (ref_alpha * cot_alpha).sum()).backward()
    ref_grads = [t.grad.clone() for t in leaves]
    for t in leaves:
        t.grad = None
    ((out.image * cot_image).sum() + (out.alpha * cot_alpha).sum()).backward()
    for got, want in zip([t.grad for t in leaves], ref_grads):
        assert want.abs().max() > 0  # every input receives gradient, so the comparison is not vacuous
        torch.testing.assert_close(got, want, rtol=1e-9, atol=1e-11)  # float64, summation order only
    # The screen-space gradient the densifier reads.
    torch.testing.assert_close(out.means2d.grad, ref_proj.means2d.grad, rtol=1e-9, atol=1e-11)


@pytest.mark.parametrize("backend", BACKENDS)
def test_sh_degree_zero_equals_precomputed_colours(backend):
    p = random_gaussians(6, seed=1, scale=0.2)
    args = _activated(p)
    via_sh = rasterization(*args, p["sh_coeffs"], VIEW, K, W, H, sh_degree=0, background=BG,
                           settings=settings(backend))
    colors = torch.clamp_min(C0 * p["sh_coeffs"][:, 0] + 0.5, 0.0)
    direct = rasterization(*args, colors, VIEW, K, W, H, background=BG, settings=settings(backend))
    torch.testing.assert_close(via_sh.image, direct.image, rtol=0, atol=1e-15)  # same arithmetic, one rounding


@pytest.mark.parametrize("backend", BACKENDS)
def test_zero_gaussians_render_the_background(backend):
    z3, z4 = torch.zeros(0, 3, dtype=F64), torch.zeros(0, 4, dtype=F64)
    for colors, degree in [(torch.zeros(0, 3, dtype=F64), None), (torch.zeros(0, 4, 3, dtype=F64), 1)]:
        out = rasterization(z3, z4, z3, torch.zeros(0, dtype=F64), colors, VIEW, K, W, H, sh_degree=degree,
                            background=BG, settings=settings(backend))
        torch.testing.assert_close(out.image, BG[:, None, None].expand(3, H, W), rtol=0, atol=0)
        torch.testing.assert_close(out.alpha, torch.zeros(H, W, dtype=F64), rtol=0, atol=0)
        assert out.means2d.shape == (0, 2) and out.radii.shape == (0,) and out.visible.shape == (0,)


@pytest.mark.parametrize("backend", BACKENDS)
def test_default_background_is_black_and_any_channel_count_works(backend):
    p = random_gaussians(1, seed=2, scale=0.3)
    colors = torch.rand(1, 5, dtype=F64)
    out = rasterization(*_activated(p), colors, VIEW, K, W, H, settings=settings(backend))
    assert out.image.shape == (5, H, W)
    far = out.alpha < 1e-12
    assert far.any() and (out.image[:, far] == 0).all()


def test_shape_errors_name_the_offending_shape():
    p = random_gaussians(3, seed=0)
    means, quats, scales, opacities = _activated(p)
    with pytest.raises(AssertionError, match=r"opacities must be \[N\].*\(3, 1\)"):
        rasterization(means, quats, scales, opacities[:, None], p["sh_coeffs"], VIEW, K, W, H, sh_degree=0)
    with pytest.raises(AssertionError, match=r"K >= 4.*\(3, 1, 3\)"):
        rasterization(means, quats, scales, opacities, p["sh_coeffs"], VIEW, K, W, H, sh_degree=1)
    with pytest.raises(AssertionError, match=r"colors must be \[N,D\].*\(3, 1, 3\)"):
        rasterization(means, quats, scales, opacities, p["sh_coeffs"], VIEW, K, W, H)
    with pytest.raises(AssertionError, match=r"background must be \[D\].*\(4,\)"):
        rasterization(means, quats, scales, opacities, torch.rand(3, 3, dtype=F64), VIEW, K, W, H,
                      background=torch.zeros(4, dtype=F64))


def _model_and_camera(sh_degree=1):
    p = random_gaussians(8, seed=5, sh_degree=sh_degree, scale=0.2)  # float64
    params = {"means": p["means"], "quats": p["quats"], "log_scales": p["log_scales"],
              "logit_opacities": p["logit_opacities"], "sh_dc": p["sh_coeffs"][:, :1], "sh_rest": p["sh_coeffs"][:, 1:]}
    model = GaussianModel(sh_degree, params)
    model.active_sh_degree = sh_degree
    fx, fy, cx, cy = K.tolist()
    camera = Camera(uid=0, image_name="c0", viewmat=VIEW, fx=fx, fy=fy, cx=cx, cy=cy, width=W, height=H)
    return model, camera


@pytest.mark.parametrize("backend", BACKENDS)
def test_render_of_a_model_equals_the_dense_reference_forward_and_backward(backend):
    model, camera = _model_and_camera()
    out = render(camera, model, BG, settings(backend))
    raw = {k: v.detach().clone().requires_grad_(True) for k, v in model.params.items()}
    # The model's activations written out here (exp, normalised wxyz quaternion, sigmoid, SH = dc + rest), then the
    # projection and the dense every-pixel reference compositing, all plain autograd.
    unit = raw["quats"] / raw["quats"].norm(dim=-1, keepdim=True)
    ref_image, ref_alpha, _ = _reference_render(raw["means"], unit, torch.exp(raw["log_scales"]),
                                                torch.sigmoid(raw["logit_opacities"]),
                                                torch.cat([raw["sh_dc"], raw["sh_rest"]], dim=1), 1)
    torch.testing.assert_close(out.image, ref_image, rtol=1e-10, atol=1e-12)  # float64, summation order only
    torch.testing.assert_close(out.alpha, ref_alpha, rtol=1e-10, atol=1e-12)
    cot = torch.randn_like(ref_image)
    (out.image * cot).sum().backward()
    (ref_image * cot).sum().backward()
    for name, leaf in raw.items():
        got = model.params[name].grad
        assert leaf.grad.abs().max() > 0, name  # every raw parameter receives gradient: not vacuous
        torch.testing.assert_close(got, leaf.grad, rtol=1e-9, atol=1e-11, msg=name)
    assert out.means2d.grad is not None and out.means2d.grad.shape == (8, 2)


@pytest.mark.parametrize("backend", BACKENDS)
def test_render_override_colour_equals_the_dense_reference(backend):
    model, camera = _model_and_camera()
    override = torch.rand(8, 3, dtype=F64, generator=torch.Generator().manual_seed(3))
    out = render(camera, model, BG, settings(backend), override_color=override)
    proj = project_gaussians(model.means.detach(), model.unit_quats.detach(), model.scales.detach(), VIEW, K, W, H)
    ref, _ = rasterize_reference(proj.means2d, proj.conics, model.opacities.detach(), override, proj.depths,
                                 proj.radii, W, H, BG, SETTINGS)
    torch.testing.assert_close(out.image, ref, rtol=1e-10, atol=1e-12)


def _attributes(means, quats, log_scales, logit_opacities, sh_coeffs, degree):
    """The 9 2D attributes of every Gaussian. [N, 9]"""
    proj = project_gaussians(means, quats, torch.exp(log_scales), VIEW, K, W, H)
    colors = sh_to_colors(sh_coeffs, means, camera_center(VIEW), degree)
    return torch.cat([proj.means2d, proj.conics, torch.sigmoid(logit_opacities)[:, None], colors], dim=1)


def _finite_difference_blocks(p, degree, h=1e-6):
    """d attributes_i / d (own raw parameters of i) by central differences, no autograd. Gaussians are independent,
    so perturbing one parameter coordinate of every Gaussian at once gives that column for all.
    -> {name: [N, 9, size]}"""
    names = ["means", "quats", "log_scales", "logit_opacities", "sh_coeffs"]
    base = {k: p[k].clone() for k in names}
    out = {}
    with torch.no_grad():
        for name in names:
            n = base[name].shape[0]
            cols = []
            for c in range(base[name][0].numel()):
                step = torch.zeros(n, base[name][0].numel(), dtype=F64)
                step[:, c] = h
                step = step.reshape(base[name].shape)
                plus = _attributes(**{**base, name: base[name] + step}, degree=degree)
                minus = _attributes(**{**base, name: base[name] - step}, degree=degree)
                cols.append((plus - minus) / (2 * h))  # [N, 9]
            out[name] = torch.stack(cols, dim=2)
    out["sh_dc"], out["sh_rest"] = out["sh_coeffs"][:, :, :3], out["sh_coeffs"][:, :, 3:]
    return out


@pytest.mark.parametrize("groups", [("means", "quats", "log_scales", "logit_opacities", "sh_dc"),
                                    ("sh_rest", "means", "sh_dc")])
def test_projection_jacobian_equals_finite_differences(groups):
    degree = 2
    p = random_gaussians(6, seed=7, sh_degree=degree, scale=0.2)
    p["sh_coeffs"][0] = 0.0
    p["sh_coeffs"][0, 0] = -4.0  # Gaussian 0's colour is clamped at 0 in every channel: zero colour rows
    blocks = _finite_difference_blocks(p, degree)
    expected = torch.cat([blocks[g] for g in groups], dim=2)
    jac = projection_jacobian(p["means"], p["quats"], p["log_scales"], p["logit_opacities"], p["sh_coeffs"], degree,
                              VIEW, K, W, H, groups)
    assert jac.shape == expected.shape
    # float64 central differences with h = 1e-6: truncation ~h^2 and rounding ~1e-16 / h relative to entries that
    # reach ~1e2 (conics): ~1e-8 absolute.
    torch.testing.assert_close(jac, expected, rtol=1e-6, atol=1e-6)
    assert (jac[0, 6:] == 0).all() and jac[1, 6:].abs().max() > 0


def test_projection_jacobian_rejects_unknown_groups():
    p = random_gaussians(2, seed=0)
    with pytest.raises(UserError, match="sh_rest"):
        projection_jacobian(p["means"], p["quats"], p["log_scales"], p["logit_opacities"], p["sh_coeffs"], 0,
                            VIEW, K, W, H, ("means", "colour"))
