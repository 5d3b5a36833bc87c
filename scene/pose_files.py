"""Camera poses without images: a 3DGS `cameras.json`, a `transforms.json`-style file, a nerfstudio
`camera_path.json` or a COLMAP model, read into image-less `Camera`s (OpenCV axes, pinhole).

No image file is opened: a frame's `file_path` is ignored (and may be missing); a transforms file without `w`/`h`
takes the size from `default_size`. Lens distortion is dropped (the cameras are pinholes). Every pose is checked by
`scene.pose_check.checked_c2w`, the rule train.py's readers use too.

    cameras = read_pose_file(Path("cameras.json"))          # format detected from the content
"""
from __future__ import annotations

import math
from pathlib import Path

import torch

from scene import colmap_io
from scene.cameras import Camera
from scene.frames import GL_TO_CV
from scene.pose_check import ORTHONORMAL_TOL, checked_c2w  # noqa: F401  (the one pose rule)
from utils.errors import UserError
from utils.io import read_json

def camera_from_c2w(uid: int, name: str, c2w_cv: torch.Tensor, fx: float, fy: float, cx: float, cy: float,
                    width: int, height: int) -> Camera:
    """An image-less `Camera` from a camera-to-world matrix in OpenCV axes [4, 4]."""
    return Camera(uid, name, torch.linalg.inv(c2w_cv).float(), float(fx), float(fy), float(cx), float(cy),
                  int(width), int(height))


def _number(value, key: str, where: str) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise UserError(f"{where}: '{key}' must be a number, got {value!r}") from None
    if not math.isfinite(out) or out <= 0:
        raise UserError(f"{where}: '{key}' must be a finite positive number, got {value!r}")
    return out


def read_cameras_json(path: Path, data: list) -> list[Camera]:
    """3DGS `cameras.json`: a list of {img_name, width, height, position, rotation (camera-to-world, OpenCV),
    fx, fy}; the principal point is the image centre."""
    cameras = []
    for i, entry in enumerate(data):
        where = f"{path} entry {i}"
        if not isinstance(entry, dict) or not {"position", "rotation", "width", "height", "fx", "fy"} <= set(entry):
            raise UserError(f"{where}: needs position, rotation, width, height, fx and fy (3DGS cameras.json)")
        try:
            m = torch.cat([torch.as_tensor(entry["rotation"], dtype=torch.float64),
                           torch.as_tensor(entry["position"], dtype=torch.float64)[:, None]], dim=1)
        except (TypeError, ValueError, RuntimeError):
            raise UserError(f"{where}: rotation must be 3x3 and position 3 numbers") from None
        w, h = (int(_number(entry[k], k, where)) for k in ("width", "height"))
        cameras.append(camera_from_c2w(i, str(entry.get("img_name", f"camera_{i}")), checked_c2w(m, where),
                                       _number(entry["fx"], "fx", where), _number(entry["fy"], "fy", where),
                                       w / 2, h / 2, w, h))
    return cameras


def read_transforms(path: Path, data: dict, default_size: tuple[int, int] | None) -> list[Camera]:
    """A `transforms.json`-style file (Blender, nerfstudio, instant-ngp): frames with a camera-to-world
    `transform_matrix` (OpenGL axes); intrinsics `fl_x`/`fl_y`/`cx`/`cy` or `camera_angle_x`, size `w`/`h`, each at
    file level or per frame. `file_path` is ignored."""
    cameras = []
    for i, frame in enumerate(data["frames"]):
        where = f"{path} frame {i}"
        if not isinstance(frame, dict) or "transform_matrix" not in frame:
            raise UserError(f"{where}: needs a 'transform_matrix'")

        def get(key):
            value = frame.get(key, data.get(key))
            return None if value is None else _number(value, key, where)

        w, h = get("w"), get("h")
        if w is None or h is None:
            if default_size is None:
                raise UserError(f"{where}: no image size ('w' and 'h'); give one (--size WxH) or captured cameras")
            w, h = default_size
        fl_x = get("fl_x")
        if fl_x is None:
            angle = get("camera_angle_x")
            if angle is None:
                raise UserError(f"{where}: needs 'fl_x' or 'camera_angle_x' (the focal length)")
            fl_x = 0.5 * w / math.tan(0.5 * angle)
        fl_y = get("fl_y") or fl_x
        cx, cy = frame.get("cx", data.get("cx", w / 2)), frame.get("cy", data.get("cy", h / 2))
        c2w = checked_c2w(frame["transform_matrix"], where) @ GL_TO_CV
        name = Path(frame["file_path"]).stem if isinstance(frame.get("file_path"), str) else f"frame_{i}"
        cameras.append(camera_from_c2w(i, name, c2w, fl_x, fl_y, float(cx), float(cy), int(w), int(h)))
    return cameras


def read_camera_path(path: Path, data: dict) -> list[Camera]:
    """A nerfstudio `camera_path.json`: `render_width`, `render_height` and `camera_path` keyframes with a
    row-major 4x4 `camera_to_world` (OpenGL axes) and a vertical `fov` in degrees."""
    where = str(path)
    w, h = (int(_number(data.get(k), k, where)) for k in ("render_width", "render_height"))
    cameras = []
    for i, key in enumerate(data["camera_path"]):
        at = f"{path} camera_path {i}"
        if not isinstance(key, dict) or "camera_to_world" not in key or "fov" not in key:
            raise UserError(f"{at}: needs 'camera_to_world' and 'fov'")
        flat = key["camera_to_world"]
        if not isinstance(flat, list) or len(flat) != 16:
            raise UserError(f"{at}: 'camera_to_world' must be 16 numbers (a row-major 4x4 matrix)")
        fov = _number(key["fov"], "fov", at)
        focal = 0.5 * h / math.tan(math.radians(fov) / 2)
        c2w = checked_c2w([flat[0:4], flat[4:8], flat[8:12], flat[12:16]], at) @ GL_TO_CV
        cameras.append(camera_from_c2w(i, f"path_{i}", c2w, focal, focal, w / 2, h / 2, w, h))
    return cameras


def read_colmap_model(sparse: Path) -> list[Camera]:
    """The registered images of a COLMAP model (`cameras`/`images` .bin or .txt), sorted by name; distortion is
    dropped."""
    cams, imgs, _ = colmap_io.read_model(sparse)
    cameras = []
    for i, im in enumerate(sorted(imgs.values(), key=lambda im: im.name)):
        where = f"COLMAP image {im.name}"
        if im.camera_id not in cams:
            raise UserError(f"{where} refers to camera {im.camera_id}, which is not in the cameras file")
        lens = colmap_io.camera_lens(cams[im.camera_id])
        w2c = torch.eye(4, dtype=torch.float64)
        w2c[:3, :3] = torch.from_numpy(colmap_io.qvec_to_rotmat(im.qvec))
        w2c[:3, 3] = torch.from_numpy(im.tvec)
        c2w = checked_c2w(torch.linalg.inv(w2c), where)
        cameras.append(camera_from_c2w(i, Path(im.name).stem, c2w, lens.fx, lens.fy, lens.cx, lens.cy,
                                       lens.width, lens.height))
    return cameras


def read_pose_file(path: str | Path, default_size: tuple[int, int] | None = None) -> list[Camera]:
    """The cameras of a pose file or COLMAP model folder, format detected from the content.

    Args:
        path: cameras.json (a list), transforms.json-style (has 'frames'), camera_path.json (has 'camera_path'),
            or a folder holding a COLMAP model (cameras.bin|txt, directly or under sparse/0).
        default_size: (width, height) for transforms files that give none.
    Raises:
        UserError: unreadable, unknown format, no cameras, or a bad pose (named).
    """
    path = Path(path)
    if path.is_dir():
        sparse = next((d for d in (path, path / "sparse" / "0", path / "sparse")
                       if (d / "cameras.bin").is_file() or (d / "cameras.txt").is_file()), None)
        if sparse is None:
            raise UserError(f"{path} is a folder without a COLMAP model (cameras.bin|txt, here or under sparse/0)")
        cameras = read_colmap_model(sparse)
    else:
        data = read_json(path, kind=None, what="pose file", fix="fix or regenerate it")
        if isinstance(data, list):
            cameras = read_cameras_json(path, data)
        elif isinstance(data, dict) and isinstance(data.get("frames"), list):
            cameras = read_transforms(path, data, default_size)
        elif isinstance(data, dict) and isinstance(data.get("camera_path"), list):
            cameras = read_camera_path(path, data)
        else:
            raise UserError(f"{path} is neither a 3DGS cameras.json (a list), a transforms.json ('frames') nor a "
                            "nerfstudio camera_path.json ('camera_path')")
    if not cameras:
        raise UserError(f"{path} lists no cameras")
    return cameras


def scaled_camera(camera: Camera, width: int) -> Camera:
    """`camera` with its image `width` px wide: intrinsics scaled by width / camera.width, height rounded."""
    if width == camera.width:
        return camera
    s = width / camera.width
    return Camera(camera.uid, camera.image_name, camera.viewmat, camera.fx * s, camera.fy * s, camera.cx * s,
                  camera.cy * s, int(width), max(1, round(camera.height * s)))


def c2w_opengl(camera: Camera) -> torch.Tensor:
    """The camera-to-world matrix in OpenGL axes (transforms.json's `transform_matrix`). [4, 4] float64"""
    return torch.linalg.inv(camera.viewmat.double().cpu()) @ GL_TO_CV
