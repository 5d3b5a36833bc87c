"""A small reader for COLMAP sparse models (cameras, images, points3D), binary and text, and a text writer."""
from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Callable

import numpy as np

from scene.lens import Lens
from utils.errors import UserError

# model id -> (name, number of parameters)
CAMERA_MODELS = {0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5),
                 4: ("OPENCV", 8), 5: ("OPENCV_FISHEYE", 8), 6: ("FULL_OPENCV", 12), 7: ("FOV", 5),
                 8: ("SIMPLE_RADIAL_FISHEYE", 4), 9: ("RADIAL_FISHEYE", 5), 10: ("THIN_PRISM_FISHEYE", 12)}
MODEL_IDS = {name: (mid, n) for mid, (name, n) in CAMERA_MODELS.items()}


@dataclass
class ColmapCamera:
    id: int
    model: str
    width: int
    height: int
    params: np.ndarray


@dataclass
class ColmapImage:
    id: int
    qvec: np.ndarray  # world-to-camera rotation, wxyz
    tvec: np.ndarray  # world-to-camera translation
    camera_id: int
    name: str


def _read(fh, fmt: str):
    size = struct.calcsize("<" + fmt)
    data = fh.read(size)
    if len(data) != size:
        raise EOFError
    return struct.unpack("<" + fmt, data)


def _skip(fh, size: int) -> None:
    """Skip `size` bytes, raising EOFError when the file ends first."""
    if len(fh.read(size)) != size:
        raise EOFError


def _read_records(path: Path, read_one: Callable[[BinaryIO], tuple[int, Any]]) -> dict[int, Any]:
    """A COLMAP binary file: a u64 count, then `count` records, each read by `read_one(fh) -> (id, record)`."""
    with open(path, "rb") as fh:
        (count,) = _read(fh, "Q")
        return dict(read_one(fh) for _ in range(count))


def _camera_record(fh: BinaryIO) -> tuple[int, ColmapCamera]:
    cid, model_id, width, height = _read(fh, "iiQQ")
    name, n = CAMERA_MODELS[model_id]
    return cid, ColmapCamera(cid, name, width, height, np.array(_read(fh, "d" * n)))


def _image_record(fh: BinaryIO) -> tuple[int, ColmapImage]:
    iid, *rest = _read(fh, "idddddddi")
    name = b""
    while (ch := fh.read(1)) != b"\x00":
        if not ch:
            raise EOFError
        name += ch
    (num_points,) = _read(fh, "Q")
    _skip(fh, 24 * num_points)  # (x, y, point3D_id) per 2D point: not needed
    return iid, ColmapImage(iid, np.array(rest[:4]), np.array(rest[4:7]), rest[7], name.decode())


def read_cameras_binary(path: Path) -> dict[int, ColmapCamera]:
    """`cameras.bin`: count, then per camera (id i32, model i32, width u64, height u64, params f64 x n)."""
    return _read_records(path, _camera_record)


def read_images_binary(path: Path) -> dict[int, ColmapImage]:
    """`images.bin`: count, then per image (id, qvec wxyz, tvec, camera id, NUL-ended name, 2D points)."""
    return _read_records(path, _image_record)


def read_points_binary(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """`points3D.bin` -> (xyz [P,3] float64, rgb [P,3] uint8); errors and tracks are skipped."""
    xyz, rgb = [], []
    with open(path, "rb") as fh:
        (count,) = _read(fh, "Q")
        for _ in range(count):
            vals = _read(fh, "QdddBBBd")
            xyz.append(vals[1:4])
            rgb.append(vals[4:7])
            (track_len,) = _read(fh, "Q")
            _skip(fh, 8 * track_len)
    return np.array(xyz, dtype=np.float64).reshape(-1, 3), np.array(rgb, dtype=np.uint8).reshape(-1, 3)


def _text_lines(path: Path):
    for line in path.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            yield line


def read_cameras_text(path: Path) -> dict[int, ColmapCamera]:
    """`cameras.txt`: CAMERA_ID MODEL WIDTH HEIGHT PARAMS[] per line."""
    cams = {}
    for line in _text_lines(path):
        parts = line.split()
        cid, model, width, height = int(parts[0]), parts[1], int(parts[2]), int(parts[3])
        cams[cid] = ColmapCamera(cid, model, width, height, np.array([float(p) for p in parts[4:]]))
    return cams


def read_images_text(path: Path) -> dict[int, ColmapImage]:
    """`images.txt`: per image a header line (IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME) then a 2D-points line.

    The points line may be empty, so records are read in pairs of non-comment lines; blank lines where a header
    is expected are skipped.
    """
    images = {}
    lines = [line.strip() for line in path.read_text().splitlines() if not line.lstrip().startswith("#")]
    i = 0
    while i < len(lines):
        if not lines[i]:
            i += 1
            continue
        parts = lines[i].split(maxsplit=9)
        if len(parts) != 10:
            raise ValueError(f"images.txt header line has {len(parts)} fields, expected 10")
        iid = int(parts[0])
        images[iid] = ColmapImage(iid, np.array([float(p) for p in parts[1:5]]),
                                  np.array([float(p) for p in parts[5:8]]), int(parts[8]), parts[9])
        i += 2  # skip the 2D points line
    return images


def read_points_text(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """`points3D.txt`: POINT3D_ID X Y Z R G B ERROR TRACK[] per line -> (xyz [P,3], rgb [P,3] uint8)."""
    xyz, rgb = [], []
    for line in _text_lines(path):
        parts = line.split()
        xyz.append([float(p) for p in parts[1:4]])
        rgb.append([int(p) for p in parts[4:7]])
    return np.array(xyz, dtype=np.float64).reshape(-1, 3), np.array(rgb, dtype=np.uint8).reshape(-1, 3)


def read_model(sparse_dir: Path):
    """(cameras, images, (xyz [P,3], rgb [P,3] uint8)) from `sparse_dir`, binary preferred over text."""
    try:
        if (sparse_dir / "cameras.bin").is_file():
            return (read_cameras_binary(sparse_dir / "cameras.bin"), read_images_binary(sparse_dir / "images.bin"),
                    read_points_binary(sparse_dir / "points3D.bin"))
        return (read_cameras_text(sparse_dir / "cameras.txt"), read_images_text(sparse_dir / "images.txt"),
                read_points_text(sparse_dir / "points3D.txt"))
    except FileNotFoundError as exc:
        raise UserError(f"COLMAP model in {sparse_dir} is incomplete: {Path(exc.filename).name} is missing") from None
    except (EOFError, struct.error, KeyError, ValueError, IndexError):
        raise UserError(f"COLMAP model in {sparse_dir} is corrupt or truncated; re-export it from COLMAP") from None


def read_point_tracks(sparse_dir: Path) -> list[np.ndarray]:
    """The ids of the images that observe each 3D point of `sparse_dir` ([T_p] int64 each), in read_model's point
    order (binary preferred over text)."""
    tracks = []
    if (sparse_dir / "points3D.bin").is_file():
        with open(sparse_dir / "points3D.bin", "rb") as fh:
            (count,) = _read(fh, "Q")
            for _ in range(count):
                _read(fh, "QdddBBBd")
                (track_len,) = _read(fh, "Q")
                pairs = np.frombuffer(fh.read(8 * track_len), dtype="<i4")  # (image id, point2D index) pairs
                if len(pairs) != 2 * track_len:
                    raise UserError(f"COLMAP model in {sparse_dir} is corrupt or truncated; re-export it from COLMAP")
                tracks.append(pairs[0::2].astype(np.int64))
        return tracks
    for line in _text_lines(sparse_dir / "points3D.txt"):
        tracks.append(np.array([int(v) for v in line.split()[8::2]], dtype=np.int64))
    return tracks


def write_model_text(sparse_dir: Path, cameras: dict[int, ColmapCamera], images: dict[int, ColmapImage],
                     xyz: np.ndarray, rgb: np.ndarray) -> None:
    """`sparse_dir`/{cameras,images,points3D}.txt: the model without 2D points or tracks (what the readers use)."""
    sparse_dir.mkdir(parents=True, exist_ok=True)
    (sparse_dir / "cameras.txt").write_text("".join(
        f"{c.id} {c.model} {c.width} {c.height} " + " ".join(repr(float(v)) for v in c.params) + "\n"
        for c in cameras.values()))
    (sparse_dir / "images.txt").write_text("".join(
        f"{im.id} " + " ".join(repr(float(v)) for v in (*im.qvec, *im.tvec)) + f" {im.camera_id} {im.name}\n\n"
        for im in images.values()))
    (sparse_dir / "points3D.txt").write_text("".join(
        f"{i + 1} {p[0]!r} {p[1]!r} {p[2]!r} {c[0]} {c[1]} {c[2]} 0\n"
        for i, (p, c) in enumerate(zip(xyz.tolist(), rgb.tolist()))))


def qvec_to_rotmat(q: np.ndarray) -> np.ndarray:
    """Rotation matrix [3,3] of a wxyz quaternion [4] (normalised here)."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def camera_lens(cam: ColmapCamera) -> Lens:
    """The `Lens` of a COLMAP camera (calibrated pixels): pinhole models without, radial/OpenCV ones with
    distortion coefficients in OpenCV's order."""
    p = [float(v) for v in cam.params]
    expected = MODEL_IDS.get(cam.model, (None, len(p)))[1]
    if len(p) != expected:
        raise UserError(f"COLMAP camera {cam.id} ({cam.model}) has {len(p)} parameters, expected {expected}; "
                        "re-export the model from COLMAP")
    w, h = cam.width, cam.height
    if cam.model == "SIMPLE_PINHOLE":
        return Lens(w, h, p[0], p[0], p[1], p[2])
    if cam.model == "SIMPLE_RADIAL":
        return Lens(w, h, p[0], p[0], p[1], p[2], "OPENCV", (p[3], 0.0, 0.0, 0.0))
    if cam.model == "RADIAL":
        return Lens(w, h, p[0], p[0], p[1], p[2], "OPENCV", (p[3], p[4], 0.0, 0.0))
    if cam.model == "PINHOLE":
        return Lens(w, h, *p)
    if cam.model in ("OPENCV", "FULL_OPENCV"):  # (k1, k2, p1, p2[, k3, k4, k5, k6]): OpenCV's own order
        return Lens(w, h, *p[:4], "OPENCV", tuple(p[4:]))
    if cam.model == "OPENCV_FISHEYE":
        return Lens(w, h, *p[:4], "OPENCV_FISHEYE", tuple(p[4:]))
    raise UserError(f"COLMAP camera {cam.id} uses model {cam.model}; supported: SIMPLE_PINHOLE, PINHOLE, "
                    "SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV, OPENCV_FISHEYE (undistort the images with COLMAP "
                    "first)")
