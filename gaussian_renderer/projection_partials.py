"""Closed-form (forward-mode) Jacobian of each Gaussian's 2D attributes w.r.t. its raw parameters.

The same map as `project_gaussians` + `sh_to_colors` + sigmoid, differentiated by hand: tangents of the raw
parameters are pushed through camera space, the clamped EWA Jacobian, the 3D and 2D covariances and the conic
(one batched pass, no autograd graph). The autograd twin is `fisher_partials.projection_jacobian_autograd`.
"""
from __future__ import annotations

import torch

from gaussian_renderer.projection import (camera_center, clamp_ratio, frustum_limits, near_plane_depths,
                                         quat_to_rotmat)
from gaussian_renderer.sh import C0, C1, C2, C3, eval_sh, num_sh_bases


def _rotmat_tangents(quats: torch.Tensor) -> torch.Tensor:
    """d R(q / |q|) / d q for each of the 4 raw quaternion entries. [N, 4, 3, 3]"""
    norm = quats.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    q = quats / norm
    eye = torch.eye(4, dtype=quats.dtype, device=quats.device)
    dq = (eye[None] - q[:, :, None] * q[:, None, :]) / norm[:, :, None]  # [N, 4 (raw), 4 (unit)] rows = raw dir
    w, x, y, z = q.unbind(-1)
    dw, dx, dy, dz = (dq[..., i] for i in range(4))  # [N, 4] each
    w, x, y, z = (v[:, None] for v in (w, x, y, z))
    return 2 * torch.stack([
        -2 * (y * dy + z * dz), dx * y + x * dy - dw * z - w * dz, dx * z + x * dz + dw * y + w * dy,
        dx * y + x * dy + dw * z + w * dz, -2 * (x * dx + z * dz), dy * z + y * dz - dw * x - w * dx,
        dx * z + x * dz - dw * y - w * dy, dy * z + y * dz + dw * x + w * dx, -2 * (x * dx + y * dy),
    ], dim=-1).reshape(*dw.shape, 3, 3)


def sh_basis_gradients(dirs: torch.Tensor, degree: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Real SH basis values and their gradients w.r.t. the (unit) direction components, as in `eval_sh`.

    Args:
        dirs: unit directions. [N, 3]
    Returns:
        Y [N, K] and dY/d(x, y, z) [N, K, 3], K = (degree + 1)^2.
    """
    x, y, z = dirs.unbind(-1)
    one, zero = torch.ones_like(x), torch.zeros_like(x)
    xx, yy, zz = x * x, y * y, z * z
    vals = [C0 * one]
    grads = [(zero, zero, zero)]
    if degree >= 1:
        vals += [-C1 * y, C1 * z, -C1 * x]
        grads += [(zero, -C1 * one, zero), (zero, zero, C1 * one), (-C1 * one, zero, zero)]
    if degree >= 2:
        vals += [C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * zz - xx - yy), C2[3] * x * z, C2[4] * (xx - yy)]
        grads += [(C2[0] * y, C2[0] * x, zero), (zero, C2[1] * z, C2[1] * y),
                  (-2 * C2[2] * x, -2 * C2[2] * y, 4 * C2[2] * z), (C2[3] * z, zero, C2[3] * x),
                  (2 * C2[4] * x, -2 * C2[4] * y, zero)]
    if degree >= 3:
        vals += [C3[0] * y * (3 * xx - yy), C3[1] * x * y * z, C3[2] * y * (4 * zz - xx - yy),
                 C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy), C3[5] * z * (xx - yy),
                 C3[6] * x * (xx - 3 * yy)]
        grads += [(6 * C3[0] * x * y, C3[0] * (3 * xx - 3 * yy), zero),
                  (C3[1] * y * z, C3[1] * x * z, C3[1] * x * y),
                  (-2 * C3[2] * x * y, C3[2] * (4 * zz - xx - 3 * yy), 8 * C3[2] * y * z),
                  (-6 * C3[3] * x * z, -6 * C3[3] * y * z, C3[3] * (6 * zz - 3 * xx - 3 * yy)),
                  (C3[4] * (4 * zz - 3 * xx - yy), -2 * C3[4] * x * y, 8 * C3[4] * x * z),
                  (2 * C3[5] * x * z, -2 * C3[5] * y * z, C3[5] * (xx - yy)),
                  (C3[6] * (3 * xx - 3 * yy), -6 * C3[6] * x * y, zero)]
    return torch.stack(vals, -1), torch.stack([torch.stack(g, -1) for g in grads], 1)


def projection_jacobian_closed_form(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
                                    logit_opacities: torch.Tensor, sh_coeffs: torch.Tensor, sh_degree: int,
                                    viewmat: torch.Tensor, intrinsics: torch.Tensor, width: int, height: int,
                                    param_groups: tuple[str, ...], near_plane: float = 0.01,
                                    dilation: float = 0.3) -> dict[str, torch.Tensor]:
    """Per-group Jacobian blocks of the 2D attributes (means2d 2, conic 3, opacity 1, colour 3; A = 9).

    Inputs as `fisher_partials.projection_jacobian` (already checked). Returns {group: [N, A, P_group]} for the
    groups in `param_groups`, in the dtype of `means`.
    """
    n, dtype, device = means.shape[0], means.dtype, means.device
    means, quats, log_scales = means.detach(), quats.detach(), log_scales.detach()
    fx, fy, cx, cy = intrinsics.to(dtype).unbind(-1)
    rot, trans = viewmat[:3, :3].to(dtype), viewmat[:3, 3].to(dtype)
    t = means @ rot.T + trans  # [N, 3]
    z = t[:, 2]
    in_front, z_s = near_plane_depths(z, near_plane)
    # Tangents w.r.t. the means: dt/dm_p = rot[:, p]; z_safe is constant behind the near plane.
    dt = rot.T[None].expand(n, 3, 3)  # [N, P=3, 3]
    dz = dt[..., 2] * in_front[:, None]  # [N, 3]
    means2d_jac = torch.stack([fx * (dt[..., 0] * z_s[:, None] - t[:, 0:1] * dz),
                               fy * (dt[..., 1] * z_s[:, None] - t[:, 1:2] * dz)], 1) / (z_s * z_s)[:, None, None]

    tc, dtc = [], []
    for axis, (neg, pos) in enumerate(frustum_limits(fx, fy, cx, cy, width, height)):
        clamped, inside = clamp_ratio(t[:, axis], z_s, neg, pos)  # [N] each
        d_ratio = (dt[..., axis] * z_s[:, None] - t[:, axis:axis + 1] * dz) / (z_s * z_s)[:, None]
        tc.append(z_s * clamped)
        dtc.append(dz * clamped[:, None] + z_s[:, None] * d_ratio * inside[:, None])  # [N, 3]
    zeros = torch.zeros_like(z_s)
    jac = torch.stack([fx / z_s, zeros, -fx * tc[0] / z_s**2,
                       zeros, fy / z_s, -fy * tc[1] / z_s**2], -1).reshape(n, 2, 3)
    zeros3 = torch.zeros_like(dz)
    d_jac = torch.stack([-fx * dz / z_s[:, None]**2, zeros3,
                         -fx * (dtc[0] / z_s[:, None]**2 - 2 * tc[0][:, None] * dz / z_s[:, None]**3),
                         zeros3, -fy * dz / z_s[:, None]**2,
                         -fy * (dtc[1] / z_s[:, None]**2 - 2 * tc[1][:, None] * dz / z_s[:, None]**3)],
                        -1).reshape(n, 3, 2, 3)  # [N, P=3, 2, 3]

    scales = torch.exp(log_scales)
    rotmat = quat_to_rotmat(quats)  # [N, 3, 3]
    m = rotmat * scales[:, None, :]  # R S
    cov_cam = rot @ (m @ m.transpose(1, 2)) @ rot.T  # [N, 3, 3]
    # dM for quats (R' S) and log_scales (R[:, k] s_k e_k^T), then dSigma = dM M^T + M dM^T.
    d_m = torch.cat([_rotmat_tangents(quats) * scales[:, None, None, :],
                     torch.diag_embed(scales)[:, :, None, :] * rotmat[:, None]], 1)  # [N, 7, 3, 3]
    d_sigma = d_m @ m.transpose(1, 2)[:, None]
    d_cov_cam = rot @ (d_sigma + d_sigma.transpose(2, 3)) @ rot.T  # [N, 7, 3, 3]
    jc = jac @ cov_cam  # [N, 2, 3]
    cov2d = jc @ jac.transpose(1, 2)
    d_cov2d = torch.cat([d_jac @ jc.transpose(1, 2)[:, None] + (d_jac @ jc.transpose(1, 2)[:, None]).transpose(2, 3),
                         jac[:, None] @ d_cov_cam @ jac.transpose(1, 2)[:, None]], 1)  # [N, 10, 2, 2]
    a, b, c = cov2d[:, 0, 0] + dilation, cov2d[:, 0, 1], cov2d[:, 1, 1] + dilation
    da, db, dc = d_cov2d[..., 0, 0], d_cov2d[..., 0, 1], d_cov2d[..., 1, 1]  # [N, 10]
    det = a * c - b * b
    valid = in_front & (det > 0) & torch.isfinite(det) & torch.isfinite(t).all(dim=-1)
    det_s = torch.where(valid, det, torch.ones_like(det))[:, None]
    d_det = (da * c[:, None] + a[:, None] * dc - 2 * b[:, None] * db) * valid[:, None]
    conic_jac = torch.stack([dc / det_s - c[:, None] * d_det / det_s**2, -db / det_s + b[:, None] * d_det / det_s**2,
                             da / det_s - a[:, None] * d_det / det_s**2], 1)  # [N, 3, 10]

    # Colour: max(SH(dir) + 0.5, 0), dir = mean - camera centre.
    k_all = sh_coeffs.shape[1]
    center = camera_center(viewmat).to(dtype)
    direction = means - center
    dist = direction.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    unit = direction / dist
    live = (eval_sh(sh_coeffs.detach(), direction, sh_degree) + 0.5 >= 0).to(dtype)  # [N, 3] clamp inactive
    basis, d_basis = sh_basis_gradients(unit, sh_degree)  # [N, K], [N, K, 3]
    k = num_sh_bases(sh_degree)
    d_unit = (torch.eye(3, dtype=dtype, device=device)[None] - unit[:, :, None] * unit[:, None, :]) / dist[:, :, None]
    if sh_degree == 0:
        d_basis = torch.zeros_like(d_basis)
    color_means = torch.einsum("nkd,nkj,nji->ndi", sh_coeffs[:, :k].detach(), d_basis, d_unit) * live[..., None]
    eye3 = torch.eye(3, dtype=dtype, device=device)
    full_basis = torch.cat([basis, basis.new_zeros(n, k_all - k)], 1)  # [N, K_all]

    def block(rows: dict[int, torch.Tensor], cols: int) -> torch.Tensor:
        out = torch.zeros(n, 9, cols, dtype=dtype, device=device)
        for row, value in rows.items():
            out[:, row:row + value.shape[1]] = value
        return out

    blocks = {
        "means": block({0: means2d_jac, 2: conic_jac[..., :3], 6: color_means}, 3),
        "quats": block({2: conic_jac[..., 3:7]}, 4),
        "log_scales": block({2: conic_jac[..., 7:10]}, 3),
        "logit_opacities": block({5: (torch.sigmoid(logit_opacities) * torch.sigmoid(-logit_opacities))
                                  .detach()[:, None, None].to(dtype)}, 1),
        "sh_dc": block({6: C0 * live[:, :, None] * eye3}, 3),
        "sh_rest": block({6: (live[:, :, None, None] * full_basis[:, None, 1:, None] * eye3[None, :, None, :])
                          .reshape(n, 3, 3 * (k_all - 1))}, 3 * (k_all - 1)),
    }
    return {g: blocks[g] for g in param_groups}
