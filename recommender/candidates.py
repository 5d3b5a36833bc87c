"""Generated candidate poses: an orbit or a hemisphere of N cameras around the captured views' look-at point.

The frame comes from the captured cameras: centre = the point their optical axes pass closest to
(`look_at_point`), radius = their mean distance to it, "up" = their mean up vector (-y of the OpenCV camera),
snapped to the nearest world axis when within `AXIS_SNAP_DEG` of it (cameras looking down tilt the mean).
Elevations are measured from the plane through the centre perpendicular to up.

* `orbit:N` -- N azimuths evenly spaced; elevation the captured views' mean, or spread evenly over `elevation`
  (lo, hi) degrees (a spiral) when given.
* `hemisphere:N` -- N poses spread evenly over the spherical cap between `elevation` lo and hi (default 0..80
  degrees) by a golden-angle spiral (equal area per pose).

Every pose looks at the centre with the captured up on screen; intrinsics and size are the first captured
camera's unless given.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from gaussian_renderer.projection import camera_centers, look_at_point
from scene.cameras import Camera, look_at
from utils.errors import UserError

HEMISPHERE_ELEVATION = (0.0, 80.0)  # degrees
AXIS_SNAP_DEG = 30.0  # a mean up within this angle of a world axis is snapped to the axis
MAX_ELEVATION = 89.0  # |elevation| above this would make "up" parallel to the viewing direction


@dataclass(frozen=True)
class CaptureFrame:
    """The frame of the captured views: look-at centre [3], mean distance, unit up [3] (float64)."""

    center: torch.Tensor
    radius: float
    up: torch.Tensor

    @classmethod
    def of(cls, cameras: list[Camera]) -> "CaptureFrame":
        viewmats = torch.stack([c.viewmat.double().cpu() for c in cameras])  # [C, 4, 4]
        center = look_at_point(viewmats)
        radius = float((camera_centers(viewmats) - center).norm(dim=-1).mean())
        up = -viewmats[:, 1, :3].sum(0)  # camera -y (image up) in world coordinates, summed
        if up.norm() < 1e-9 or radius <= 0:
            raise UserError("the captured cameras give no up direction or distance to generate poses around; "
                            "pass a candidate file instead")
        up = up / up.norm()
        axis = torch.zeros(3, dtype=torch.float64)
        axis[int(up.abs().argmax())] = float(up[int(up.abs().argmax())].sign())
        if float(up @ axis) >= math.cos(math.radians(AXIS_SNAP_DEG)):
            up = axis  # cameras looking down at the centre tilt the mean up; a nearby world axis is the intent
        return cls(center, radius, up)

    def elevations(self, cameras: list[Camera]) -> torch.Tensor:
        """Elevation of each camera above the centre's horizontal plane, degrees. [C]"""
        offsets = camera_centers(torch.stack([c.viewmat.double().cpu() for c in cameras])) - self.center
        return torch.rad2deg(torch.asin((offsets @ self.up / offsets.norm(dim=-1)).clamp(-1, 1)))

    def pose(self, azimuth_deg: float, elevation_deg: float, radius: float) -> torch.Tensor:
        """World-to-camera [4, 4] float64 of the camera at (azimuth, elevation, radius) looking at the centre."""
        e1 = torch.linalg.cross(self.up, torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64))
        if e1.norm() < 1e-6:
            e1 = torch.linalg.cross(self.up, torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64))
        e1 = e1 / e1.norm()
        e2 = torch.linalg.cross(self.up, e1)
        a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
        direction = math.cos(e) * (math.cos(a) * e1 + math.sin(a) * e2) + math.sin(e) * self.up
        return look_at(self.center + radius * direction, self.center, self.up)


def parse_spec(spec: str) -> tuple[str, int] | None:
    """("orbit" | "hemisphere", N) for a generator spec such as `orbit:64`, None for anything else."""
    kind, _, count = spec.partition(":")
    if kind not in ("orbit", "hemisphere") or not _:
        return None
    try:
        n = int(count)
    except ValueError:
        raise UserError(f"--candidates {spec}: N must be a whole number (e.g. {kind}:64)") from None
    if n <= 0:
        raise UserError(f"--candidates {spec}: N must be positive")
    return kind, n


def generate(kind: str, n: int, captured: list[Camera], *, elevation: tuple[float, float] | None = None,
             radius: float | None = None, template: Camera | None = None) -> list[Camera]:
    """`n` image-less cameras of an orbit or hemisphere around `captured` (see the module docstring).

    Args:
        elevation: (lo, hi) degrees; default: orbit at the captured mean, hemisphere `HEMISPHERE_ELEVATION`.
        radius: distance to the centre; default the captured mean.
        template: intrinsics and size (default the first captured camera).
    """
    frame = CaptureFrame.of(captured)
    radius = frame.radius if radius is None else radius
    if radius <= 0:
        raise UserError(f"--radius must be positive, got {radius}")
    if elevation is None:
        mean = float(frame.elevations(captured).mean())
        elevation = (mean, mean) if kind == "orbit" else HEMISPHERE_ELEVATION
    lo, hi = elevation
    if not -MAX_ELEVATION <= lo <= hi <= MAX_ELEVATION:
        raise UserError(f"--elevation {lo},{hi}: need -{MAX_ELEVATION} <= lo <= hi <= {MAX_ELEVATION} degrees")
    template = template or captured[0]
    angles = []  # (azimuth, elevation) degrees
    for i in range(n):
        if kind == "orbit":
            angles.append((360.0 * i / n, lo + (hi - lo) * (i / (n - 1) if n > 1 else 0.5)))
        else:  # equal-area cap: sin(elevation) uniform in [sin lo, sin hi]
            s_lo, s_hi = math.sin(math.radians(lo)), math.sin(math.radians(hi))
            angles.append(((i * 180.0 * (3 - math.sqrt(5))) % 360.0,
                           math.degrees(math.asin(s_lo + (s_hi - s_lo) * (i + 0.5) / n))))
    return [Camera(i, f"{kind}_{i:04d}", frame.pose(az, el, radius).float(), template.fx, template.fy, template.cx,
                   template.cy, template.width, template.height) for i, (az, el) in enumerate(angles)]
