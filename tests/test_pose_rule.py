"""One pose rule (scene.pose_check): train.py's reader (load_scene_info) and recommend.py's reader (read_pose_file)
accept and refuse the same transforms.json files, with the same one-line error naming file and frame, and both
re-orthonormalise a rotation that is orthonormal to ~1e-4 with one log line."""
from __future__ import annotations

import logging
import math

import pytest
import torch

from scene.dataset_readers import load_scene_info
from scene.pose_check import checked_c2w
from scene.pose_files import read_pose_file
from tests.test_dataset_readers import C2W_A, C2W_B
from tests.test_transforms_json import write_ns
from utils.errors import UserError

pytestmark = pytest.mark.auto_backend


def _rot_z(c2w, angle):
    m = torch.tensor(c2w, dtype=torch.float64)
    c, s = math.cos(angle), math.sin(angle)
    m[:3, :3] = m[:3, :3] @ torch.tensor([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=torch.float64)
    return m.tolist()


def _scaled(c2w, factor):
    m = torch.tensor(c2w, dtype=torch.float64)
    m[:3, :3] *= factor
    return m.tolist()


def _reflected(c2w):
    m = torch.tensor(c2w, dtype=torch.float64)
    m[:3, 0] *= -1
    return m.tolist()


BAD = {"scaled by 1.1": _scaled(C2W_A, 1.1), "a reflection": _reflected(C2W_A),
       "singular": _scaled(C2W_A, 0.0)}


def _train_reader(root):
    return load_scene_info(str(root)).train_cameras


def _recommend_reader(root):
    return read_pose_file(root / "transforms.json")


@pytest.mark.parametrize("bad", sorted(BAD))
def test_both_readers_refuse_a_non_rotation_with_the_same_error(tmp_path, bad):
    root = write_ns(tmp_path, poses=(C2W_A, C2W_B, BAD[bad]))
    messages = []
    for reader in (_train_reader, _recommend_reader):
        with pytest.raises(UserError) as info:
            reader(root)
        messages.append(str(info.value))
    assert messages[0] == messages[1]
    # the file lists frames backwards: the bad pose is frame 0
    assert f"{root / 'transforms.json'} frame 0: the rotation part of the pose is not a rotation" in messages[0]
    assert "\n" not in messages[0]


def test_both_readers_accept_and_reorthonormalise_a_nearly_orthonormal_rotation(tmp_path, caplog):
    off = torch.tensor(_rot_z(C2W_B, 0.3), dtype=torch.float64)
    off[:3, :3] += 5e-5 * torch.tensor([[1.0, -2.0, 0.5], [0.3, 1.0, -1.0], [2.0, 0.0, 1.0]], dtype=torch.float64)
    root = write_ns(tmp_path, poses=(C2W_A, C2W_B, off.tolist()))
    exact = checked_c2w(_rot_z(C2W_B, 0.3), "exact")
    for reader in (_train_reader, _recommend_reader):
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="scene.pose_check"):
            cameras = reader(root)
        notes = [r.getMessage() for r in caplog.records if r.name == "scene.pose_check"]
        assert len(notes) == 1 and "frame 0" in notes[0] and "re-orthonormalised" in notes[0]
        assert len(cameras) == 3
    fixed = checked_c2w(off, "off")[:3, :3]
    assert torch.allclose(fixed.T @ fixed, torch.eye(3, dtype=torch.float64), atol=1e-12)
    assert torch.allclose(fixed, exact[:3, :3], atol=1e-3)


def test_exact_rotations_are_kept_bit_for_bit():
    m = torch.tensor(C2W_A, dtype=torch.float64)
    m[:3, :3] += 1e-7  # exported float error (lego's files: 1.3e-6) is below the re-orthonormalisation threshold
    assert torch.equal(checked_c2w(m, "f")[:3], m[:3])
