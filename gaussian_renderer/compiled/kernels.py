"""numba kernels of the compiled CPU rasterizer: tile binning, forward, backward and the Fisher Gram.

Each kernel runs in parallel over `num_slices` slices, one per thread (interleaved tiles; for binning, contiguous
runs of the depth-sorted Gaussians), and works one pixel at a time, as the CUDA 3DGS kernel does: per tile it walks
the tile's depth-sorted list and updates the tile's pixels, so nothing is padded and a tile stops as soon as all
its pixels are finished. All arrays are float64 (one compiled specialisation; the wrappers in
`gaussian_renderer.compiled.ops` convert), per-Gaussian sums go to one buffer per slice, added up at the end.

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


@njit(cache=True)
def _pixel_offsets(tile_size):
    """Pixel centre offsets inside a tile (float64) and integer offsets, each [tile_size^2]."""
    num_px = tile_size * tile_size
    fx, fy = np.empty(num_px), np.empty(num_px)
    ix, iy = np.empty(num_px, np.int64), np.empty(num_px, np.int64)
    for p in range(num_px):
        ix[p], iy[p] = p % tile_size, p // tile_size
        fx[p], fy[p] = ix[p] + 0.5, iy[p] + 0.5
    return fx, fy, ix, iy


@njit(parallel=True, cache=True)
def forward(offsets, ids, geom, colors, background, width, height, tile_size, tiles_x, alpha_min, alpha_max,
            trans_min, image, trans_out, last_out):
    """Front-to-back compositing. Writes image [D, H, W] (background included), trans_out [H, W] (final
    transmittance) and last_out [H, W] (int32, see the module docstring)."""
    num_tiles = offsets.shape[0] - 1
    d = colors.shape[1]
    fx, fy, ix, iy = _pixel_offsets(tile_size)
    num_px = fx.shape[0]
    for t in prange(num_tiles):
        px0, py0 = (t % tiles_x) * tile_size, (t // tiles_x) * tile_size
        trans = np.ones(num_px)
        color = np.zeros((num_px, d))
        last = np.zeros(num_px, np.int32)
        done = np.zeros(num_px, np.bool_)
        remaining = 0
        for p in range(num_px):
            if px0 + ix[p] >= width or py0 + iy[p] >= height:
                done[p] = True
            else:
                remaining += 1
        start, end = offsets[t], offsets[t + 1]
        for k in range(start, end):
            if remaining == 0:
                break
            g = ids[k]
            mx, my = geom[g, 0] - px0, geom[g, 1] - py0
            ca, cb, cc, o, cut = geom[g, 2], geom[g, 3], geom[g, 4], geom[g, 5], geom[g, 6]
            for p in range(num_px):
                if done[p]:
                    continue
                dx, dy = fx[p] - mx, fy[p] - my
                power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
                if power > 0.0 or power < cut:
                    continue
                alpha = min(alpha_max, o * math.exp(power))
                if alpha < alpha_min:
                    continue
                test = trans[p] * (1.0 - alpha)
                if test < trans_min:
                    done[p] = True
                    remaining -= 1
                    continue
                w = alpha * trans[p]
                for ch in range(d):
                    color[p, ch] += w * colors[g, ch]
                trans[p] = test
                last[p] = k - start + 1
        for p in range(num_px):
            x, y = px0 + ix[p], py0 + iy[p]
            if x < width and y < height:
                for ch in range(d):
                    image[ch, y, x] = color[p, ch] + trans[p] * background[ch]
                trans_out[y, x] = trans[p]
                last_out[y, x] = last[p]


@njit(parallel=True, cache=True)
def backward(offsets, ids, geom, colors, background, width, height, tile_size, tiles_x, alpha_min, alpha_max,
             trans_final, last_in, grad_image, grad_alpha, num_slices):
    """Back-to-front replay. Returns per-Gaussian gradients [N, 6 + D]: mean x, y, conic a, b, c, opacity,
    colour[D] (for loss gradients grad_image [D, H, W] and grad_alpha [H, W])."""
    n, d = colors.shape
    num_tiles = offsets.shape[0] - 1
    fx, fy, ix, iy = _pixel_offsets(tile_size)
    num_px = fx.shape[0]
    buf = np.zeros((num_slices, n, GEO + d))
    for sl in prange(num_slices):  # interleaved tiles, one gradient buffer per slice
        trans = np.empty(num_px)
        behind = np.empty(num_px)  # g . (colour behind the current pair) - dL/dalpha_out T_final
        gpix = np.empty((num_px, d))
        last = np.empty(num_px, np.int32)
        gcol = np.empty(d)
        for t in range(sl, num_tiles, num_slices):
            px0, py0 = (t % tiles_x) * tile_size, (t // tiles_x) * tile_size
            longest = 0
            for p in range(num_px):
                x, y = px0 + ix[p], py0 + iy[p]
                last[p] = 0
                if x < width and y < height:
                    trans[p] = trans_final[y, x]
                    last[p] = last_in[y, x]
                    longest = max(longest, last[p])
                    gb = 0.0
                    for ch in range(d):
                        gpix[p, ch] = grad_image[ch, y, x]
                        gb += gpix[p, ch] * background[ch]
                    behind[p] = trans[p] * (gb - grad_alpha[y, x])
            start = offsets[t]
            for j in range(longest - 1, -1, -1):
                g = ids[start + j]
                mx, my = geom[g, 0] - px0, geom[g, 1] - py0
                ca, cb, cc, o, cut = geom[g, 2], geom[g, 3], geom[g, 4], geom[g, 5], geom[g, 6]
                s_x = s_y = s_xx = s_xy = s_yy = s_o = 0.0
                gcol[:] = 0.0
                for p in range(num_px):
                    if j >= last[p]:
                        continue
                    dx, dy = fx[p] - mx, fy[p] - my
                    power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
                    if power > 0.0 or power < cut:
                        continue
                    gauss = math.exp(power)
                    raw = o * gauss
                    alpha = min(alpha_max, raw)
                    if alpha < alpha_min:
                        continue
                    inv = 1.0 / (1.0 - alpha)
                    t_front = trans[p] * inv
                    w = alpha * t_front
                    gc = 0.0
                    for ch in range(d):
                        gc += gpix[p, ch] * colors[g, ch]
                        gcol[ch] += w * gpix[p, ch]
                    if raw < alpha_max:
                        dl_dalpha = gc * t_front - behind[p] * inv
                        la = dl_dalpha * alpha
                        lx, ly = la * dx, la * dy
                        s_x += lx
                        s_y += ly
                        s_xx += lx * dx
                        s_xy += lx * dy
                        s_yy += ly * dy
                        s_o += dl_dalpha * gauss
                    behind[p] += w * gc
                    trans[p] = t_front
                buf[sl, g, 0] += ca * s_x + cb * s_y
                buf[sl, g, 1] += cb * s_x + cc * s_y
                buf[sl, g, 2] += -0.5 * s_xx
                buf[sl, g, 3] += -s_xy
                buf[sl, g, 4] += -0.5 * s_yy
                buf[sl, g, 5] += s_o
                for ch in range(d):
                    buf[sl, g, GEO + ch] += gcol[ch]
    return _sum_slices(buf)


@njit(parallel=True, cache=True)
def _sum_slices(buf):
    """Sum [S, N, K] over the slices. [N, K]"""
    out = np.zeros(buf.shape[1:])
    for i in prange(buf.shape[1]):
        for s in range(buf.shape[0]):
            for a in range(buf.shape[2]):
                out[i, a] += buf[s, i, a]
    return out


@njit(parallel=True, cache=True)
def gram(offsets, ids, geom, colors, background, width, height, tile_size, tiles_x, alpha_min, alpha_max,
         trans_final, last_in, pixel_weights, num_slices):
    """Per-Gaussian sums for the attribute Gram [N, 6 (6 + D) + 1]: the 6 x (6 + D) block
    [v (|u|^2 v)^T | v (w u)^T] row-major (upper triangle of the 6 x 6 part only), then sum w^2, over pixels p
    (weighted by pixel_weights [H, W]).

    Per pair: u = dC/dalpha [D] = c T - B / (1 - alpha) (B = colour behind, background included),
    v = dalpha / d(geometry) [6] (0 where alpha is clamped), w = alpha T.
    """
    n, d = colors.shape
    row_len = GEO * (GEO + d) + 1
    num_tiles = offsets.shape[0] - 1
    fx, fy, ix, iy = _pixel_offsets(tile_size)
    num_px = fx.shape[0]
    buf = np.zeros((num_slices, n, row_len))
    for sl in prange(num_slices):  # interleaved tiles, one buffer per slice
        trans = np.empty(num_px)
        behind = np.empty((num_px, d))
        wpix = np.empty(num_px)
        last = np.empty(num_px, np.int32)
        acc = np.empty(row_len)
        u = np.empty(d)
        v = np.empty(GEO)
        for t in range(sl, num_tiles, num_slices):
            px0, py0 = (t % tiles_x) * tile_size, (t // tiles_x) * tile_size
            longest = 0
            for p in range(num_px):
                x, y = px0 + ix[p], py0 + iy[p]
                last[p] = 0
                if x < width and y < height:
                    trans[p] = trans_final[y, x]
                    last[p] = last_in[y, x]
                    longest = max(longest, last[p])
                    wpix[p] = pixel_weights[y, x]
                    for ch in range(d):
                        behind[p, ch] = trans[p] * background[ch]
            start = offsets[t]
            for j in range(longest - 1, -1, -1):
                g = ids[start + j]
                mx, my = geom[g, 0] - px0, geom[g, 1] - py0
                ca, cb, cc, o, cut = geom[g, 2], geom[g, 3], geom[g, 4], geom[g, 5], geom[g, 6]
                acc[:] = 0.0
                for p in range(num_px):
                    if j >= last[p]:
                        continue
                    dx, dy = fx[p] - mx, fy[p] - my
                    power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
                    if power > 0.0 or power < cut:
                        continue
                    gauss = math.exp(power)
                    raw = o * gauss
                    alpha = min(alpha_max, raw)
                    if alpha < alpha_min:
                        continue
                    inv = 1.0 / (1.0 - alpha)
                    t_front = trans[p] * inv
                    w = alpha * t_front
                    wp = wpix[p]
                    uu = 0.0
                    for ch in range(d):
                        u[ch] = colors[g, ch] * t_front - behind[p, ch] * inv
                        uu += u[ch] * u[ch]
                        behind[p, ch] += w * colors[g, ch]
                    trans[p] = t_front
                    if raw < alpha_max:
                        ax, ay = alpha * dx, alpha * dy
                        v[0] = ca * ax + cb * ay
                        v[1] = cb * ax + cc * ay
                        v[2] = -0.5 * ax * dx
                        v[3] = -ax * dy
                        v[4] = -0.5 * ay * dy
                        v[5] = gauss
                        wuu, ww = wp * uu, wp * w
                        for r in range(GEO):
                            row = r * (GEO + d)
                            vr = v[r]
                            for q in range(r, GEO):
                                acc[row + q] += wuu * vr * v[q]
                            for ch in range(d):
                                acc[row + GEO + ch] += ww * vr * u[ch]
                    acc[row_len - 1] += wp * w * w
                for a in range(row_len):
                    buf[sl, g, a] += acc[a]
    return _sum_slices(buf)
