"""Standard 3DGS PLY files: x y z nx ny nz f_dc_* f_rest_* opacity scale_* rot_* (raw, pre-activation values)."""
from __future__ import annotations

import math
import os

import numpy as np
import torch
from plyfile import PlyData, PlyElement

from utils.errors import UserError


def ply_attribute_names(num_rest: int) -> list[str]:
    """Property names in the order the original 3DGS writes them; `num_rest` = 3 (K - 1)."""
    return (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
            + [f"f_rest_{i}" for i in range(num_rest)] + ["opacity"]
            + [f"scale_{i}" for i in range(3)] + [f"rot_{i}" for i in range(4)])


def save_ply(path: str | os.PathLike, params: dict[str, torch.Tensor]) -> None:
    """Write raw parameters; f_rest is stored channel-major ([N, 3, K-1] flattened) as 3DGS does."""
    n = params["means"].shape[0]
    rest = params["sh_rest"].transpose(1, 2).reshape(n, -1)
    columns = torch.cat([params["means"], torch.zeros(n, 3, device=params["means"].device),
                         params["sh_dc"].reshape(n, 3), rest, params["logit_opacities"][:, None],
                         params["log_scales"], params["quats"]], dim=1).cpu().float().numpy()
    names = ply_attribute_names(rest.shape[1])
    data = np.empty(n, dtype=[(name, "f4") for name in names])
    for i, name in enumerate(names):
        data[name] = columns[:, i]
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    PlyData([PlyElement.describe(data, "vertex")]).write(str(path))


def load_ply(path: str | os.PathLike) -> tuple[dict[str, torch.Tensor], int]:
    """Read raw parameters and the SH degree; a foreign or corrupt file is a one-line `UserError`."""
    try:
        vertex = PlyData.read(str(path))["vertex"]
        names = [p.name for p in vertex.properties]
        num_rest = sum(1 for nm in names if nm.startswith("f_rest_"))
        degree = int(round(math.sqrt(num_rest / 3 + 1))) - 1
        missing = [nm for nm in ply_attribute_names(num_rest) if nm not in names and nm not in ("nx", "ny", "nz")]
        if missing or (degree + 1) ** 2 * 3 != num_rest + 3:
            raise UserError(f"{path} is not a 3DGS point cloud (missing properties {missing[:4]}, "
                            f"{num_rest} f_rest values); point to a PLY written by train.py")
        cols = lambda keys: torch.from_numpy(np.stack([np.asarray(vertex[k], dtype=np.float32) for k in keys], 1))
    except UserError:
        raise
    except Exception as exc:
        raise UserError(f"cannot read PLY {path} ({type(exc).__name__}: {exc}); the file is corrupt or truncated, "
                        "retrain or restore it") from None
    n = len(vertex.data)
    rest = (cols([f"f_rest_{i}" for i in range(num_rest)]).reshape(n, 3, -1).transpose(1, 2) if num_rest
            else torch.zeros(n, 0, 3))
    params = {
        "means": cols(["x", "y", "z"]),
        "sh_dc": cols(["f_dc_0", "f_dc_1", "f_dc_2"])[:, None, :],
        "sh_rest": rest.contiguous(),
        "logit_opacities": cols(["opacity"])[:, 0],
        "log_scales": cols([f"scale_{i}" for i in range(3)]),
        "quats": cols([f"rot_{i}" for i in range(4)]),
    }
    return params, degree
