"""Standard 3DGS PLY files: x y z nx ny nz f_dc_* f_rest_* opacity scale_* rot_* (raw, pre-activation values)."""
from __future__ import annotations

import os

import numpy as np
import torch
from plyfile import PlyData, PlyElement

from utils.errors import UserError
from utils.io import atomic_write

MAX_PLY_SH_DEGREE = 3  # f_rest counts 0, 9, 24, 45


def ply_attribute_names(num_rest: int) -> list[str]:
    """Property names in the order the original 3DGS writes them; `num_rest` = 3 (K - 1)."""
    return (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
            + [f"f_rest_{i}" for i in range(num_rest)] + ["opacity"]
            + [f"scale_{i}" for i in range(3)] + [f"rot_{i}" for i in range(4)])


def save_ply(path: str | os.PathLike, params: dict[str, torch.Tensor]) -> None:
    """Write raw parameters as binary float32, atomically (`utils.io.atomic_write`: a full disk is one `UserError`
    line and leaves an old file unchanged); normals are zero, opacity is a logit and scales are logs.

    f_rest is stored channel-major ([N, 3, K-1] flattened) as 3DGS does, so common splat viewers read the file.
    Args:
        params: means [N,3], sh_dc [N,1,3], sh_rest [N,K-1,3], logit_opacities [N], log_scales [N,3], quats [N,4].
    """
    n = params["means"].shape[0]
    rest = params["sh_rest"].transpose(1, 2).reshape(n, -1)
    columns = torch.cat([params["means"], torch.zeros(n, 3, device=params["means"].device),
                         params["sh_dc"].reshape(n, 3), rest, params["logit_opacities"][:, None],
                         params["log_scales"], params["quats"]], dim=1).cpu().float().numpy()
    names = ply_attribute_names(rest.shape[1])
    data = np.empty(n, dtype=[(name, "f4") for name in names])
    for i, name in enumerate(names):
        data[name] = columns[:, i]
    ply = PlyData([PlyElement.describe(data, "vertex")])
    atomic_write(path, ply.write)  # a temporary file renamed into place: never a truncated PLY


def load_ply(path: str | os.PathLike) -> tuple[dict[str, torch.Tensor], int]:
    """Read raw parameters and the SH degree (0..3, from the f_rest count) of a standard 3DGS PLY.

    Normals are optional (some exporters drop them). A missing, corrupt, truncated or foreign file is a one-line
    `UserError` naming the file and, for a foreign file, the first missing property.
    Returns:
        {means [N,3], sh_dc [N,1,3], sh_rest [N,K-1,3], logit_opacities [N], log_scales [N,3], quats [N,4]}
        as float32 CPU tensors (views of one table), and the SH degree.
    """
    if not os.path.isfile(path):
        raise UserError(f"PLY file {path} does not exist; check the path (point clouds are under "
                        "point_cloud/iteration_N/point_cloud.ply)")
    try:
        ply = PlyData.read(str(path))
        if "vertex" not in [el.name for el in ply.elements]:
            raise UserError(f"{path} has no 'vertex' element, so it is not a 3DGS point cloud; "
                            "point to a PLY written by train.py")
        vertex = ply["vertex"]
        names = [p.name for p in vertex.properties]
        num_rest = sum(1 for nm in names if nm.startswith("f_rest_"))
        missing = [nm for nm in ply_attribute_names(num_rest) if nm not in names and nm not in ("nx", "ny", "nz")]
        if missing:
            raise UserError(f"{path} lacks the 3DGS properties {', '.join(missing)}, so it is not a 3DGS point "
                            "cloud; point to a PLY written by train.py or another 3DGS trainer")
        degree = next((d for d in range(MAX_PLY_SH_DEGREE + 1) if 3 * ((d + 1) ** 2 - 1) == num_rest), None)
        if degree is None:
            raise UserError(f"{path} has {num_rest} f_rest properties, which matches no SH degree 0..3 "
                            "(0, 9, 24 or 45 expected); point to a PLY written by train.py")
        # one float32 table in parameter order, f_rest reordered from channel-major on disk ([N, 3, K-1] flattened)
        # to [N, K-1, 3]: one copy of the file's columns (a 3M-Gaussian degree-3 PLY: 2 s on a shared 2-core machine)
        rest = [f"f_rest_{c * (num_rest // 3) + j}" for j in range(num_rest // 3) for c in range(3)]
        order = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", *rest, "opacity", *(f"scale_{i}" for i in range(3)),
                 *(f"rot_{i}" for i in range(4))]
        table = torch.from_numpy(np.stack([np.asarray(vertex[k], dtype=np.float32) for k in order], axis=1))
    except UserError:
        raise
    except Exception as exc:  # plyfile raises many types for a damaged header or body
        raise UserError(f"cannot read PLY {path} ({type(exc).__name__}: {exc}); the file is corrupt or truncated, "
                        "retrain or restore it") from None
    n, r = table.shape[0], 6 + num_rest
    params = {  # column views of the table (`GaussianModel.set_params` copies them)
        "means": table[:, 0:3],
        "sh_dc": table[:, 3:6].reshape(n, 1, 3),
        "sh_rest": table[:, 6:r].reshape(n, num_rest // 3, 3),
        "logit_opacities": table[:, r],
        "log_scales": table[:, r + 1:r + 4],
        "quats": table[:, r + 4:r + 8],
    }
    return params, degree


def load_points_ply(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """A point cloud PLY (SfM points: x y z and optional red green blue, as COLMAP and nerfstudio write them).

    Points without colours are grey. An unreadable file, or one without x/y/z, is a one-line `UserError`.
    Returns:
        (xyz [P, 3] float64, rgb [P, 3] uint8)
    """
    try:
        ply = PlyData.read(str(path))
        vertex = ply["vertex"]
        names = {p.name for p in vertex.properties}
        if not {"x", "y", "z"} <= names:
            raise UserError(f"points file {path} has no x/y/z vertex properties; point to a point cloud PLY")
        xyz = np.stack([np.asarray(vertex[k], dtype=np.float64) for k in ("x", "y", "z")], axis=1)
        if {"red", "green", "blue"} <= names:
            rgb = np.stack([np.asarray(vertex[k]) for k in ("red", "green", "blue")], axis=1).astype(np.uint8)
        else:
            rgb = np.full((len(xyz), 3), 128, dtype=np.uint8)
    except UserError:
        raise
    except Exception as exc:  # plyfile raises many types for a damaged header or body
        raise UserError(f"cannot read points file {path} ({type(exc).__name__}: {exc}); the file is corrupt or "
                        "truncated, regenerate it") from None
    if not len(xyz) or not np.isfinite(xyz).all():
        raise UserError(f"points file {path} has no points or non-finite coordinates; regenerate it")
    return xyz, rgb
