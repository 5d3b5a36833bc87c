"""The tile engine both rasterizer backends share: tile geometry, binning, the chunked front-to-back replay and the
per-pair closed-form partials.

Gaussians are binned into square tiles by their reach (`tile_ranges`: opacity-aware, capped by the 3-sigma radius),
sorted by depth per tile. The torch path (`gaussian_renderer.rasterize`, `gaussian_renderer.fisher_partials`)
replays every still-active tile at once, `chunk_size` Gaussians deep at a time (`iterate_chunks`): the working set
is [tiles, chunk_size, tile_size^2], never pixels x all Gaussians, and nothing per pair is stored for a backward
pass: each pair's d colour / d alpha comes in closed form from the running prefix colour and the final colour
(`color_alpha_partials`; the CUDA 3DGS kernel does the same back to front). The compiled backend
(`gaussian_renderer.compiled.ops`) bins with the same `tile_ranges` into blocks of `BLOCK_PIXELS`.

2D attributes of Gaussian i (A = 6 + D): mean x, mean y, conic a, b, c, opacity, colour[D].
Conventions: pixel (x, y) has its centre at (x + 0.5, y + 0.5); conic (a, b, c) is [[a, b], [b, c]].
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import torch

from gaussian_renderer.settings import RasterSettings

# The engine's fixed sizes (the tunable ones are `RasterSettings`):
NUM_GEOMETRY_ATTRIBUTES = 6  # mean x, mean y, conic a, b, c, opacity
# Torch path: pixel-Gaussian pairs evaluated at once (tiles x chunk_size x tile_size^2): a few MB per pair tensor, so
# the chunk's ~20 temporaries stay cache-sized at any resolution (benchmarks/bench_rasterize.py --resolution_scaling).
MAX_CHUNK_PAIRS = 1 << 18
# Compiled path: side of the pixel blocks the kernels work on (measured: 8-16 beat 4; CUDA 3DGS also uses 16).
BLOCK_PIXELS = 16


def grid_size(width: int, height: int, side: int) -> tuple[int, int]:
    """Squares of `side` pixels across and down an image of width x height (the last ones may stick out)."""
    return -(-width // side), -(-height // side)


@dataclass
class TileBins:
    """Per-tile, depth-sorted Gaussian lists and the pixels of each tile."""

    lists: torch.Tensor  # [T, L] Gaussian ids, front to back, -1 = padding
    pixels: torch.Tensor  # [T, P, 2] pixel centres (P = tile_size^2)
    pixel_valid: torch.Tensor  # [T, P] bool: inside the image
    pixel_index: torch.Tensor  # [T, P] flat index y * W + x (clamped for invalid pixels)


def tile_ranges(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, radii: torch.Tensor,
                width: int, height: int, tile_size: int, alpha_min: float) -> tuple[torch.Tensor, ...]:
    """Inclusive tile rectangle (x0, x1, y0, y1) of the pixels a Gaussian can reach, clamped to the image. [N] each

    The reach is the tighter of the 3-sigma radius and the opacity-aware extent: alpha = o exp(-d^2/2) falls below
    alpha_min beyond d = sqrt(2 ln(o / alpha_min)) standard deviations, per axis (sqrt of the 2D covariance's
    diagonal). Pairs dropped this way would be skipped by the alpha test anyway, so the image is unchanged.
    A Gaussian whose opacity is below alpha_min gets an empty rectangle (x0 > x1).
    """
    tiles_x, tiles_y = grid_size(width, height, tile_size)
    det = (conics[:, 0] * conics[:, 2] - conics[:, 1] ** 2).clamp_min(1e-30)
    sigma_x, sigma_y = torch.sqrt((conics[:, 2] / det).clamp_min(0)), torch.sqrt((conics[:, 0] / det).clamp_min(0))
    reach = torch.sqrt(2 * torch.log((opacities / alpha_min).clamp_min(1.0)))  # in standard deviations
    r = radii.to(means2d.dtype)
    ext_x, ext_y = torch.minimum(reach * sigma_x, r), torch.minimum(reach * sigma_y, r)
    x0 = torch.floor((means2d[:, 0] - ext_x) / tile_size).clamp(0, tiles_x - 1).long()
    x1 = torch.floor((means2d[:, 0] + ext_x) / tile_size).clamp(0, tiles_x - 1).long()
    y0 = torch.floor((means2d[:, 1] - ext_y) / tile_size).clamp(0, tiles_y - 1).long()
    y1 = torch.floor((means2d[:, 1] + ext_y) / tile_size).clamp(0, tiles_y - 1).long()
    empty = opacities < alpha_min
    return x0, torch.where(empty, x0 - 1, x1), y0, y1


def bin_gaussians(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, radii: torch.Tensor,
                  depths: torch.Tensor, width: int, height: int, settings: RasterSettings) -> TileBins:
    """Build depth-sorted per-tile lists from the (tile, Gaussian) pairs of each Gaussian's tile rectangle."""
    tile_size = settings.tile_size
    device = means2d.device
    tiles_x, tiles_y = grid_size(width, height, tile_size)
    num_tiles = tiles_x * tiles_y
    with torch.no_grad():
        ids = torch.nonzero(radii > 0).squeeze(1)  # [n]
        x0, x1, y0, y1 = tile_ranges(means2d.detach()[ids], conics.detach()[ids], opacities.detach()[ids],
                                     radii[ids], width, height, tile_size, settings.alpha_min)
        nx, ny = (x1 - x0 + 1).clamp_min(0), y1 - y0 + 1
        counts = nx * ny  # [n]
        total = int(counts.sum())
        gid = torch.repeat_interleave(ids, counts)  # [M]
        starts = torch.cumsum(counts, 0) - counts
        local = torch.arange(total, device=device) - torch.repeat_interleave(starts, counts)
        nx_rep = torch.repeat_interleave(nx, counts)
        tile = ((torch.repeat_interleave(y0, counts) + local // nx_rep) * tiles_x
                + torch.repeat_interleave(x0, counts) + local % nx_rep)
        rank = torch.empty_like(radii)
        rank[torch.argsort(depths.detach(), stable=True)] = torch.arange(len(radii), device=device)
        order = torch.argsort(tile * max(len(radii), 1) + rank[gid])
        tile, gid = tile[order], gid[order]
        per_tile = torch.bincount(tile, minlength=num_tiles)
        length = max(int(per_tile.max()) if total else 0, 1)
        pos = torch.arange(total, device=device) - (torch.cumsum(per_tile, 0) - per_tile)[tile]
        lists = torch.full((num_tiles, length), -1, dtype=torch.long, device=device)
        lists[tile, pos] = gid
        t = torch.arange(num_tiles, device=device)
        p = torch.arange(tile_size * tile_size, device=device)
        px = (t % tiles_x)[:, None] * tile_size + (p % tile_size)[None, :]  # [T, P]
        py = (t // tiles_x)[:, None] * tile_size + (p // tile_size)[None, :]
        valid = (px < width) & (py < height)
        pixels = torch.stack([px, py], dim=-1).to(means2d.dtype) + 0.5
        index = torch.where(valid, py * width + px, torch.zeros_like(px))
    return TileBins(lists, pixels, valid, index)


@dataclass
class ChunkPairs:
    """The (pixel, Gaussian) pairs of one depth chunk of the still-active tiles. Shapes [Ta, c, P] unless noted."""

    tiles: torch.Tensor  # [Ta] indices of the tiles in this chunk
    ids: torch.Tensor  # [Ta, c] Gaussian ids, front to back (-1 = padding)
    alpha: torch.Tensor  # effective alpha (0 where the pair does not contribute)
    unclamped: torch.Tensor  # bool: contributes and alpha < alpha_max (so alpha has a derivative)
    gauss: torch.Tensor  # exp(power)
    dx: torch.Tensor  # pixel centre - mean, x
    dy: torch.Tensor
    trans: torch.Tensor  # transmittance in front of the Gaussian
    weight: torch.Tensor  # alpha * trans: the pair's share of the pixel colour


def iterate_chunks(bins: TileBins, means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor,
                    settings: RasterSettings) -> Iterator[ChunkPairs]:
    """Replay the front-to-back compositing chunk by chunk (3DGS rules: alpha skip, clamp, early stop).

    Only tiles that still have Gaussians at this depth and an unfinished pixel take part in a chunk, so short
    tile lists and saturated tiles cost nothing. Pair tensors are laid out [tiles, depth, pixels] so that sums
    over a tile's pixels run over contiguous memory. The active tiles of one depth step are split into groups of
    at most `MAX_CHUNK_PAIRS` pixel-Gaussian pairs, so the working set stays the same size at any resolution
    (one [all tiles, chunk, pixels] tensor grows with the image and turns memory-bound). Groups hold disjoint
    tiles and every tile still sees its chunks front to back, so the result does not depend on the grouping.
    """
    num_tiles, num_pixels = bins.pixel_valid.shape
    dtype, device = means2d.dtype, means2d.device
    group = max(1, MAX_CHUNK_PAIRS // (settings.chunk_size * num_pixels))  # tiles per group
    trans = torch.ones(num_tiles, num_pixels, dtype=dtype, device=device)  # real transmittance
    trans_test = trans.clone()  # transmittance with every alpha, for the early-stop test (monotone)
    for start in range(0, bins.lists.shape[1], settings.chunk_size):
        unfinished = (trans_test >= settings.transmittance_min) & bins.pixel_valid  # [T, P]
        active = torch.nonzero((bins.lists[:, start] >= 0) & unfinished.any(dim=1)).squeeze(1)
        if active.numel() == 0:
            break
        for tiles in active.split(group):
            chunk, cum, cum_test = _chunk_pairs(bins, tiles, start, means2d, conics, opacities, trans, trans_test,
                                                settings)
            yield chunk
            trans[tiles] = trans[tiles] * cum[:, -1]
            trans_test[tiles] = cum_test[:, -1]


def _chunk_pairs(bins: TileBins, tiles: torch.Tensor, start: int, means2d: torch.Tensor, conics: torch.Tensor,
                 opacities: torch.Tensor, trans: torch.Tensor, trans_test: torch.Tensor,
                 settings: RasterSettings) -> tuple[ChunkPairs, torch.Tensor, torch.Tensor]:
    """The pairs of `tiles` [Ta] at list positions start .. start + chunk_size, given the transmittances [T, P]
    in front of them; also returns the running products of (1 - alpha) [Ta, c, P], real and for the stop test."""
    ids = bins.lists[tiles, start:start + settings.chunk_size]  # [Ta, c]
    safe = ids.clamp_min(0)
    mean, conic, opacity = means2d[safe], conics[safe], opacities[safe]  # [Ta,c,2], [Ta,c,3], [Ta,c]
    pixels = bins.pixels[tiles]  # [Ta, P, 2]
    dx = pixels[:, None, :, 0] - mean[..., 0:1]  # [Ta, c, P]
    dy = pixels[:, None, :, 1] - mean[..., 1:2]
    power = -0.5 * (conic[..., 0:1] * dx * dx + conic[..., 2:3] * dy * dy) - conic[..., 1:2] * dx * dy
    gauss = torch.exp(power)
    raw = opacity[..., None] * gauss
    alpha = raw.clamp_max(settings.alpha_max)
    live = ((ids >= 0)[..., None] & (power <= 0) & (alpha >= settings.alpha_min)
            & bins.pixel_valid[tiles][:, None, :])
    alpha = torch.where(live, alpha, torch.zeros_like(alpha))
    cum = torch.cumprod(1 - alpha, dim=1)
    cum_test = trans_test[tiles][:, None, :] * cum
    stop = cum_test < settings.transmittance_min  # this pair and all behind it in the pixel are skipped
    if alpha.is_cuda or bool(stop.any()):  # on CUDA no host sync: the masked recompute is exact when none stops
        alpha = torch.where(stop, torch.zeros_like(alpha), alpha)
        cum = torch.cumprod(1 - alpha, dim=1)
    front = trans[tiles][:, None, :] * torch.cat([torch.ones_like(cum[:, :1]), cum[:, :-1]], dim=1)
    chunk = ChunkPairs(tiles, ids, alpha, (alpha > 0) & (raw < settings.alpha_max), gauss, dx, dy, front,
                       alpha * front)
    return chunk, cum, cum_test


def to_image(values: torch.Tensor, bins: TileBins, width: int, height: int) -> torch.Tensor:
    """Scatter per-tile pixel values [T, P, D] to an image [D, H, W]."""
    d = values.shape[-1]
    out = values.new_zeros(height * width, d)
    out[bins.pixel_index[bins.pixel_valid]] = values[bins.pixel_valid]
    return out.T.reshape(d, height, width)


def from_image(image: torch.Tensor, bins: TileBins) -> torch.Tensor:
    """Gather an image [D, H, W] into per-tile pixels [T, P, D] (zeros outside the image)."""
    flat = image.reshape(image.shape[0], -1).T  # [H*W, D]
    return torch.where(bins.pixel_valid[..., None], flat[bins.pixel_index], torch.zeros_like(flat[:1]))


def composite(bins: TileBins, means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor,
               colors: torch.Tensor, background: torch.Tensor,
               settings: RasterSettings) -> tuple[torch.Tensor, torch.Tensor]:
    """Forward compositing; returns final per-tile colour [T,P,D] (background included) and transmittance [T,P]."""
    num_tiles, num_pixels = bins.pixel_valid.shape
    trans = torch.ones(num_tiles, num_pixels, dtype=means2d.dtype, device=means2d.device)
    color = torch.zeros(num_tiles, num_pixels, colors.shape[1], dtype=means2d.dtype, device=means2d.device)
    for chunk in iterate_chunks(bins, means2d, conics, opacities, settings):
        color[chunk.tiles] += torch.bmm(chunk.weight.transpose(1, 2), colors[chunk.ids.clamp_min(0)])
        trans[chunk.tiles] = chunk.trans[:, -1] * (1 - chunk.alpha[:, -1])
    return color + trans[..., None] * background, trans


def alpha_partials(chunk: ChunkPairs, conics: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """d alpha / d (mean x, mean y, conic a, b, c, opacity) per pair, zero where alpha has no derivative.

    Returns [Ta, c, P, 6] (dim=-1) or [Ta, c, 6, P] (dim=2, the layout of a per-pair matrix product).
    """
    conic = conics[chunk.ids.clamp_min(0)][..., None, :]  # [Ta, c, 1, 3]
    a = torch.where(chunk.unclamped, chunk.alpha, torch.zeros_like(chunk.alpha))
    ax, ay = a * chunk.dx, a * chunk.dy
    return torch.stack([conic[..., 0] * ax + conic[..., 1] * ay, conic[..., 1] * ax + conic[..., 2] * ay,
                        -0.5 * ax * chunk.dx, -ax * chunk.dy, -0.5 * ay * chunk.dy,
                        torch.where(chunk.unclamped, chunk.gauss, torch.zeros_like(chunk.gauss))], dim=dim)


def color_alpha_partials(chunk: ChunkPairs, colors: torch.Tensor, final_color: torch.Tensor,
                          prefix: torch.Tensor) -> torch.Tensor:
    """d pixel colour / d alpha_i = c_i T_i - (colour behind i) / (1 - alpha_i). [Ta, c, D, P]

    `final_color` [T, D, P] is the composited colour; `prefix` [T, D, P] holds the colour accumulated in front of
    this chunk and is advanced past it. Both are laid out channels-before-pixels like the result.
    """
    col = colors[chunk.ids.clamp_min(0)][..., None]  # [Ta, c, D, 1]
    incl = torch.cumsum(chunk.weight[:, :, None, :] * col, dim=1)  # [Ta, c, D, P]
    incl += prefix[chunk.tiles][:, None]
    prefix[chunk.tiles] = incl[:, -1]
    behind = final_color[chunk.tiles][:, None] - incl
    return col * chunk.trans[:, :, None, :] - behind * (1 / (1 - chunk.alpha))[:, :, None, :]


def scatter_rows(values: torch.Tensor, ids: torch.Tensor, n: int) -> torch.Tensor:
    """Sum rows [Ta, c, ...] into [n, ...] by Gaussian id, dropping the -1 padding.

    The padding goes to a spare row n instead of being masked out: boolean indexing would be a host sync per chunk
    on a GPU, and each real row still receives the same values in the same order.
    """
    flat_ids = ids.reshape(-1)
    flat = values.reshape(flat_ids.shape[0], -1)
    out = flat.new_zeros(n + 1, flat.shape[1])
    out.index_add_(0, torch.where(flat_ids >= 0, flat_ids, n), flat)
    return out[:n].reshape(n, *values.shape[2:])


def check_inputs(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, colors: torch.Tensor,
                 depths: torch.Tensor, radii: torch.Tensor, background: torch.Tensor) -> None:
    """Assert the shapes every rasterizer entry point takes (`rasterize`'s arguments)."""
    n = means2d.shape[0]
    assert means2d.shape == (n, 2), f"means2d must be [N,2], got {tuple(means2d.shape)}"
    assert conics.shape == (n, 3), f"conics must be [N,3], got {tuple(conics.shape)}"
    assert opacities.shape == (n,), f"opacities must be [N], got {tuple(opacities.shape)}"
    assert colors.ndim == 2 and colors.shape[0] == n, f"colors must be [N,D], got {tuple(colors.shape)}"
    assert depths.shape == (n,) and radii.shape == (n,), f"depths/radii must be [N], got {depths.shape}/{radii.shape}"
    assert background.shape == (colors.shape[1],), f"background must be [D], got {tuple(background.shape)}"
