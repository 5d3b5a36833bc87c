"""Real spherical harmonics up to degree 3, with the constants and sign conventions of the original 3DGS.

Basis k = l^2 + l + m (m = -l..l) is the real SH Y_lm with the Condon-Shortley phase, written as polynomials in the
unit direction (x, y, z); e.g. Y_1,-1 = -C1 y, Y_1,0 = C1 z, Y_1,1 = -C1 x. Colour = max(SH(dir) + 0.5, 0).
"""
from __future__ import annotations

import torch

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
      1.445305721320277, -0.5900435899266435)


def num_sh_bases(degree: int) -> int:
    """K = (degree + 1)^2."""
    return (degree + 1) ** 2


def eval_sh(sh_coeffs: torch.Tensor, dirs: torch.Tensor, degree: int) -> torch.Tensor:
    """Evaluate SH of `degree` (<= 3) in unit directions.

    Args:
        sh_coeffs: coefficients, at least (degree+1)^2 bases. [N, K, D]
        dirs: view directions, normalised inside. [N, 3]
    Returns:
        the raw SH sum (no +0.5 offset). [N, D]
    """
    assert 0 <= degree <= 3, f"SH degree must be in 0..3, got {degree}"
    assert sh_coeffs.ndim == 3 and sh_coeffs.shape[1] >= num_sh_bases(degree), \
        f"sh_coeffs must be [N,K,D] with K >= {num_sh_bases(degree)}, got {tuple(sh_coeffs.shape)}"
    assert dirs.shape == (sh_coeffs.shape[0], 3), f"dirs must be [N,3], got {tuple(dirs.shape)}"
    result = C0 * sh_coeffs[:, 0]
    if degree == 0:
        return result
    d = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    x, y, z = d[:, 0:1], d[:, 1:2], d[:, 2:3]
    result = result - C1 * y * sh_coeffs[:, 1] + C1 * z * sh_coeffs[:, 2] - C1 * x * sh_coeffs[:, 3]
    if degree == 1:
        return result
    xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
    result = (result + C2[0] * xy * sh_coeffs[:, 4] + C2[1] * yz * sh_coeffs[:, 5]
              + C2[2] * (2 * zz - xx - yy) * sh_coeffs[:, 6] + C2[3] * xz * sh_coeffs[:, 7]
              + C2[4] * (xx - yy) * sh_coeffs[:, 8])
    if degree == 2:
        return result
    return (result + C3[0] * y * (3 * xx - yy) * sh_coeffs[:, 9] + C3[1] * xy * z * sh_coeffs[:, 10]
            + C3[2] * y * (4 * zz - xx - yy) * sh_coeffs[:, 11]
            + C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh_coeffs[:, 12]
            + C3[4] * x * (4 * zz - xx - yy) * sh_coeffs[:, 13] + C3[5] * z * (xx - yy) * sh_coeffs[:, 14]
            + C3[6] * x * (xx - 3 * yy) * sh_coeffs[:, 15])


def sh_to_colors(sh_coeffs: torch.Tensor, means: torch.Tensor, camera_center: torch.Tensor, degree: int) -> torch.Tensor:
    """View-dependent colour max(SH(mean - camera centre) + 0.5, 0).

    Args:
        sh_coeffs: [N, K, D]; means: world-space centres [N, 3]; camera_center: [3].
    Returns:
        colours. [N, D]
    """
    return torch.clamp_min(eval_sh(sh_coeffs, means - camera_center, degree) + 0.5, 0.0)


def rgb_to_sh(rgb: torch.Tensor) -> torch.Tensor:
    """DC coefficient whose degree-0 colour C0 sh + 0.5 equals `rgb`. [..., D] -> [..., D]"""
    return (rgb - 0.5) / C0


def sh_to_rgb(sh_dc: torch.Tensor) -> torch.Tensor:
    """Degree-0 colour C0 sh_dc + 0.5 (before the clamp at 0); inverse of `rgb_to_sh`. [..., D] -> [..., D]"""
    return sh_dc * C0 + 0.5
