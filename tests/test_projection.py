"""EWA projection against a per-Gaussian float64 twin written from the definitions, plus edge cases."""
import math

import pytest
import torch

from gaussian_renderer.projection import covariance_3d, project_gaussians, quat_to_rotmat
from tests.scenes import intrinsics_for, look_at_viewmat

F64 = torch.float64


def rotmat_reference(q: torch.Tensor) -> torch.Tensor:
    """Rodrigues' formula from the quaternion's axis and angle (theta = 2 atan2(|v|, w)). [4] -> [3, 3]"""
    q = q / q.norm()
    w, v = q[0], q[1:]
    s = v.norm()
    if s == 0:
        return torch.eye(3, dtype=q.dtype)
    axis, angle = v / s, 2 * torch.atan2(s, w)
    k = torch.tensor([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]], dtype=q.dtype)
    return torch.eye(3, dtype=q.dtype) + torch.sin(angle) * k + (1 - torch.cos(angle)) * k @ k


def project_reference(means, quats, scales, viewmat, intrinsics, width, height, near_plane=0.01, dilation=0.3):
    """One Gaussian at a time, in plain float64 steps. Returns means2d [N,2], conics [N,3], depths [N], radii [N]."""
    fx, fy, cx, cy = intrinsics.tolist()
    tan_x, tan_y = width / (2 * fx), height / (2 * fy)  # tan(fov/2)
    lim_left, lim_right = cx / fx + 0.3 * tan_x, (width - cx) / fx + 0.3 * tan_x
    lim_top, lim_bottom = cy / fy + 0.3 * tan_y, (height - cy) / fy + 0.3 * tan_y
    rot, trans = viewmat[:3, :3], viewmat[:3, 3]
    out_means, out_conics, out_depths, out_radii = [], [], [], []
    for i in range(means.shape[0]):
        x, y, z = (rot @ means[i] + trans).tolist()
        r = rotmat_reference(quats[i])
        sigma = r @ torch.diag(scales[i] ** 2) @ r.T
        sigma_cam = rot @ sigma @ rot.T
        u, v = fx * x / z + cx, fy * y / z + cy
        xc = min(max(x / z, -lim_left), lim_right) * z
        yc = min(max(y / z, -lim_top), lim_bottom) * z
        jac = torch.tensor([[fx / z, 0.0, -fx * xc / z**2], [0.0, fy / z, -fy * yc / z**2]], dtype=F64)
        cov2d = jac @ sigma_cam @ jac.T + dilation * torch.eye(2, dtype=F64)
        conic = torch.linalg.inv(cov2d)
        radius = math.ceil(3 * math.sqrt(torch.linalg.eigvalsh(cov2d).max().item()))
        box_hits_image = u + radius > 0 and u - radius < width and v + radius > 0 and v - radius < height
        if z <= near_plane or not box_hits_image:
            radius = 0
        out_means.append([u, v])
        out_conics.append([conic[0, 0].item(), conic[0, 1].item(), conic[1, 1].item()])
        out_depths.append(z)
        out_radii.append(radius)
    return (torch.tensor(out_means, dtype=F64), torch.tensor(out_conics, dtype=F64), torch.tensor(out_depths, dtype=F64),
            torch.tensor(out_radii, dtype=torch.int64))


def _scene(n=40, seed=0):
    """Gaussians spread wide enough that some are behind the camera, some off-screen, some clamped."""
    g = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=g, dtype=F64) * 2 - 1) * 5.0  # the camera sits 3.2 from the origin
    quats = torch.randn(n, 4, generator=g, dtype=F64) * 2.0  # unnormalised on purpose
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=F64) * 0.7 - 1.5)
    return means, quats, scales


W, H = 24, 14  # non-square
VIEW = look_at_viewmat((0.4, -3.0, 1.2))
K = intrinsics_for(W, H, 55.0, cx=9.3, cy=8.1)  # off-centre principal point


def test_quat_to_rotmat_matches_rodrigues_and_is_a_rotation():
    quats = torch.randn(20, 4, dtype=F64) * 3
    rots = quat_to_rotmat(quats)
    for q, r in zip(quats, rots):
        torch.testing.assert_close(r, rotmat_reference(q), rtol=0, atol=1e-13)  # float64 rounding of trig/sqrt
    torch.testing.assert_close(rots @ rots.transpose(1, 2), torch.eye(3, dtype=F64).expand(20, 3, 3))
    torch.testing.assert_close(torch.linalg.det(rots), torch.ones(20, dtype=F64))


def test_covariance_3d_is_r_s2_rt():
    quats, scales = torch.randn(6, 4, dtype=F64), torch.rand(6, 3, dtype=F64) + 0.1
    cov = covariance_3d(quats, scales)
    for q, s, c in zip(quats, scales, cov):
        r = rotmat_reference(q)
        torch.testing.assert_close(c, r @ torch.diag(s**2) @ r.T, rtol=0, atol=1e-13)  # float64 rounding


def _clamped_in_x(means2d, depths):
    """Gaussians in front whose x/z lies beyond the J clamp (1.3 tan(fov/2) around the centred axis, roughly). [N]"""
    fx, cx = K[0].item(), K[2].item()
    return (depths > 0.01) & ((means2d[:, 0] - cx).abs() / fx > 1.3 * W / (2 * fx))


def test_projection_matches_per_gaussian_twin():
    means, quats, scales = _scene()
    proj = project_gaussians(means, quats, scales, VIEW, K, W, H)
    ref_means, ref_conics, ref_depths, ref_radii = project_reference(means, quats, scales, VIEW, K, W, H)
    # The scene must exercise every branch, or the comparison proves little.
    assert (ref_depths <= 0.01).any()  # behind the camera
    assert ((ref_radii == 0) & (ref_depths > 0.01)).any()  # off-screen
    assert (_clamped_in_x(ref_means, ref_depths) & (ref_radii > 0)).any()  # visible with a clamped J
    torch.testing.assert_close(proj.radii, ref_radii, rtol=0, atol=0)
    front = ref_depths > 0.01
    # float64: the two paths differ only by rounding (conics up to ~1e2, hence the absolute floor).
    torch.testing.assert_close(proj.means2d[front], ref_means[front], rtol=1e-12, atol=1e-10)
    torch.testing.assert_close(proj.conics[front], ref_conics[front], rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(proj.depths, ref_depths, rtol=1e-12, atol=1e-12)


def test_gradients_match_finite_differences():
    means, quats, scales = _scene(n=40, seed=1)
    proj = project_gaussians(means, quats, scales, VIEW, K, W, H)
    keep = proj.radii > 0
    assert _clamped_in_x(proj.means2d, proj.depths)[keep].any()  # the clamp's zero derivative is checked too
    means, quats, scales = means[keep], quats[keep], scales[keep]
    inputs = tuple(t.clone().requires_grad_(True) for t in (means, quats, scales))

    def f(m, q, s):
        p = project_gaussians(m, q, s, VIEW, K, W, H)
        return p.means2d, p.conics

    # gradcheck: autograd vs central finite differences in float64 (default eps 1e-6, atol 1e-5, rtol 1e-3).
    assert torch.autograd.gradcheck(f, inputs)


def test_optical_axis_lands_on_principal_point():
    view = look_at_viewmat((1.0, -2.0, 0.5), target=(0.0, 0.0, 0.0))
    intr = torch.tensor([30.0, 34.0, 3.25, 17.75], dtype=F64)  # far off-centre, non-square image
    centre = -view[:3, :3].T @ view[:3, 3]
    forward = view[2, :3]  # camera z axis in world coordinates
    means = torch.stack([centre + 2.0 * forward, centre + 7.0 * forward])  # two depths on the axis
    proj = project_gaussians(means, torch.tensor([[1.0, 0, 0, 0]] * 2, dtype=F64),
                             torch.full((2, 3), 0.05, dtype=F64), view, intr, 40, 22)
    torch.testing.assert_close(proj.means2d, torch.tensor([[3.25, 17.75]] * 2, dtype=F64))  # float64 rounding
    torch.testing.assert_close(proj.depths, torch.tensor([2.0, 7.0], dtype=F64))
    assert (proj.radii > 0).all()


def test_single_isotropic_gaussian_closed_form():
    fx, z, s = 40.0, 4.0, 0.1
    view = torch.eye(4, dtype=F64)
    intr = torch.tensor([fx, fx, 8.0, 8.0], dtype=F64)
    proj = project_gaussians(torch.tensor([[0.0, 0.0, z]], dtype=F64), torch.tensor([[2.0, 0, 0, 0]], dtype=F64),
                             torch.full((1, 3), s, dtype=F64), view, intr, 16, 16)
    var = (fx * s / z) ** 2 + 0.3  # on the axis J = diag(f/z) and the dilation adds 0.3
    torch.testing.assert_close(proj.conics, torch.tensor([[1 / var, 0.0, 1 / var]], dtype=F64))
    assert proj.radii.tolist() == [math.ceil(3 * math.sqrt(var))]


def test_culling_behind_near_and_off_screen():
    view, intr = torch.eye(4, dtype=F64), torch.tensor([20.0, 20.0, 8.0, 8.0], dtype=F64)
    means = torch.tensor([[0.0, 0.0, -2.0],  # behind the camera
                          [0.0, 0.0, 0.005],  # in front of the near plane
                          [5.0, 0.0, 2.0],  # far right of the image (u = 58)
                          [0.45, 0.0, 1.0],  # centre off-screen (u = 17) but its 3-sigma box reaches in
                          [0.0, 0.0, 2.0]], dtype=F64)  # centre of the image
    scales = torch.full((5, 3), 0.02, dtype=F64)
    quats = torch.tensor([[1.0, 0, 0, 0]] * 5, dtype=F64)
    proj = project_gaussians(means, quats, scales, view, intr, 16, 16)
    assert proj.radii.tolist()[:3] == [0, 0, 0]
    assert proj.means2d[3, 0].item() > 16 and proj.radii[3].item() > 0
    assert proj.radii[4].item() > 0
    assert torch.isfinite(proj.conics).all() and torch.isfinite(proj.means2d).all()


def test_non_invertible_covariance_is_culled():
    view, intr = torch.eye(4, dtype=F64), torch.tensor([20.0, 20.0, 8.0, 8.0], dtype=F64)
    means = torch.tensor([[0.0, 0.0, 2.0], [0.0, 0.0, 2.0]], dtype=F64)
    scales = torch.tensor([[0.0, 0.0, 0.0], [float("inf"), 0.1, 0.1]], dtype=F64)
    quats = torch.tensor([[1.0, 0, 0, 0]] * 2, dtype=F64)
    # Without dilation a zero-scale Gaussian has a singular 2D covariance; an infinite one a non-finite one.
    proj = project_gaussians(means, quats, scales, view, intr, 16, 16, dilation=0.0)
    assert proj.radii.tolist() == [0, 0]


def test_zero_gaussians_and_shape_errors():
    empty = torch.zeros(0, 3, dtype=F64)
    proj = project_gaussians(empty, torch.zeros(0, 4, dtype=F64), empty, VIEW, K, W, H)
    assert proj.means2d.shape == (0, 2) and proj.conics.shape == (0, 3) and proj.radii.shape == (0,)
    with pytest.raises(AssertionError, match=r"quats must be \[N,4\].*\(3, 3\)"):
        project_gaussians(torch.zeros(3, 3), torch.zeros(3, 3), torch.ones(3, 3), VIEW, K, W, H)
    with pytest.raises(AssertionError, match="intrinsics"):
        project_gaussians(torch.zeros(3, 3), torch.ones(3, 4), torch.ones(3, 3), VIEW, torch.eye(3), W, H)
