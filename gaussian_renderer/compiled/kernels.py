"""numba kernels of the compiled CPU rasterizer: tile binning, the pixel reach box of a pair and the Gram assembly;
the forward, backward and Gram moment-sum kernels that follow these rules are in `row_kernels`.

The walking kernels run in parallel over `num_slices` slices, one per thread (interleaved tiles; for binning,
contiguous runs of the depth-sorted Gaussians): per tile they walk the tile's depth-sorted list and update the
tile's pixels, as the CUDA 3DGS kernel does, so nothing per pair is stored and a tile stops as soon as all its
pixels are finished. A kernel "tile" is a block of whole binning tiles (`tiles.BLOCK_PIXELS`); a pair visits only
the pixels of its reach box (`_pixel_box`: the ellipse where alpha >= alpha_min can hold) clipped to its tile
rectangle (`rects`, pixels), so the block size changes the work, never the pixels a Gaussian touches. All arrays
are float64 (one compiled specialisation; the wrappers in `gaussian_renderer.compiled.ops` convert), per-Gaussian
sums go to one buffer per slice, added up at the end (`_sum_slices`).

Compositing rules (identical to `gaussian_renderer.rasterize`): a pair is skipped where power > 0 or
alpha = min(alpha_max, o exp(power)) < alpha_min; a pixel stops before the pair that would take its
transmittance below transmittance_min. `last[p]` = 1 + position (in the tile list) of the pixel's last
contributing pair, 0 when none. The backward and the Gram replay each pixel back to front from its final
transmittance, T_before = T_after / (1 - alpha), with the colour behind the pair accumulated on the way.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

GEO = 6  # mean x, mean y, conic a, b, c, opacity
# Packed per-Gaussian attributes, one row of `geom` [N, 8]: mean x, y, conic a, b, c, opacity, the skip threshold
# ln(alpha_min / o) - 1e-9 (exp is skipped below it: alpha < alpha_min there; the alpha test decides the rest), unused.


@njit(parallel=True, cache=True)
def bin_tiles(x0, x1, y0, y1, gids, num_tiles, tiles_x, num_slices):
    """Counting sort of (tile, Gaussian) pairs by tile, keeping the input (depth) order within each tile.

    x0..y1: inclusive tile rectangles, gids: Gaussian ids, all [n] and already in depth order.
    Returns offsets [T + 1] (int64) and ids [M] (int32): tile t's list is ids[offsets[t]:offsets[t + 1]].
    The Gaussians are cut into `num_slices` contiguous slices that count and fill in parallel.
    """
    n = gids.shape[0]
    step = (n + num_slices - 1) // num_slices
    counts = np.zeros((num_slices, num_tiles), np.int64)
    for s in prange(num_slices):
        for k in range(s * step, min(n, (s + 1) * step)):
            for ty in range(y0[k], y1[k] + 1):
                for tx in range(x0[k], x1[k] + 1):
                    counts[s, ty * tiles_x + tx] += 1
    offsets = np.zeros(num_tiles + 1, np.int64)
    starts = np.empty((num_slices, num_tiles), np.int64)
    total = 0
    for t in range(num_tiles):
        offsets[t] = total
        for s in range(num_slices):
            starts[s, t] = total
            total += counts[s, t]
    offsets[num_tiles] = total
    ids = np.empty(total, np.int32)
    for s in prange(num_slices):
        for k in range(s * step, min(n, (s + 1) * step)):
            g = gids[k]
            for ty in range(y0[k], y1[k] + 1):
                for tx in range(x0[k], x1[k] + 1):
                    t = ty * tiles_x + tx
                    ids[starts[s, t]] = g
                    starts[s, t] += 1
    return offsets, ids


BOX_MARGIN = 1e-6  # px added to the pixel box's half-widths, so rounding never drops a pixel the tests pass


@njit(inline="always", cache=True)
def _pixel_box(mx, my, ca, cb, cc, cut, tile_size):
    """Pixels of a tile the pair can reach: (x_lo, x_hi, y_lo, y_hi), inclusive, in-tile pixel indices.

    Where power = -q/2 >= cut, q = a dx^2 + 2 b dx dy + c dy^2 <= r2 = -2 cut: an ellipse whose axis-aligned box
    has half-widths sqrt(r2 c / det), sqrt(r2 a / det) (det = a c - b^2). Outside it every pixel fails the
    `power < cut` test, so skipping it changes nothing. Empty (x_lo > x_hi) when cut > 0; the whole tile when
    the conic is not positive definite or a value is not finite."""
    last = tile_size - 1
    det = ca * cc - cb * cb
    r2 = -2.0 * cut
    if r2 < 0.0:
        return 0, -1, 0, -1
    if not (det > 0.0 and ca > 0.0 and cc > 0.0 and r2 <= 1e300 and abs(mx) < 1e15 and abs(my) < 1e15):
        return 0, last, 0, last
    hx = min(1e9, math.sqrt(r2 * cc / det) * (1.0 + BOX_MARGIN) + BOX_MARGIN)  # capped: int() of inf is undefined
    hy = min(1e9, math.sqrt(r2 * ca / det) * (1.0 + BOX_MARGIN) + BOX_MARGIN)
    # pixel i has its centre at i + 0.5: keep i with |i + 0.5 - m| <= h
    x_lo = max(0, int(math.ceil(mx - hx - 0.5)))
    x_hi = min(last, int(math.floor(mx + hx - 0.5)))
    y_lo = max(0, int(math.ceil(my - hy - 0.5)))
    y_hi = min(last, int(math.floor(my + hy - 0.5)))
    return x_lo, x_hi, y_lo, y_hi


@njit(inline="always", cache=True)
def _pair_box(geom, rects, g, px0, py0, tile_size):
    """`_pixel_box` of Gaussian g in the tile (block) at (px0, py0), clipped to the Gaussian's pixel rectangle."""
    mx, my = geom[g, 0] - px0, geom[g, 1] - py0
    x_lo, x_hi, y_lo, y_hi = _pixel_box(mx, my, geom[g, 2], geom[g, 3], geom[g, 4], geom[g, 6], tile_size)
    return (max(x_lo, rects[g, 0] - px0), min(x_hi, rects[g, 1] - px0), max(y_lo, rects[g, 2] - py0),
            min(y_hi, rects[g, 3] - py0))


@njit(cache=True)
def first_appearance_order(lists, n):
    """Renumber the Gaussians of the block lists `lists` [M] (ids < n) by first appearance, so the kernels, which walk
    the lists block by block, read and write per-Gaussian rows that lie close together in memory. Returns order [n']
    (kernel index -> Gaussian id, each listed Gaussian once) and the lists in kernel indices [M] (int32)."""
    slot = np.full(n, -1, np.int32)
    order = np.empty(n, np.int64)
    out = np.empty(lists.shape[0], np.int32)
    count = 0
    for k in range(lists.shape[0]):
        g = lists[k]
        if slot[g] < 0:
            slot[g] = count
            order[count] = g
            count += 1
        out[k] = slot[g]
    return order[:count].copy(), out


@njit(parallel=True, cache=True)
def _sum_slices(buf):
    """Sum [S, N, K] over the slices. [N, K]"""
    out = np.zeros(buf.shape[1:])
    for i in prange(buf.shape[1]):
        for s in range(buf.shape[0]):
            for a in range(buf.shape[2]):
                out[i, a] += buf[s, i, a]
    return out


NUM_MOMENTS = 15  # sum s dx^i dy^j for i + j <= 4, in the order of `row_kernels.gram`'s accumulators


# Where each entry of the monomial Gram M = sum s m m^T (m = dx, dy, dx^2, dx dy, dy^2, 1) sits among the 15 moments
# (1, dx, dy, dx^2, dx dy, dy^2, dx^3, dx^2 dy, dx dy^2, dy^3, dx^4, dx^3 dy, dx^2 dy^2, dx dy^3, dy^4).
MOMENT_INDEX = np.array([[3, 4, 6, 7, 8, 1],
                         [4, 5, 7, 8, 9, 2],
                         [6, 7, 10, 11, 12, 3],
                         [7, 8, 11, 12, 13, 4],
                         [8, 9, 12, 13, 14, 5],
                         [1, 2, 3, 4, 5, 0]], np.int64)


@njit(parallel=True, cache=True)
def assemble_gram(sums, conics, opacities, d, rows):
    """[R, 6 + D, 6 + D] Grams of the Gaussians `rows` [R] from the moment sums [N, 15 + 6 D + 1] of `gram` (conics
    [N, 3], opacities [N]): geometry block L M L^T, cross block L X, colour block (sum w^2) I, with
    L = blockdiag([[a, b], [b, c]], -1/2, -1, -1/2, 1/o) (so v = alpha L m). Exactly symmetric, float64; every
    output element is written (no zero-filled array to page in)."""
    size = GEO + d
    out = np.empty((rows.shape[0], size, size))
    for j in prange(rows.shape[0]):
        i = rows[j]
        lmat = np.zeros((GEO, GEO))
        lmat[0, 0], lmat[0, 1], lmat[1, 0], lmat[1, 1] = conics[i, 0], conics[i, 1], conics[i, 1], conics[i, 2]
        lmat[2, 2], lmat[3, 3], lmat[4, 4] = -0.5, -1.0, -0.5
        lmat[5, 5] = 1.0 / max(opacities[i], 1e-300)
        for r in range(GEO):
            for c in range(r, GEO):
                acc = 0.0
                for k in range(GEO):
                    if lmat[r, k] != 0.0:
                        for m in range(GEO):
                            acc += lmat[r, k] * sums[i, MOMENT_INDEX[k, m]] * lmat[c, m]
                out[j, r, c] = acc
                out[j, c, r] = acc
            for ch in range(d):
                acc = 0.0
                for k in range(GEO):
                    acc += lmat[r, k] * sums[i, NUM_MOMENTS + k * d + ch]
                out[j, r, GEO + ch] = acc
                out[j, GEO + ch, r] = acc
        for ch in range(d):
            for ch2 in range(d):
                out[j, GEO + ch, GEO + ch2] = sums[i, NUM_MOMENTS + GEO * d] if ch == ch2 else 0.0
    return out


@njit(cache=True)
def nonzero_rows(sums):
    """Indices [R] of the rows of `sums` [N, S] with a non-zero entry (the Gaussians a view's Gram sees)."""
    keep = np.empty(sums.shape[0], np.int64)
    count = 0
    for i in range(sums.shape[0]):
        for a in range(sums.shape[1]):
            if sums[i, a] != 0.0:
                keep[count] = i
                count += 1
                break
    return keep[:count].copy()
