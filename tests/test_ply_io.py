"""Standard 3DGS PLY: bit-exact round trips, property order, clear errors for foreign files."""
import pytest
import torch
from plyfile import PlyData

from scene.gaussian_model import GaussianModel
from scene.ply_io import ply_attribute_names
from utils.errors import UserError


@pytest.mark.parametrize("degree", [0, 1, 3])
def test_roundtrip_bit_exact(tmp_path, degree):
    g = torch.Generator().manual_seed(degree)
    model = GaussianModel.from_point_cloud(torch.rand(50, 3, generator=g), torch.rand(50, 3, generator=g), degree)
    for p in model.params.values():
        p.data.add_(torch.randn(p.shape, generator=g) * 0.1)
    path = tmp_path / "pc.ply"
    model.save_ply(path)
    loaded = GaussianModel.load_ply(path)
    assert loaded.max_sh_degree == degree
    for name, value in model.params.items():
        assert torch.equal(loaded.params[name], value.detach()), name
    names = [p.name for p in PlyData.read(str(path))["vertex"].properties]
    assert names == ply_attribute_names(3 * ((degree + 1) ** 2 - 1))


def test_corrupt_and_foreign_files(tmp_path):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 10\n")
    with pytest.raises(UserError, match="cannot read PLY"):
        GaussianModel.load_ply(bad)
    foreign = tmp_path / "foreign.ply"
    foreign.write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1.0\n")
    with pytest.raises(UserError, match="not a 3DGS point cloud"):
        GaussianModel.load_ply(foreign)
