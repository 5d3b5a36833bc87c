"""The one rule for a camera-to-world pose read from any file (transforms*.json, cameras.json, camera_path.json,
COLMAP): numeric, finite, and its rotation part a rotation.

A rotation orthonormal to within `ORTHONORMAL_TOL` is accepted; when it is off by more than `EXACT_TOL` (files
exported in float32 or with rounded digits) it is re-orthonormalised to the nearest rotation (polar decomposition),
with one log line naming file and frame. Anything else (|RᵀR - I| above `ORTHONORMAL_TOL`, or a reflection) is a
`UserError` with one line naming file and frame. train.py's readers and recommend.py's reader both call
`checked_c2w`, so they accept and refuse the same files.
"""
from __future__ import annotations

import logging

import torch

from utils.errors import UserError

log = logging.getLogger(__name__)

ORTHONORMAL_TOL = 1e-3  # max |R^T R - I| accepted as a rotation (re-orthonormalised)
EXACT_TOL = 1e-5        # max |R^T R - I| kept as it is (float error of exported files: lego 1.3e-6)


def checked_c2w(matrix, where: str) -> torch.Tensor:
    """A camera-to-world matrix (3x4 or 4x4 nested list or tensor) as float64 [4, 4] with bottom row (0, 0, 0, 1),
    after the checks; `where` names the file and the frame ("path/transforms.json frame 3")."""
    try:
        m = torch.as_tensor(matrix, dtype=torch.float64)
    except (TypeError, ValueError, RuntimeError):
        raise UserError(f"{where}: the pose is not a matrix of numbers") from None
    if m.shape not in ((4, 4), (3, 4)):
        raise UserError(f"{where}: the pose must be a 4x4 or 3x4 matrix, got shape {tuple(m.shape)}")
    if not torch.isfinite(m).all():
        row, col = (int(i) for i in torch.nonzero(~torch.isfinite(m))[0])
        raise UserError(f"{where}: the pose holds a non-finite value ({float(m[row, col])}) at row {row}, column "
                        f"{col}; fix the pose")
    rot = m[:3, :3]
    error = float((rot.T @ rot - torch.eye(3, dtype=torch.float64)).abs().max())
    det = float(torch.linalg.det(rot))
    if error > ORTHONORMAL_TOL or det < 0:
        raise UserError(f"{where}: the rotation part of the pose is not a rotation (|R^T R - I| = {error:.3g}, "
                        f"det {det:.3g}); fix the pose")
    c2w = torch.eye(4, dtype=torch.float64)
    c2w[:3, :] = m[:3, :]
    if error > EXACT_TOL:
        u, _, vh = torch.linalg.svd(rot)
        c2w[:3, :3] = u @ vh
        log.info("%s: rotation orthonormal to %.2g only, re-orthonormalised", where, error)
    return c2w
