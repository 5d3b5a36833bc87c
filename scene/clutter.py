"""The built-in scene's `clutter` layout: a different arrangement of objects for every seed.

The default layout (`objects` in scene/builtin.py) places the same four objects for every seed, only resampling
their surface points, so it is one scene. Here the seed draws the scene itself: seven objects, one of each kind
(sphere, box, standing ring, tall column) and three of kinds drawn at random, with random sizes, hues and yaws,
placed without overlap on the ground disc, so each seed is a scene no selector or rule was designed on (held-out
checks: docs/recommend.md). Columns are three to four times taller than wide and hide what stands behind them from
part of the hemisphere.
"""
from __future__ import annotations

import colorsys
import math

import torch

NUM_OBJECTS = 7
KINDS = ("sphere", "box", "ring", "column")
PLACE_RADIUS = 0.85  # object centres lie in this disc (the ground disc has radius 1.2)
MIN_GAP = 0.1  # free space between two objects' footprints
POINT_SCALE = 0.045  # isotropic Gaussian scale, as the default layout's objects
ATTEMPTS = 400  # placement draws per object
POINTS_PER_AREA = 2500.0  # surface samples per unit area, clamped to [150, 1200] per object


def _uniform(g: torch.Generator, low: float, high: float) -> float:
    return low + (high - low) * torch.rand((), generator=g).item()


def _count(area: float) -> int:
    return int(min(1200, max(150, area * POINTS_PER_AREA)))


def _sphere(g: torch.Generator, size: float) -> torch.Tensor:
    """Surface points of a sphere of radius `size` resting on the ground, centred above the origin. [N, 3]"""
    n = _count(4 * math.pi * size ** 2)
    u, phi = torch.rand(n, generator=g) * 2 - 1, torch.rand(n, generator=g) * 2 * math.pi
    r = torch.sqrt(1 - u * u)
    return torch.stack([r * torch.cos(phi), r * torch.sin(phi), u + 1], 1) * size


def _box(g: torch.Generator, size: float) -> torch.Tensor:
    """Surface points of a box with half extents (size, 0.6-1.2 size, 0.8-1.6 size) standing on the ground. [N, 3]"""
    half = torch.tensor([size, size * _uniform(g, 0.6, 1.2), size * _uniform(g, 0.8, 1.6)])
    area = 8 * float(half[0] * half[1] + half[1] * half[2] + half[0] * half[2])
    n = _count(area)
    p = torch.rand(n, 3, generator=g) * 2 - 1
    axis = torch.randint(0, 3, (n,), generator=g)
    p[torch.arange(n), axis] = torch.sign(p[torch.arange(n), axis])
    return p * half + torch.tensor([0.0, 0.0, float(half[2])])


def _ring(g: torch.Generator, size: float) -> torch.Tensor:
    """Surface points of a torus (major radius `size`, minor 0.25 size) standing upright on the ground. [N, 3]"""
    minor = 0.25 * size
    n = _count(4 * math.pi ** 2 * size * minor)
    a, b = torch.rand(n, generator=g) * 2 * math.pi, torch.rand(n, generator=g) * 2 * math.pi
    return torch.stack([(size + minor * torch.cos(b)) * torch.cos(a), minor * torch.sin(b),
                        (size + minor * torch.cos(b)) * torch.sin(a) + size + minor], 1)


def _column(g: torch.Generator, size: float) -> torch.Tensor:
    """Surface points of a capped cylinder of radius 0.35 size and height 3-4 size on the ground. [N, 3]"""
    radius, height = 0.35 * size, size * _uniform(g, 3.0, 4.0)
    side, cap = 2 * math.pi * radius * height, math.pi * radius ** 2
    n = _count(side + cap)
    ang = torch.rand(n, generator=g) * 2 * math.pi
    on_cap = torch.rand(n, generator=g) < cap / (side + cap)
    rad = torch.where(on_cap, torch.sqrt(torch.rand(n, generator=g)) * radius, torch.full((n,), radius))
    z = torch.where(on_cap, torch.full((n,), height), torch.rand(n, generator=g) * height)
    return torch.stack([rad * torch.cos(ang), rad * torch.sin(ang), z], 1)


SHAPES = {"sphere": _sphere, "box": _box, "ring": _ring, "column": _column}
FOOTPRINT = {"sphere": 1.0, "box": 1.3, "ring": 1.25, "column": 0.35}  # footprint radius / size


def _yaw(points: torch.Tensor, angle: float) -> torch.Tensor:
    c, s = math.cos(angle), math.sin(angle)
    rot = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return points @ rot.T


def clutter_points(g: torch.Generator) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, list[dict]]:
    """Centres [N,3], colours [N,3], isotropic scales [N] and the placed objects (kind, centre, size, hue)."""
    placed: list[dict] = []
    parts = []
    for i in range(NUM_OBJECTS):
        kind = KINDS[i % len(KINDS)] if i < len(KINDS) else KINDS[int(torch.randint(0, 4, (), generator=g))]
        for attempt in range(ATTEMPTS):  # rejection sampling of a free footprint, smaller every 40 tries
            size = _uniform(g, 0.14, 0.3) * 0.85 ** (attempt // 40)
            rad, ang = math.sqrt(_uniform(g, 0, 1)) * PLACE_RADIUS, _uniform(g, 0, 2 * math.pi)
            centre = (rad * math.cos(ang), rad * math.sin(ang))
            reach = FOOTPRINT[kind] * size
            if all(math.dist(centre, o["centre"]) > reach + o["reach"] + MIN_GAP for o in placed):
                break
        else:
            raise RuntimeError(f"no free footprint for object {i} after {ATTEMPTS} draws")  # not seen in 1,000 seeds
        hue = _uniform(g, 0, 1)
        placed.append({"kind": kind, "centre": centre, "size": size, "reach": reach, "hue": hue})
        points = _yaw(SHAPES[kind](g, size), _uniform(g, 0, 2 * math.pi)) + torch.tensor([*centre, 0.0])
        base = torch.tensor(colorsys.hsv_to_rgb(hue, 0.75, 0.85))
        colors = (base + 0.15 * (torch.rand(points.shape[0], 3, generator=g) - 0.5)).clamp(0, 1)
        parts.append((points, colors))
    means = torch.cat([p for p, _ in parts])
    colors = torch.cat([c for _, c in parts])
    return means, colors, torch.full((means.shape[0],), POINT_SCALE), placed
