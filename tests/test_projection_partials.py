"""Closed-form projection Jacobian (`projection_jacobian`) vs its autograd twin (`projection_jacobian_autograd`), for
both closed-form paths: the batched torch formulas (backend "torch") and the numba kernel (backend "compiled")."""
import pytest
import torch

from gaussian_renderer.compiled import numba_import_error
from gaussian_renderer.fisher_partials import projection_jacobian, projection_jacobian_autograd
from tests.scenes import intrinsics_for, look_at_viewmat, random_gaussians

W, H = 24, 18
VIEW = look_at_viewmat((0.3, -2.5, 1.0))
K = intrinsics_for(W, H, 50.0, cx=10.3, cy=8.6)  # off-centre principal point
ALL = ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest")


def scene(degree):
    """Random Gaussians plus the awkward cases: behind the camera, far outside the frustum (x/z clamped in the
    EWA Jacobian), colour clamped at 0 in some channels, a far-from-unit quaternion."""
    p = random_gaussians(12, seed=3, sh_degree=degree, scale=0.2)
    p["means"][0] = torch.tensor([0.3, -4.0, 1.2], dtype=torch.float64)  # behind the camera at (0.3, -2.5, 1)
    p["means"][1] = torch.tensor([3.0, 0.0, 0.0], dtype=torch.float64)  # far right of the image: clamped x/z
    p["means"][2] = torch.tensor([0.0, 0.0, -2.5], dtype=torch.float64)  # far below: clamped y/z
    p["sh_coeffs"][3, 0, :2] = -4.0  # two colour channels clamped
    p["quats"][4] *= 7.0
    return p


BACKENDS = ["torch", pytest.param("compiled", marks=pytest.mark.skipif(numba_import_error() is not None,
                                                                     reason="numba is not importable"))]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
@pytest.mark.parametrize("groups", [ALL, ("sh_rest", "log_scales", "means"), ("logit_opacities", "quats", "sh_dc")])
def test_closed_form_matches_autograd(backend, degree, groups):
    p = scene(degree)
    args = (p["means"], p["quats"], p["log_scales"], p["logit_opacities"], p["sh_coeffs"], degree, VIEW, K, W, H,
            groups)
    fast, twin = projection_jacobian(*args, backend=backend), projection_jacobian_autograd(*args)
    assert fast.shape == twin.shape and fast.dtype == twin.dtype
    torch.testing.assert_close(fast, twin, rtol=1e-10, atol=1e-10 * twin.abs().max().item())  # float64 rounding


@pytest.mark.skipif(numba_import_error() is not None, reason="numba is not importable")
@pytest.mark.parametrize("degree", [0, 3])
def test_compiled_matches_torch_closed_form_on_many_gaussians(degree):
    """The kernel's slices (one per thread) against the batched formulas, culled rows included, float32 inputs: the
    kernel computes in float64, so it matches the torch path run on the same values in float64."""
    p = random_gaussians(2000, seed=5, sh_degree=degree, scale=0.3)
    p32 = {k: v.float() for k, v in p.items()}
    args = [p32[k] for k in ("means", "quats", "log_scales", "logit_opacities", "sh_coeffs")]
    fast = projection_jacobian(*args, degree, VIEW.float(), K.float(), W, H, ALL, backend="compiled")
    twin = projection_jacobian(*(a.double() for a in args), degree, VIEW.float().double(), K.float().double(), W, H,
                               ALL, backend="torch")
    assert fast.dtype == torch.float64 and fast.shape == twin.shape
    torch.testing.assert_close(fast, twin, rtol=1e-9, atol=1e-9 * twin.abs().max().item())


@pytest.mark.skipif(numba_import_error() is not None, reason="numba is not importable")
@pytest.mark.parametrize("active", [0, 1, 2])
def test_compiled_matches_torch_below_the_stored_sh_degree(active):
    """During training the active SH degree is below the stored one (16 coefficients, degree 0-2 active): the rest
    columns of inactive bands are zero on both paths."""
    p = random_gaussians(300, seed=8, sh_degree=3, scale=0.3)
    args = [p[k] for k in ("means", "quats", "log_scales", "logit_opacities", "sh_coeffs")]
    fast = projection_jacobian(*args, active, VIEW, K, W, H, ALL, backend="compiled")
    twin = projection_jacobian(*args, active, VIEW, K, W, H, ALL, backend="torch")
    assert fast.shape == twin.shape == (300, 9, 14 + 45)
    torch.testing.assert_close(fast, twin, rtol=1e-10, atol=1e-10 * twin.abs().max().item())


def test_awkward_cases_are_exercised():
    p = scene(3)
    jac = projection_jacobian(p["means"], p["quats"], p["log_scales"], p["logit_opacities"], p["sh_coeffs"], 3,
                              VIEW, K, W, H, ALL)
    assert (jac[3, 6:8] == 0).all() and jac[3, 8].abs().max() > 0  # clamped channels have zero colour rows
    assert jac[1, 2:5, :3].abs().max() > 0  # clamped frustum: conic still moves with the mean (through z)


def test_float32_close_to_float64():
    p64 = scene(2)
    p32 = {k: v.float() for k, v in p64.items()}
    j64 = projection_jacobian(*(p64[k] for k in ("means", "quats", "log_scales", "logit_opacities", "sh_coeffs")),
                              2, VIEW, K, W, H, ALL)
    j32 = projection_jacobian(*(p32[k] for k in ("means", "quats", "log_scales", "logit_opacities", "sh_coeffs")),
                              2, VIEW.float(), K.float(), W, H, ALL)
    assert j32.dtype == torch.float32
    visible = torch.ones(12, dtype=torch.bool)
    visible[0] = False
    err = (j32.double() - j64)[visible].abs().max() / j64[visible].abs().max()
    assert err < 1e-5


@pytest.mark.skipif(numba_import_error() is not None, reason="numba is not importable")
@pytest.mark.parametrize("degree", [0, 1, 3])
def test_compiled_projection_and_colours_match_the_torch_functions(degree):
    """`project_and_shade_compiled` (the Fisher pass's render inputs, one kernel) against its twin,
    `project_gaussians` + `sh_to_colors` in float64: behind-camera, clamped, off-screen and clamped-colour rows
    included, and a zero quaternion (NaN rotation: culled by both)."""
    from gaussian_renderer.compiled.ops import project_and_shade_compiled
    from gaussian_renderer.projection import camera_center, project_gaussians
    from gaussian_renderer.sh import sh_to_colors
    p = scene(degree)
    p["means"][5] = torch.tensor([40.0, 0.0, 0.0], dtype=torch.float64)  # off-screen: culled
    p["quats"][6] = 0.0
    sh = p["sh_coeffs"]
    proj, colors = project_and_shade_compiled(p["means"], p["quats"], p["log_scales"], sh[:, :1], sh[:, 1:], degree,
                                              VIEW, K, W, H)
    unit = p["quats"] / p["quats"].norm(dim=-1, keepdim=True)
    twin = project_gaussians(p["means"], unit, p["log_scales"].exp(), VIEW, K, W, H)
    assert torch.equal(proj.radii, twin.radii) and (twin.radii == 0).sum() >= 3 and (twin.radii > 0).sum() >= 6
    kept = twin.radii > 0
    for name in ("means2d", "conics", "depths"):
        torch.testing.assert_close(getattr(proj, name)[kept], getattr(twin, name)[kept], rtol=1e-12, atol=1e-12)
    twin_colors = sh_to_colors(sh, p["means"], camera_center(VIEW), degree)
    torch.testing.assert_close(colors[kept], twin_colors[kept], rtol=1e-12, atol=1e-12)
    assert (colors[~kept] == 0).all() and (twin_colors[kept] == 0).any()  # a clamped channel among the kept
