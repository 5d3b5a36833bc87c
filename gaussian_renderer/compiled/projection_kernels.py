"""numba kernel of the closed-form projection Jacobian: d (2D attributes) / d (raw parameters), one Gaussian at a time.

The same map and the same formulas as `gaussian_renderer.projection_partials.projection_jacobian_closed_form` (its
torch twin, compared in `tests/test_projection_partials.py`), written per Gaussian with 3x3 scalar algebra instead of
batched [N, 10, 3, 3] tensors, in float64. Rows of `out` (A = 9): mean2d x, y, conic a, b, c, opacity, colour RGB;
its columns are the raw parameter groups at the offsets `cols` gives (-1: group absent):

    cols[0] means (3)   cols[1] quats (4)   cols[2] log_scales (3)   cols[3] logit_opacities (1)
    cols[4] sh_dc (3)   cols[5] sh_rest (3 (K - 1), column 3 (k - 1) + channel)

Per Gaussian: camera-space t = R m + T, the clamped EWA Jacobian J and its tangents w.r.t. the mean, W = R rot(q) S
and its tangents w.r.t. the quaternion and log-scales, the 2D covariance J W W^T J^T + dilation I and the conic's
derivative through its determinant, then the view-dependent colour max(SH(dir) + 0.5, 0) and its derivatives.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from gaussian_renderer.projection import MAX_RADIUS, SIGMA_EXTENT
from gaussian_renderer.sh import C0, C1, C2, C3

_C2_0, _C2_1, _C2_2, _C2_3, _C2_4 = C2
_C3_0, _C3_1, _C3_2, _C3_3, _C3_4, _C3_5, _C3_6 = C3


@njit(inline="always", cache=True)
def _sh_basis(x, y, z, degree, vals, grads):
    """Real SH basis values vals[K] and their gradients grads[K, 3] at the unit direction (x, y, z), as `eval_sh`."""
    k = (degree + 1) * (degree + 1)
    for i in range(k):
        grads[i, 0] = 0.0
        grads[i, 1] = 0.0
        grads[i, 2] = 0.0
    vals[0] = C0
    if degree >= 1:
        vals[1], vals[2], vals[3] = -C1 * y, C1 * z, -C1 * x
        grads[1, 1], grads[2, 2], grads[3, 0] = -C1, C1, -C1
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        vals[4], vals[5] = _C2_0 * x * y, _C2_1 * y * z
        vals[6], vals[7], vals[8] = _C2_2 * (2 * zz - xx - yy), _C2_3 * x * z, _C2_4 * (xx - yy)
        grads[4, 0], grads[4, 1] = _C2_0 * y, _C2_0 * x
        grads[5, 1], grads[5, 2] = _C2_1 * z, _C2_1 * y
        grads[6, 0], grads[6, 1], grads[6, 2] = -2 * _C2_2 * x, -2 * _C2_2 * y, 4 * _C2_2 * z
        grads[7, 0], grads[7, 2] = _C2_3 * z, _C2_3 * x
        grads[8, 0], grads[8, 1] = 2 * _C2_4 * x, -2 * _C2_4 * y
    if degree >= 3:
        xx, yy, zz = x * x, y * y, z * z
        vals[9] = _C3_0 * y * (3 * xx - yy)
        vals[10] = _C3_1 * x * y * z
        vals[11] = _C3_2 * y * (4 * zz - xx - yy)
        vals[12] = _C3_3 * z * (2 * zz - 3 * xx - 3 * yy)
        vals[13] = _C3_4 * x * (4 * zz - xx - yy)
        vals[14] = _C3_5 * z * (xx - yy)
        vals[15] = _C3_6 * x * (xx - 3 * yy)
        grads[9, 0], grads[9, 1] = 6 * _C3_0 * x * y, _C3_0 * (3 * xx - 3 * yy)
        grads[10, 0], grads[10, 1], grads[10, 2] = _C3_1 * y * z, _C3_1 * x * z, _C3_1 * x * y
        grads[11, 0], grads[11, 1], grads[11, 2] = -2 * _C3_2 * x * y, _C3_2 * (4 * zz - xx - 3 * yy), 8 * _C3_2 * y * z
        grads[12, 0], grads[12, 1] = -6 * _C3_3 * x * z, -6 * _C3_3 * y * z
        grads[12, 2] = _C3_3 * (6 * zz - 3 * xx - 3 * yy)
        grads[13, 0], grads[13, 1], grads[13, 2] = _C3_4 * (4 * zz - 3 * xx - yy), -2 * _C3_4 * x * y, 8 * _C3_4 * x * z
        grads[14, 0], grads[14, 1], grads[14, 2] = 2 * _C3_5 * x * z, -2 * _C3_5 * y * z, _C3_5 * (xx - yy)
        grads[15, 0], grads[15, 1] = _C3_6 * (3 * xx - 3 * yy), -6 * _C3_6 * x * y


@njit(inline="always", cache=True)
def _rotation_and_tangents(q0, q1, q2, q3, rmat, d_rmat):
    """rmat [3, 3] = R(q / |q|) and d_rmat [4, 3, 3] = its derivative along each raw quaternion entry (wxyz)."""
    norm = max(math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3), 1e-12)
    w, x, y, z = q0 / norm, q1 / norm, q2 / norm, q3 / norm
    rmat[0, 0], rmat[0, 1], rmat[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    rmat[1, 0], rmat[1, 1], rmat[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    rmat[2, 0], rmat[2, 1], rmat[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    unit = (w, x, y, z)
    for r in range(4):  # d unit / d raw_r = (e_r - u u_r) / |q|
        dw = ((1.0 if r == 0 else 0.0) - w * unit[r]) / norm
        dx = ((1.0 if r == 1 else 0.0) - x * unit[r]) / norm
        dy = ((1.0 if r == 2 else 0.0) - y * unit[r]) / norm
        dz = ((1.0 if r == 3 else 0.0) - z * unit[r]) / norm
        d_rmat[r, 0, 0] = -4 * (y * dy + z * dz)
        d_rmat[r, 0, 1] = 2 * (dx * y + x * dy - dw * z - w * dz)
        d_rmat[r, 0, 2] = 2 * (dx * z + x * dz + dw * y + w * dy)
        d_rmat[r, 1, 0] = 2 * (dx * y + x * dy + dw * z + w * dz)
        d_rmat[r, 1, 1] = -4 * (x * dx + z * dz)
        d_rmat[r, 1, 2] = 2 * (dy * z + y * dz - dw * x - w * dx)
        d_rmat[r, 2, 0] = 2 * (dx * z + x * dz - dw * y - w * dy)
        d_rmat[r, 2, 1] = 2 * (dy * z + y * dz + dw * x + w * dx)
        d_rmat[r, 2, 2] = -4 * (x * dx + y * dy)


@njit(parallel=True, cache=True)
def projection_jacobian_kernel(means, quats, log_scales, logit_opacities, sh, degree, view_rot, view_trans, center,
                               intrinsics, limits, near_plane, dilation, cols, out, num_slices):
    """Fills out [N, 9, P] (float64, any content on entry) with each Gaussian's Jacobian, computed in float64.

    means [N, 3], quats [N, 4] raw wxyz, log_scales [N, 3], logit_opacities [N], sh [N, K, 3], all of one float dtype
    (float32 inputs are read as float64, as the same values converted first); the camera, float64: view_rot
    [3, 3] and view_trans [3] (world-to-camera), center [3] its position, intrinsics (fx, fy, cx, cy), limits
    (neg_x, pos_x, neg_y, pos_y) of the clamped ratios (`projection.frustum_limits`); cols [6] int64 as above.
    """
    n, k_all = means.shape[0], sh.shape[1]
    k_active = (degree + 1) * (degree + 1)
    fx, fy = intrinsics[0], intrinsics[1]
    step = (n + num_slices - 1) // num_slices
    for s in prange(num_slices):
        t = np.empty(3)
        dz = np.empty(3)
        tc = np.empty(2)
        dtc = np.empty((2, 3))
        jac = np.empty((2, 3))
        d_jac = np.empty((3, 2, 3))
        rmat = np.empty((3, 3))
        d_rmat = np.empty((4, 3, 3))
        w_mat = np.empty((3, 3))  # W = view_rot R S
        dw_mat = np.empty((3, 3))
        jw = np.empty((2, 3))
        jdw = np.empty((2, 3))
        cj = np.empty((3, 2))  # cov_cam J^T
        d_cov = np.empty((10, 3))  # per direction: d (a, b, c) of the 2D covariance
        scales = np.empty(3)
        vals = np.full(16, np.nan)  # bands above the active degree stay NaN: reading one would show
        grads = np.empty((16, 3))
        unit = np.empty(3)
        live = np.empty(3)
        for i in range(s * step, min(n, (s + 1) * step)):
            for r in range(9):  # `out` arrives uninitialised: its rows are zeroed by the thread that owns them
                for col in range(out.shape[2]):
                    out[i, r, col] = 0.0
            for a in range(3):
                t[a] = view_trans[a] + view_rot[a, 0] * means[i, 0] + view_rot[a, 1] * means[i, 1] \
                    + view_rot[a, 2] * means[i, 2]
            in_front = t[2] > near_plane
            zs = t[2] if in_front else 1.0
            zs2 = zs * zs
            zs3 = zs2 * zs
            for p in range(3):
                dz[p] = view_rot[2, p] if in_front else 0.0
            # the clamped ratios x/z, y/z and their tangents along the mean
            for ax in range(2):
                neg, pos = limits[2 * ax], limits[2 * ax + 1]
                ratio = t[ax] / zs
                clamped = min(max(ratio, -neg), pos)
                inside = 1.0 if (ratio > -neg and ratio < pos) else 0.0
                tc[ax] = zs * clamped
                for p in range(3):
                    d_ratio = (view_rot[ax, p] * zs - t[ax] * dz[p]) / zs2
                    dtc[ax, p] = dz[p] * clamped + zs * d_ratio * inside
            jac[0, 0], jac[0, 1], jac[0, 2] = fx / zs, 0.0, -fx * tc[0] / zs2
            jac[1, 0], jac[1, 1], jac[1, 2] = 0.0, fy / zs, -fy * tc[1] / zs2
            for p in range(3):
                d_jac[p, 0, 0], d_jac[p, 0, 1] = -fx * dz[p] / zs2, 0.0
                d_jac[p, 0, 2] = -fx * (dtc[0, p] / zs2 - 2 * tc[0] * dz[p] / zs3)
                d_jac[p, 1, 0], d_jac[p, 1, 1] = 0.0, -fy * dz[p] / zs2
                d_jac[p, 1, 2] = -fy * (dtc[1, p] / zs2 - 2 * tc[1] * dz[p] / zs3)

            # W = view_rot R(q) S, the 2D covariance J W W^T J^T and its tangents
            _rotation_and_tangents(np.float64(quats[i, 0]), np.float64(quats[i, 1]), np.float64(quats[i, 2]),
                                   np.float64(quats[i, 3]), rmat, d_rmat)
            for k in range(3):
                scales[k] = math.exp(np.float64(log_scales[i, k]))
            for a in range(3):
                for k in range(3):
                    w_mat[a, k] = (view_rot[a, 0] * rmat[0, k] + view_rot[a, 1] * rmat[1, k]
                                   + view_rot[a, 2] * rmat[2, k]) * scales[k]
            for r in range(2):
                for k in range(3):
                    jw[r, k] = jac[r, 0] * w_mat[0, k] + jac[r, 1] * w_mat[1, k] + jac[r, 2] * w_mat[2, k]
            for a in range(3):  # cov_cam J^T = W (J W)^T
                for r in range(2):
                    cj[a, r] = w_mat[a, 0] * jw[r, 0] + w_mat[a, 1] * jw[r, 1] + w_mat[a, 2] * jw[r, 2]
            cov_a = jw[0, 0] * jw[0, 0] + jw[0, 1] * jw[0, 1] + jw[0, 2] * jw[0, 2] + dilation
            cov_b = jw[0, 0] * jw[1, 0] + jw[0, 1] * jw[1, 1] + jw[0, 2] * jw[1, 2]
            cov_c = jw[1, 0] * jw[1, 0] + jw[1, 1] * jw[1, 1] + jw[1, 2] * jw[1, 2] + dilation
            for p in range(3):  # mean: dJ cov_cam J^T + its transpose
                x00 = d_jac[p, 0, 0] * cj[0, 0] + d_jac[p, 0, 1] * cj[1, 0] + d_jac[p, 0, 2] * cj[2, 0]
                x01 = d_jac[p, 0, 0] * cj[0, 1] + d_jac[p, 0, 1] * cj[1, 1] + d_jac[p, 0, 2] * cj[2, 1]
                x10 = d_jac[p, 1, 0] * cj[0, 0] + d_jac[p, 1, 1] * cj[1, 0] + d_jac[p, 1, 2] * cj[2, 0]
                x11 = d_jac[p, 1, 0] * cj[0, 1] + d_jac[p, 1, 1] * cj[1, 1] + d_jac[p, 1, 2] * cj[2, 1]
                d_cov[p, 0], d_cov[p, 1], d_cov[p, 2] = 2 * x00, x01 + x10, 2 * x11
            for d in range(7):  # quaternion entries (d_rmat S), then log-scales (column k of R S)
                for a in range(3):
                    for k in range(3):
                        if d < 4:
                            dm = view_rot[a, 0] * d_rmat[d, 0, k] + view_rot[a, 1] * d_rmat[d, 1, k] \
                                + view_rot[a, 2] * d_rmat[d, 2, k]
                            dw_mat[a, k] = dm * scales[k]
                        else:
                            dw_mat[a, k] = w_mat[a, k] if k == d - 4 else 0.0
                for r in range(2):
                    for k in range(3):
                        jdw[r, k] = jac[r, 0] * dw_mat[0, k] + jac[r, 1] * dw_mat[1, k] + jac[r, 2] * dw_mat[2, k]
                y00 = jdw[0, 0] * jw[0, 0] + jdw[0, 1] * jw[0, 1] + jdw[0, 2] * jw[0, 2]
                y01 = jdw[0, 0] * jw[1, 0] + jdw[0, 1] * jw[1, 1] + jdw[0, 2] * jw[1, 2]
                y10 = jdw[1, 0] * jw[0, 0] + jdw[1, 1] * jw[0, 1] + jdw[1, 2] * jw[0, 2]
                y11 = jdw[1, 0] * jw[1, 0] + jdw[1, 1] * jw[1, 1] + jdw[1, 2] * jw[1, 2]
                d_cov[3 + d, 0], d_cov[3 + d, 1], d_cov[3 + d, 2] = 2 * y00, y01 + y10, 2 * y11

            # conic = (c, -b, a) / det; culled Gaussians keep det 1 and no det derivative (finite, unused rows)
            det = cov_a * cov_c - cov_b * cov_b
            finite_t = math.isfinite(t[0]) and math.isfinite(t[1]) and math.isfinite(t[2])
            valid = in_front and det > 0 and math.isfinite(det) and finite_t
            det_s = det if valid else 1.0
            det_s2 = det_s * det_s
            for d in range(10):
                da, db, dc = d_cov[d, 0], d_cov[d, 1], d_cov[d, 2]
                d_det = (da * cov_c + cov_a * dc - 2 * cov_b * db) if valid else 0.0
                if d < 3:
                    col = cols[0] + d if cols[0] >= 0 else -1
                elif d < 7:
                    col = cols[1] + d - 3 if cols[1] >= 0 else -1
                else:
                    col = cols[2] + d - 7 if cols[2] >= 0 else -1
                if col >= 0:
                    out[i, 2, col] = dc / det_s - cov_c * d_det / det_s2
                    out[i, 3, col] = -db / det_s + cov_b * d_det / det_s2
                    out[i, 4, col] = da / det_s - cov_a * d_det / det_s2
            if cols[0] >= 0:
                for p in range(3):
                    out[i, 0, cols[0] + p] = fx * (view_rot[0, p] * zs - t[0] * dz[p]) / zs2
                    out[i, 1, cols[0] + p] = fy * (view_rot[1, p] * zs - t[1] * dz[p]) / zs2
            if cols[3] >= 0:
                sig = 1.0 / (1.0 + math.exp(-np.float64(logit_opacities[i])))
                out[i, 5, cols[3]] = sig * (1.0 - sig)

            # colour: max(SH(dir) + 0.5, 0) with dir = mean - centre; rows are 0 where the clamp is active
            if cols[0] < 0 and cols[4] < 0 and cols[5] < 0:
                continue
            ux, uy, uz = means[i, 0] - center[0], means[i, 1] - center[1], means[i, 2] - center[2]
            dist = max(math.sqrt(ux * ux + uy * uy + uz * uz), 1e-12)
            unit[0], unit[1], unit[2] = ux / dist, uy / dist, uz / dist
            _sh_basis(unit[0], unit[1], unit[2], degree, vals, grads)
            for ch in range(3):
                value = 0.0
                for k in range(k_active):
                    value += vals[k] * sh[i, k, ch]
                live[ch] = 1.0 if value + 0.5 >= 0 else 0.0
            if cols[0] >= 0 and degree > 0:
                for ch in range(3):
                    g0, g1, g2 = 0.0, 0.0, 0.0
                    for k in range(1, k_active):
                        g0 += sh[i, k, ch] * grads[k, 0]
                        g1 += sh[i, k, ch] * grads[k, 1]
                        g2 += sh[i, k, ch] * grads[k, 2]
                    radial = g0 * unit[0] + g1 * unit[1] + g2 * unit[2]
                    out[i, 6 + ch, cols[0] + 0] = live[ch] * (g0 - unit[0] * radial) / dist
                    out[i, 6 + ch, cols[0] + 1] = live[ch] * (g1 - unit[1] * radial) / dist
                    out[i, 6 + ch, cols[0] + 2] = live[ch] * (g2 - unit[2] * radial) / dist
            if cols[4] >= 0:
                for ch in range(3):
                    out[i, 6 + ch, cols[4] + ch] = C0 * live[ch]
            if cols[5] >= 0:
                for k in range(1, min(k_active, k_all)):
                    for ch in range(3):
                        out[i, 6 + ch, cols[5] + 3 * (k - 1) + ch] = live[ch] * vals[k]


@njit(parallel=True, cache=True)
def project_and_shade_kernel(means, quats, log_scales, sh_dc, sh_rest, degree, view_rot, view_trans, center,
                             intrinsics, limits, near_plane, dilation, width, height, means2d, conics, depths, radii,
                             colors, num_slices):
    """`projection.project_gaussians` and, for the Gaussians it keeps (radius > 0), `sh.sh_to_colors`, in float64
    without gradients (the Fisher pass's render). Inputs as `projection_jacobian_kernel`'s (sh_dc [N, 1, 3], sh_rest
    [N, K - 1, 3]); fills means2d [N, 2], conics [N, 3], depths [N], radii [N] (int64, 0 = culled) and colors [N, 3]
    (0 where culled)."""
    n = means.shape[0]
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    step = (n + num_slices - 1) // num_slices
    for s in prange(num_slices):
        t = np.empty(3)
        tc = np.empty(2)
        rmat = np.empty((3, 3))
        d_rmat = np.empty((4, 3, 3))  # the rotation's tangents, unused here
        jw = np.empty((2, 3))  # J W, W = view_rot R(q) S: the 2D covariance is (J W)(J W)^T + dilation I
        vals = np.empty(16)
        grads = np.empty((16, 3))  # the SH basis's gradients, unused here
        for i in range(s * step, min(n, (s + 1) * step)):
            for a in range(3):
                t[a] = view_trans[a] + view_rot[a, 0] * means[i, 0] + view_rot[a, 1] * means[i, 1] \
                    + view_rot[a, 2] * means[i, 2]
            in_front = t[2] > near_plane
            zs = t[2] if in_front else 1.0
            for ax in range(2):  # x/z, y/z clamped to the frustum limits before building J
                tc[ax] = zs * min(max(t[ax] / zs, -limits[2 * ax]), limits[2 * ax + 1])
            _rotation_and_tangents(np.float64(quats[i, 0]), np.float64(quats[i, 1]), np.float64(quats[i, 2]),
                                   np.float64(quats[i, 3]), rmat, d_rmat)
            for k in range(3):
                scale = math.exp(np.float64(log_scales[i, k]))
                w0 = scale * (view_rot[0, 0] * rmat[0, k] + view_rot[0, 1] * rmat[1, k] + view_rot[0, 2] * rmat[2, k])
                w1 = scale * (view_rot[1, 0] * rmat[0, k] + view_rot[1, 1] * rmat[1, k] + view_rot[1, 2] * rmat[2, k])
                w2 = scale * (view_rot[2, 0] * rmat[0, k] + view_rot[2, 1] * rmat[1, k] + view_rot[2, 2] * rmat[2, k])
                jw[0, k] = fx / zs * w0 - fx * tc[0] / (zs * zs) * w2
                jw[1, k] = fy / zs * w1 - fy * tc[1] / (zs * zs) * w2
            cov_a = jw[0, 0] * jw[0, 0] + jw[0, 1] * jw[0, 1] + jw[0, 2] * jw[0, 2] + dilation
            cov_b = jw[0, 0] * jw[1, 0] + jw[0, 1] * jw[1, 1] + jw[0, 2] * jw[1, 2]
            cov_c = jw[1, 0] * jw[1, 0] + jw[1, 1] * jw[1, 1] + jw[1, 2] * jw[1, 2] + dilation
            det = cov_a * cov_c - cov_b * cov_b
            finite_t = math.isfinite(t[0]) and math.isfinite(t[1]) and math.isfinite(t[2])
            q_norm2 = quats[i, 0] ** 2 + quats[i, 1] ** 2 + quats[i, 2] ** 2 + quats[i, 3] ** 2  # 0: the model's
            valid = in_front and det > 0 and math.isfinite(det) and finite_t and q_norm2 > 0  # unit_quats are NaN
            det_safe = det if valid else 1.0
            conics[i, 0], conics[i, 1], conics[i, 2] = cov_c / det_safe, -cov_b / det_safe, cov_a / det_safe
            u, v = fx * t[0] / zs + cx, fy * t[1] / zs + cy
            means2d[i, 0], means2d[i, 1] = u, v
            depths[i] = t[2]
            mid = 0.5 * (cov_a + cov_c)
            lam_max = mid + math.sqrt(max(mid * mid - det_safe, 0.0))  # largest eigenvalue of the 2D covariance
            r = min(np.ceil(SIGMA_EXTENT * math.sqrt(lam_max)), MAX_RADIUS) if lam_max >= 0.0 else 0.0  # NaN: 0
            on_screen = u + r > 0 and u - r < width and v + r > 0 and v - r < height
            radii[i] = int(r) if valid and on_screen else 0
            for ch in range(3):
                colors[i, ch] = 0.0
            if radii[i] == 0:
                continue
            ux, uy, uz = means[i, 0] - center[0], means[i, 1] - center[1], means[i, 2] - center[2]
            dist = max(math.sqrt(ux * ux + uy * uy + uz * uz), 1e-12)
            _sh_basis(ux / dist, uy / dist, uz / dist, degree, vals, grads)
            for ch in range(3):
                acc = vals[0] * sh_dc[i, 0, ch]
                for k in range(1, (degree + 1) * (degree + 1)):
                    acc += vals[k] * sh_rest[i, k - 1, ch]
                colors[i, ch] = max(acc + 0.5, 0.0)
