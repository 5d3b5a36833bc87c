"""Standard 3DGS PLY: bit-exact round trips, property order and layout, clear errors for foreign files."""
import numpy as np
import pytest
import torch
from plyfile import PlyData, PlyElement

from scene.gaussian_model import GaussianModel
from scene.ply_io import load_ply, ply_attribute_names, save_ply
from utils.errors import UserError


def _model(degree: int, n: int = 50) -> GaussianModel:
    g = torch.Generator().manual_seed(degree)
    model = GaussianModel.from_point_cloud(torch.rand(n, 3, generator=g), torch.rand(n, 3, generator=g), degree)
    for p in model.params.values():
        p.data.add_(torch.randn(p.shape, generator=g) * 0.1)
    return model


@pytest.mark.parametrize("degree", [0, 1, 3])
def test_roundtrip_bit_exact(tmp_path, degree):
    model = _model(degree)
    path = tmp_path / "pc.ply"
    model.save_ply(path)
    loaded = GaussianModel.load_ply(path)
    assert loaded.max_sh_degree == degree and loaded.active_sh_degree == degree
    for name, value in model.params.items():
        assert torch.equal(loaded.params[name], value.detach()), name
    names = [p.name for p in PlyData.read(str(path))["vertex"].properties]
    assert names == ply_attribute_names(3 * ((degree + 1) ** 2 - 1))
    assert names[:9] == ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    assert names[-8:] == ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]


def test_file_layout_matches_3dgs(tmp_path):
    """Raw values on disk: f_rest channel-major, opacity as logit, scales as logs, quats wxyz."""
    model = _model(2, n=4)
    path = tmp_path / "pc.ply"
    model.save_ply(path)
    v = PlyData.read(str(path))["vertex"]
    p = model.params
    rest = p["sh_rest"].detach()  # [N, 8, 3]
    for c in range(3):
        for j in range(8):
            # 3DGS: f_rest_{c*(K-1)+j} is coefficient j+1 of colour channel c
            assert np.array_equal(v[f"f_rest_{c * 8 + j}"], rest[:, j, c].numpy())
    assert np.array_equal(v["opacity"], p["logit_opacities"].detach().numpy())
    assert np.array_equal(v["scale_1"], p["log_scales"].detach()[:, 1].numpy())
    assert np.array_equal(v["rot_0"], p["quats"].detach()[:, 0].numpy())  # w first
    assert np.array_equal(v["nx"], np.zeros(4, np.float32))


def test_normals_optional(tmp_path):
    params = {k: v.detach() for k, v in _model(0, n=3).params.items()}
    names = [n for n in ply_attribute_names(0) if n not in ("nx", "ny", "nz")]
    data = np.zeros(3, dtype=[(n, "f4") for n in names])
    data["x"] = params["means"][:, 0].numpy()
    path = tmp_path / "no_normals.ply"
    PlyData([PlyElement.describe(data, "vertex")]).write(str(path))
    loaded, degree = load_ply(path)
    assert degree == 0 and torch.equal(loaded["means"][:, 0], params["means"][:, 0])


def test_corrupt_and_foreign_files(tmp_path):
    with pytest.raises(UserError, match="does not exist"):
        GaussianModel.load_ply(tmp_path / "missing.ply")
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 10\n")
    with pytest.raises(UserError, match="cannot read PLY .*bad.ply"):
        GaussianModel.load_ply(bad)
    good = tmp_path / "good.ply"
    _model(1).save_ply(good)
    truncated = tmp_path / "truncated.ply"
    truncated.write_bytes(good.read_bytes()[:-100])
    with pytest.raises(UserError, match="cannot read PLY .*truncated.ply"):
        GaussianModel.load_ply(truncated)
    foreign = tmp_path / "foreign.ply"
    foreign.write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1.0\n")
    with pytest.raises(UserError, match="foreign.ply lacks the 3DGS properties y, z, f_dc_0, "):
        GaussianModel.load_ply(foreign)
    faces = tmp_path / "faces.ply"
    faces.write_text("ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n")
    with pytest.raises(UserError, match="no 'vertex' element"):
        GaussianModel.load_ply(faces)


def test_unsupported_rest_count(tmp_path):
    params = {k: v.detach() for k, v in _model(1, n=3).params.items()}
    params["sh_rest"] = params["sh_rest"][:, :2]  # 6 f_rest values: no SH degree has that
    path = tmp_path / "odd.ply"
    save_ply(path, params)
    with pytest.raises(UserError, match="6 f_rest properties"):
        load_ply(path)
