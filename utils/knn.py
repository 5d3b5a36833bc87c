"""Point-cloud helpers: exact k-nearest-neighbour distances in memory-bounded chunks, random synthetic clouds.

`knn_sq_distances` is exact but avoids the all-pairs cost: points are sorted along a Morton (Z-order) curve, each
point's distance to k of its curve neighbours bounds its true k-th neighbour distance from above, and each block
of consecutive points then only compares against the points inside its bounding box grown by that bound. Any
point outside the grown box is farther than k known points, so it cannot be among the k nearest.
"""
from __future__ import annotations

import torch

_MORTON_BITS = 21  # bits per axis: 3 * 21 = 63 fits a signed int64 code


def _spread_bits(v: torch.Tensor) -> torch.Tensor:
    """Insert two zero bits between the low 21 bits of each int64 (the per-axis step of a 3D Morton code)."""
    v = v & 0x1FFFFF
    v = (v | (v << 32)) & 0x1F00000000FFFF
    v = (v | (v << 16)) & 0x1F0000FF0000FF
    v = (v | (v << 8)) & 0x100F00F00F00F00F
    v = (v | (v << 4)) & 0x10C30C30C30C30C3
    v = (v | (v << 2)) & 0x1249249249249249
    return v


def morton_order(points: torch.Tensor, trim: float = 1e-3) -> torch.Tensor:
    """Permutation sorting `points` [P, 3] along a Z-order curve. -> [P] int64

    The curve's grid spans the per-axis [trim, 1 - trim] quantile range (points outside share the border cells),
    so a few far outliers do not collapse the bulk of the cloud into a handful of cells.
    """
    n = points.shape[0]
    by_axis = points.sort(dim=0).values  # [P, 3]
    lo = by_axis[int(trim * (n - 1))]
    extent = (by_axis[int((1 - trim) * (n - 1))] - lo).max().clamp_min(torch.finfo(points.dtype).tiny)
    cells = ((points - lo) / extent * (2 ** _MORTON_BITS - 1)).clamp(0, 2 ** _MORTON_BITS - 1).long()  # [P, 3]
    codes = _spread_bits(cells[:, 0]) | (_spread_bits(cells[:, 1]) << 1) | (_spread_bits(cells[:, 2]) << 2)
    return torch.argsort(codes)


def _sq_dist(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Squared distances by explicit differences (no |a|^2 + |b|^2 - 2ab cancellation). [A, 3], [B, 3] -> [A, B]"""
    return torch.cdist(a, b, compute_mode="donot_use_mm_for_euclid_dist").square()


def _grown_box_members(pts: torch.Tensor, queries: torch.Tensor, radius: torch.Tensor) -> torch.Tensor:
    """Indices (ascending) of the rows of `pts` [M, 3] inside the box of `queries` [B, 3] grown by `radius`."""
    lo = queries.min(dim=0).values - radius
    hi = queries.max(dim=0).values + radius
    return ((pts >= lo) & (pts <= hi)).all(dim=1).nonzero()[:, 0]


def knn_sq_distances(points: torch.Tensor, k: int, block: int = 128, superblock: int = 8192,
                     max_pairs: int = 1 << 22) -> torch.Tensor:
    """Squared distances from each point to its `k` nearest *other* points, ascending.

    Exact (see the module docstring). Candidate boxes are found in two levels: a superblock of consecutive
    curve-sorted points filters the whole cloud once, then each block inside it filters only the superblock's
    candidates. Memory stays below about `max_pairs` distances at a time (plus O(P k) for the bounds), and time is
    close to linear in P for clouds without huge empty gaps.

    Args:
        points: positions, finite. [P, 3]
        k: neighbours per point, 1 <= k <= P - 1.
        block: consecutive curve-sorted query points that share one candidate box.
        superblock: consecutive curve-sorted query points that share one first-level filter (a multiple of block).
        max_pairs: largest number of query-candidate distances held at once.
    Returns:
        squared distances. [P, k]
    """
    assert points.dim() == 2 and points.shape[1] == 3, f"points must be [P, 3], got {tuple(points.shape)}"
    n = points.shape[0]
    assert 1 <= k <= n - 1, f"need 1 <= k <= P - 1, got k={k} for P={n}"
    assert superblock % block == 0, f"superblock ({superblock}) must be a multiple of block ({block})"
    window = 4 * k  # curve neighbours on each side used for the upper bound
    if n <= 2 * window + 1:
        return knn_sq_distances_reference(points, k)
    device = points.device
    order = morton_order(points)
    sorted_pts = points[order]  # [P, 3]
    # Upper bound: the k-th smallest distance to 2 * window distinct curve neighbours (indices wrap around).
    offsets = torch.cat([torch.arange(-window, 0), torch.arange(1, window + 1)]).to(device)  # [2w]
    ring = (torch.arange(n, device=device)[:, None] + offsets) % n  # [P, 2w]
    ring_d2 = (sorted_pts[ring] - sorted_pts[:, None, :]).square().sum(dim=-1)  # [P, 2w]
    radius = ring_d2.topk(k, dim=1, largest=False).values[:, -1].sqrt()  # [P]
    out_sorted = torch.empty(n, k, dtype=points.dtype, device=device)
    for s0 in range(0, n, superblock):
        s1 = min(n, s0 + superblock)
        sup_idx = _grown_box_members(sorted_pts, sorted_pts[s0:s1], radius[s0:s1].max())  # [S] sorted indices
        sup_pts = sorted_pts[sup_idx]  # [S, 3]
        for b0 in range(s0, s1, block):
            b1 = min(s1, b0 + block)
            queries = sorted_pts[b0:b1]  # [B, 3]
            cand_idx = sup_idx[_grown_box_members(sup_pts, queries, radius[b0:b1].max())]  # [M], has the queries
            candidates = sorted_pts[cand_idx]  # [M, 3]
            # Position of each query inside the candidate list, to exclude the point itself.
            self_pos = torch.searchsorted(cand_idx, torch.arange(b0, b1, device=device))  # [B]
            rows = max(1, max_pairs // cand_idx.shape[0])
            for r0 in range(0, b1 - b0, rows):
                d2 = _sq_dist(queries[r0:r0 + rows], candidates)  # [R, M]
                d2[torch.arange(d2.shape[0], device=device), self_pos[r0:r0 + rows]] = float("inf")
                out_sorted[b0 + r0:b0 + r0 + d2.shape[0]] = d2.topk(k, dim=1, largest=False).values
    out = torch.empty_like(out_sorted)
    out[order] = out_sorted
    return out


def knn_sq_distances_reference(points: torch.Tensor, k: int) -> torch.Tensor:
    """All-pairs twin of `knn_sq_distances` (O(P^2) memory; tests and tiny clouds only). [P, 3] -> [P, k]"""
    n = points.shape[0]
    d2 = _sq_dist(points, points)  # [P, P]
    d2[torch.arange(n), torch.arange(n)] = float("inf")
    return d2.topk(k, dim=1, largest=False).values


def mean_sq_dist_to_neighbours(points: torch.Tensor, k: int = 3) -> torch.Tensor:
    """Mean squared distance of each point to its `k` nearest other points (fewer if P <= k). [P, 3] -> [P]

    A cloud of a single point has no neighbours; it gets 1.0 (a unit-sized Gaussian).
    """
    n = points.shape[0]
    if n <= 1:
        return torch.ones(n, dtype=points.dtype, device=points.device)
    return knn_sq_distances(points, min(k, n - 1)).mean(dim=1)


def random_point_cloud(n: int, half_size: float, generator: torch.Generator | None = None,
                       device: str | torch.device = "cpu") -> tuple[torch.Tensor, torch.Tensor]:
    """Uniform points in the cube [-half_size, half_size]^3 with uniform random RGB colours.

    Draws positions first, then colours, on the CPU generator, so a seed gives the same cloud on every device.
    Returns:
        points [n, 3], colors [n, 3] in [0, 1] (float32 on `device`).
    """
    points = (torch.rand(n, 3, generator=generator) * 2 - 1) * half_size
    colors = torch.rand(n, 3, generator=generator)
    return points.to(device), colors.to(device)
