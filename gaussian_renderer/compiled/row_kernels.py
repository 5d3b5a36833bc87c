"""Row-vectorised numba kernels: forward compositing, its backward, and the Fisher moment sums (`gram`).

Same tiles, lists, pixel boxes and compositing rules as `kernels` (its module docstring), but each pair's box is
handed to a separate, non-inlined function (`_forward_box`, `_gram_band`, `_backward_band`) whose loops LLVM turns
into SIMD code (4 float64 lanes): every test is a select instead of a branch, so padding lanes and the lanes a test
rejects are computed, then discarded. The forward loops over each box row, rounded up to a multiple of `LANES`, in
padded tile rows (tile_size + LANES long, so a rounded-up row never reaches the next one). The replays (Gram,
backward), whose per-lane work is longer, keep their tile state row-major with the tile's width as stride and make
each pass over a pair's *band*: the full-width tile rows its box spans, one contiguous run of lanes, the columns
outside the box rejected like any other failed test. A box row is ~12 pixels: a loop per row paid its set-up and
scalar remainder per row, and copying the box into contiguous lanes first (stop 37) paid a copy per row; the band
computes ~30 % more lanes and does neither. For all of them:

- exp comes from `exp_neg`, a polynomial that vectorises (numba's exp is a libm call that does not);
- the numpy error model (a division by zero gives inf rather than raising, which would be a branch);
- `not (x > y)` rather than `x <= y` wherever the scalar kernels skipped on a comparison, so NaN inputs still take
  the path that carries them into the image.

Speed against the scalar kernels they replaced: docs/performance.md#row-vectorised-kernels.
The torch path (`gaussian_renderer.rasterize`, `fisher_partials`) is the twin these are tested against.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from gaussian_renderer.compiled.kernels import GEO, NUM_MOMENTS, _pair_box, _sum_slices

# The forward's box rows are rounded up to a multiple of LANES: the vector loops step by 2 x 4 float64 lanes, so a
# row of 4 or 12 would leave 4 lanes to the scalar remainder (forward 1.12x against 4)
LANES = 8
EXP_SQUARINGS = 6  # exp(x) = p(x / 2^6)^(2^6): the Taylor polynomial p stays within |r| <= 0.35 for x >= -22.1
EXP_MIN = -22.0  # below this `exp_neg` is clamped (RasterSettings keeps alpha_min >= 1e-9 > e^-22 / 1)
_C = tuple(1.0 / math.factorial(i) for i in range(14))  # Taylor coefficients of exp to degree 13


@njit(inline="always", cache=True)
def exp_neg(x):
    """exp(x) for EXP_MIN <= x <= 0, relative error ~1e-14 (degree-13 Taylor at x / 64, Estrin's scheme, then 6
    squarings); NaN gives NaN. Branch-free, so a loop calling it vectorises."""
    r = x * (1.0 / 64.0)
    r2 = r * r
    r4 = r2 * r2
    q0 = (_C[0] + _C[1] * r) + (_C[2] + _C[3] * r) * r2
    q1 = (_C[4] + _C[5] * r) + (_C[6] + _C[7] * r) * r2
    q2 = (_C[8] + _C[9] * r) + (_C[10] + _C[11] * r) * r2
    q3 = _C[12] + _C[13] * r
    p = (q0 + q1 * r4) + (q2 + q3 * r4) * (r4 * r4)
    for _ in range(EXP_SQUARINGS):
        p = p * p
    return p


@njit(inline="always", cache=True)
def _alpha_lane(dx, dy, ca, cb, cc, o, cut, alpha_min, alpha_max):
    """(gauss, alpha, hit, unclamped) of a pair at one pixel: the compositing tests of `kernels` as selects."""
    power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
    gauss = exp_neg(EXP_MIN if power < EXP_MIN else power)
    raw = o * gauss
    alpha = alpha_max if raw > alpha_max else raw
    hit = (not power > 0.0) & (not power < cut) & (not alpha < alpha_min) & (alpha != 0.0)
    return gauss, alpha, hit, raw < alpha_max


@njit(inline="always", cache=True)
def _box_layout(x_lo, x_hi, y_lo, y_hi, stride):
    """A pair's box in the padded tile rows: (a0, rows, stride, n, m) = the first pixel's index, the row count, the
    row stride, a row's pixel count and that rounded up to LANES; unsigned, so the indices the box functions build
    from them need no negative-index wraparound, which would stop the vectoriser."""
    n = np.uint64(x_hi - x_lo + 1)
    m = (n + np.uint64(LANES - 1)) // np.uint64(LANES) * np.uint64(LANES)
    return np.uint64(y_lo * stride + x_lo), np.uint64(y_hi - y_lo + 1), np.uint64(stride), n, m


@njit(fastmath={"contract"}, error_model="numpy", inline="never", cache=True)
def _forward_box(trans, live, last, weight, color, cg, a0, rows, stride, n, m, x0, pos, mx, dy0, ca, cb, cc, o, cut,
                 alpha_min, alpha_max, trans_min):
    """Composite one pair over its box: `rows` rows of n pixels, the first starting at padded index a0 (m = n
    rounded up to LANES; x0, dy0 = the first pixel's centre in the tile, its y offset from the mean). Updates
    trans, live (1 / 0), last, color [D, *]; returns how many pixels stopped. weight [m]: scratch."""
    stopped = 0
    for r in range(rows):
        a = a0 + r * stride
        dy = dy0 + np.float64(r)
        for i in range(m):
            j = a + i
            _, alpha, hit, _ = _alpha_lane(np.float64(i) + x0 - mx, dy, ca, cb, cc, o, cut, alpha_min, alpha_max)
            hit = hit & (i < n) & (live[j] > 0.0)
            tp = trans[j]
            test = tp * (1.0 - alpha)
            stop = hit & (test < trans_min)
            take = hit & (not test < trans_min)
            weight[i] = alpha * tp if take else 0.0
            trans[j] = test if take else tp
            live[j] = 0.0 if stop else live[j]
            last[j] = pos if take else last[j]
            stopped += 1 if stop else 0
        for ch in range(cg.shape[0]):
            c = cg[ch]
            for i in range(m):
                color[ch, a + i] += weight[i] * c
    return stopped


@njit(parallel=True, cache=True)
def forward(offsets, ids, rects, geom, colors, background, width, height, tile_size, tiles_x, alpha_min, alpha_max,
            trans_min, image, trans_out, last_out, num_slices):
    """Front-to-back compositing, row-vectorised. Writes image [D, H, W] (background included),
    trans_out [H, W] and last_out [H, W] (int32), as the torch path does. Tiles are interleaved over `num_slices`
    threads, as in the replays: a plain prange hands each thread a contiguous half of the image, and the halves of a
    scene rarely hold the same number of pairs (garden: 252k and 365k)."""
    num_tiles = offsets.shape[0] - 1
    d = colors.shape[1]
    stride = tile_size + LANES
    num_px = tile_size * stride
    for sl in prange(num_slices):  # interleaved tiles
        for t in range(sl, num_tiles, num_slices):
            px0, py0 = (t % tiles_x) * tile_size, (t // tiles_x) * tile_size
            trans = np.ones(num_px)
            live = np.zeros(num_px)  # 1.0 while a pixel composites, 0.0 once finished or outside the image
            color = np.zeros((d, num_px))
            last = np.zeros(num_px, np.int32)
            weight = np.empty(stride)
            remaining = 0
            for y in range(min(tile_size, height - py0)):
                for x in range(min(tile_size, width - px0)):
                    live[y * stride + x] = 1.0
                    remaining += 1
            start, end = offsets[t], offsets[t + 1]
            for k in range(start, end):
                if remaining == 0:
                    break
                g = ids[k]
                x_lo, x_hi, y_lo, y_hi = _pair_box(geom, rects, g, px0, py0, tile_size)
                if x_hi < x_lo or y_hi < y_lo:  # the reach box misses the tile
                    continue
                mx, my = geom[g, 0] - px0, geom[g, 1] - py0
                a0, rows, step, n, m = _box_layout(x_lo, x_hi, y_lo, y_hi, stride)
                remaining -= _forward_box(trans, live, last, weight, color, colors[g], a0, rows, step, n, m,
                                          x_lo + 0.5, np.int32(k - start + 1), mx, y_lo + 0.5 - my, geom[g, 2],
                                          geom[g, 3], geom[g, 4], geom[g, 5], geom[g, 6], alpha_min, alpha_max,
                                          trans_min)
            for y in range(min(tile_size, height - py0)):
                for x in range(min(tile_size, width - px0)):
                    p = y * stride + x
                    for ch in range(d):
                        image[ch, py0 + y, px0 + x] = color[ch, p] + trans[p] * background[ch]
                    trans_out[py0 + y, px0 + x] = trans[p]
                    last_out[py0 + y, px0 + x] = last[p]


# The replays' tile state (`_band_lanes`): a lane per pixel of the tile, row-major with the tile's width as stride,
# so the rows y_lo to y_hi of a pair's box are one contiguous run of lanes, a *band*. Rows: the pixel's centre in the
# tile, its transmittance, last (as a float: 0 outside the image), pixel weight (Gram); per-lane results of a pair,
# the pair's tests folded into them (w = 0 where it does not contribute, alpha / q / s = 0 where alpha is clamped
# too: no flag rows to store and reload); the colour behind in the backward's form (g . B, one row); then D rows of
# colour behind (Gram) or loss gradient (backward).
(LANE_X, LANE_Y, LANE_TRANS, LANE_LAST, LANE_WPIX, LANE_Q, LANE_SA, LANE_INV, LANE_FRONT, LANE_W, LANE_U2,
 LANE_GAUSS, LANE_GC, LANE_ALPHA, LANE_BEHIND) = range(15)
LANE_ROWS = 15


@njit(inline="always", cache=True)
def _band_lanes(tile_size, channels):
    """A slice's replay state [LANE_ROWS + channels, tile_size^2], LANE_X / LANE_Y filled (pixel centres)."""
    lanes = np.zeros((LANE_ROWS + channels, tile_size * tile_size))
    for i in range(tile_size * tile_size):
        lanes[LANE_X, i] = (i % tile_size) + 0.5
        lanes[LANE_Y, i] = (i // tile_size) + 0.5
    return lanes


@njit(inline="always", cache=True)
def _load_band_tile(px0, py0, width, height, tile_size, trans_final, last_in, lanes):
    """LANE_TRANS / LANE_LAST of the tile at (px0, py0) from the forward pass (last = 0 outside the image); returns
    the tile's longest replay (max last)."""
    lanes[LANE_LAST, :] = 0.0
    longest = 0
    for y in range(min(tile_size, height - py0)):
        for x in range(min(tile_size, width - px0)):
            p = y * tile_size + x
            lanes[LANE_TRANS, p] = trans_final[py0 + y, px0 + x]
            lanes[LANE_LAST, p] = last_in[py0 + y, px0 + x]
            longest = max(longest, last_in[py0 + y, px0 + x])
    return longest


@njit(inline="always", cache=True)
def _band(y_lo, y_hi, tile_size):
    """The lanes [lo, hi) of box rows y_lo..y_hi, unsigned: a signed index gets numba's negative-index wraparound,
    which stops the vectoriser."""
    return np.uint64(y_lo * tile_size), np.uint64((y_hi + 1) * tile_size)


@njit(inline="always", cache=True)
def _replay_lane(lanes, i, xl, xr, pos, mx, my, ca, cb, cc, o, cut, alpha_min, alpha_max):
    """(gauss, alpha, hit, unclamped) of a pair at lane i of its band: `_alpha_lane`'s tests, and the pixel inside
    the box's columns (xl < x + 0.5 < xr) and before its last contributor (pos < last)."""
    x = lanes[LANE_X, i]
    gauss, alpha, hit, unclamped = _alpha_lane(x - mx, lanes[LANE_Y, i] - my, ca, cb, cc, o, cut, alpha_min, alpha_max)
    hit = hit & (x > xl) & (x < xr) & (pos < lanes[LANE_LAST, i])
    return gauss, alpha, hit, unclamped


@njit(fastmath={"contract", "reassoc"}, error_model="numpy", inline="never", cache=True)
def _gram_band(lanes, lo, hi, xl, xr, cg, pos, mx, my, ca, cb, cc, o, cut, alpha_min, alpha_max, acc):
    """One pair's replay over its band, lanes [lo, hi) (`_band`), back to front (see `gram`), in passes: alpha and
    the front transmittance (written to LANE_TRANS where the pair contributes); per three channels
    (`_gram_channels`) u, |u|^2, the cross sums and the colour behind; the moments. Lanes outside the box's columns
    xl < x < xr are rejected like every other failed test. The tests are folded into the stored values (w = 0 where
    the pair does not contribute, q = s = 0 where alpha is clamped too), which the later passes select on rather
    than on stored flags. cg [D], D a multiple of 3. Adds the pair's sums to acc in `gram`'s order."""
    d = cg.shape[0]
    ww = 0.0
    for i in range(lo, hi):
        _, alpha, hit, unclamped = _replay_lane(lanes, i, xl, xr, pos, mx, my, ca, cb, cc, o, cut, alpha_min,
                                                alpha_max)
        inv = 1.0 / (1.0 - alpha)
        t_front = lanes[LANE_TRANS, i] * inv
        w = alpha * t_front
        wp = lanes[LANE_WPIX, i]
        on = hit & unclamped
        lanes[LANE_Q, i] = wp * w * alpha if on else 0.0
        lanes[LANE_SA, i] = wp * alpha * alpha if on else 0.0
        lanes[LANE_INV, i] = inv
        lanes[LANE_FRONT, i] = t_front
        lanes[LANE_W, i] = w if hit else 0.0
        lanes[LANE_U2, i] = 0.0
        lanes[LANE_TRANS, i] = t_front if hit else lanes[LANE_TRANS, i]
        ww += wp * w * w if hit else 0.0
    acc[NUM_MOMENTS + GEO * d] += ww
    for ch in range(0, d, 3):
        _gram_channels(lanes, lo, hi, cg, ch, mx, my, acc)
    m0 = m1 = m2 = m3 = m4 = m5 = m6 = m7 = m8 = m9 = m10 = m11 = m12 = m13 = m14 = 0.0
    for i in range(lo, hi):
        dx, dy = lanes[LANE_X, i] - mx, lanes[LANE_Y, i] - my
        sa = lanes[LANE_SA, i]
        s = sa * lanes[LANE_U2, i] if sa != 0.0 else 0.0
        xx, xy, yy = dx * dx, dx * dy, dy * dy
        m0 += s
        m1 += s * dx
        m2 += s * dy
        m3 += s * xx
        m4 += s * xy
        m5 += s * yy
        m6 += s * xx * dx
        m7 += s * xx * dy
        m8 += s * dx * yy
        m9 += s * yy * dy
        m10 += s * xx * xx
        m11 += s * xx * xy
        m12 += s * xx * yy
        m13 += s * xy * yy
        m14 += s * yy * yy
    acc[0] += m0
    acc[1] += m1
    acc[2] += m2
    acc[3] += m3
    acc[4] += m4
    acc[5] += m5
    acc[6] += m6
    acc[7] += m7
    acc[8] += m8
    acc[9] += m9
    acc[10] += m10
    acc[11] += m11
    acc[12] += m12
    acc[13] += m13
    acc[14] += m14


@njit(fastmath={"contract", "reassoc"}, error_model="numpy", inline="always", cache=True)
def _gram_channels(lanes, lo, hi, cg, ch, mx, my, acc):
    """`_gram_band`'s pass over channels ch, ch + 1, ch + 2 at once (18 sums: one loop per channel recomputed dx,
    dy and reloaded the pair's lanes three times, 1.08x): u = c T - B / (1 - alpha) per channel, |u|^2 added to
    LANE_U2, the cross sums q u m (m = x, y, xx, xy, yy, 1) into acc, the pair's colour added to the colour behind."""
    d = cg.shape[0]
    c0, c1, c2 = cg[ch], cg[ch + 1], cg[ch + 2]
    b0, b1, b2 = LANE_ROWS + ch, LANE_ROWS + ch + 1, LANE_ROWS + ch + 2
    x0 = y0 = xx0 = xy0 = yy0 = one0 = 0.0
    x1 = y1 = xx1 = xy1 = yy1 = one1 = 0.0
    x2 = y2 = xx2 = xy2 = yy2 = one2 = 0.0
    for i in range(lo, hi):
        dx, dy = lanes[LANE_X, i] - mx, lanes[LANE_Y, i] - my
        front, inv, q, w = lanes[LANE_FRONT, i], lanes[LANE_INV, i], lanes[LANE_Q, i], lanes[LANE_W, i]
        u0 = c0 * front - lanes[b0, i] * inv
        u1 = c1 * front - lanes[b1, i] * inv
        u2 = c2 * front - lanes[b2, i] * inv
        lanes[LANE_U2, i] += u0 * u0 + u1 * u1 + u2 * u2
        q0 = q * u0 if q != 0.0 else 0.0
        q1 = q * u1 if q != 0.0 else 0.0
        q2 = q * u2 if q != 0.0 else 0.0
        xx, xy, yy = dx * dx, dx * dy, dy * dy
        x0 += q0 * dx
        y0 += q0 * dy
        xx0 += q0 * xx
        xy0 += q0 * xy
        yy0 += q0 * yy
        one0 += q0
        x1 += q1 * dx
        y1 += q1 * dy
        xx1 += q1 * xx
        xy1 += q1 * xy
        yy1 += q1 * yy
        one1 += q1
        x2 += q2 * dx
        y2 += q2 * dy
        xx2 += q2 * xx
        xy2 += q2 * xy
        yy2 += q2 * yy
        one2 += q2
        lanes[b0, i] += w * c0 if w != 0.0 else 0.0
        lanes[b1, i] += w * c1 if w != 0.0 else 0.0
        lanes[b2, i] += w * c2 if w != 0.0 else 0.0
    for k, (s0, s1, s2) in enumerate(((x0, x1, x2), (y0, y1, y2), (xx0, xx1, xx2), (xy0, xy1, xy2),
                                      (yy0, yy1, yy2), (one0, one1, one2))):
        acc[NUM_MOMENTS + k * d + ch] += s0
        acc[NUM_MOMENTS + k * d + ch + 1] += s1
        acc[NUM_MOMENTS + k * d + ch + 2] += s2


@njit(parallel=True, cache=True)
def gram(offsets, ids, rects, geom, colors, background, width, height, tile_size, tiles_x, alpha_min, alpha_max,
         trans_final, last_in, pixel_weights, num_slices):
    """Per-Gaussian moment sums for the attribute Gram, [N, 15 + 6 D + 1] (pixels p weighted by pixel_weights).

    Per pair: u = dC/dalpha [D] = c T - B / (1 - alpha) (B = colour behind, background included), w = alpha T,
    and where alpha is not clamped v = dalpha / d(geometry) = alpha L m with m = (dx, dy, dx^2, dx dy, dy^2, 1)
    and L a per-Gaussian constant (conic, 1 / opacity). So sum_p |u|^2 v v^T = L M L^T needs only the 15 moments
    of s = |u|^2 alpha^2 over dx, dy (1, dx, dy, dx^2, dx dy, dy^2, dx^3, dx^2 dy, dx dy^2, dy^3, dx^4, dx^3 dy,
    dx^2 dy^2, dx dy^3, dy^4), and sum_p w v u^T = L X with X [6, D] = sum_p w alpha m u^T (row-major); last,
    sum_p w^2. `kernels.assemble_gram` applies L once per Gaussian.
    """
    n, d = colors.shape
    dp = (d + 2) // 3 * 3  # `_gram_channels` takes three at a time: zero colour and background pad, sums dropped
    padded, padded_background = np.zeros((n, dp)), np.zeros(dp)
    padded[:, :d] = colors
    padded_background[:d] = background
    row_len = NUM_MOMENTS + GEO * dp + 1
    num_tiles = offsets.shape[0] - 1
    buf = np.zeros((num_slices, n, row_len))
    for sl in prange(num_slices):  # interleaved tiles, one buffer per slice
        lanes = _band_lanes(tile_size, dp)
        acc = np.empty(row_len)
        for t in range(sl, num_tiles, num_slices):
            px0, py0 = (t % tiles_x) * tile_size, (t // tiles_x) * tile_size
            longest = _load_band_tile(px0, py0, width, height, tile_size, trans_final, last_in, lanes)
            for y in range(min(tile_size, height - py0)):
                for x in range(min(tile_size, width - px0)):
                    p = y * tile_size + x
                    lanes[LANE_WPIX, p] = pixel_weights[py0 + y, px0 + x]
                    for ch in range(dp):
                        lanes[LANE_ROWS + ch, p] = lanes[LANE_TRANS, p] * padded_background[ch]
            start = offsets[t]
            for j in range(longest - 1, -1, -1):
                g = ids[start + j]
                x_lo, x_hi, y_lo, y_hi = _pair_box(geom, rects, g, px0, py0, tile_size)
                if x_hi < x_lo or y_hi < y_lo:  # the reach box misses the tile
                    continue
                lo, hi = _band(y_lo, y_hi, tile_size)
                acc[:] = 0.0
                _gram_band(lanes, lo, hi, float(x_lo), float(x_hi + 1), padded[g], float(j), geom[g, 0] - px0,
                           geom[g, 1] - py0, geom[g, 2], geom[g, 3], geom[g, 4], geom[g, 5], geom[g, 6], alpha_min,
                           alpha_max, acc)
                row = buf[sl, g]
                for k in range(row_len):
                    row[k] += acc[k]
    sums = _sum_slices(buf)
    if dp == d:
        return sums
    out = np.empty((n, NUM_MOMENTS + GEO * d + 1))  # the padding channels' cross sums dropped
    out[:, :NUM_MOMENTS] = sums[:, :NUM_MOMENTS]
    for k in range(GEO):
        out[:, NUM_MOMENTS + k * d:NUM_MOMENTS + (k + 1) * d] = sums[:, NUM_MOMENTS + k * dp:NUM_MOMENTS + k * dp + d]
    out[:, -1] = sums[:, -1]
    return out


@njit(fastmath={"contract", "reassoc"}, error_model="numpy", inline="never", cache=True)
def _backward_band(lanes, lo, hi, xl, xr, cg, pos, mx, my, ca, cb, cc, o, cut, alpha_min, alpha_max, acc):
    """One pair's gradient replay over its band, lanes [lo, hi), back to front (see `backward`), like `_gram_band`
    (the pixels' loss gradients in rows LANE_ROWS + channel): adds to acc [6 + D] the alpha-weighted dL/dalpha
    moments x, y, xx, xy, yy, the opacity sum and the colour gradient sum_p w g_p; steps LANE_TRANS / LANE_BEHIND to
    the front of the pair where it contributes."""
    d = cg.shape[0]
    for i in range(lo, hi):
        gauss, alpha, hit, unclamped = _replay_lane(lanes, i, xl, xr, pos, mx, my, ca, cb, cc, o, cut, alpha_min,
                                                    alpha_max)
        inv = 1.0 / (1.0 - alpha)
        on = hit & unclamped
        lanes[LANE_ALPHA, i] = alpha if on else 0.0
        lanes[LANE_GAUSS, i] = gauss if on else 0.0
        lanes[LANE_INV, i] = inv
        lanes[LANE_W, i] = alpha * lanes[LANE_TRANS, i] * inv if hit else 0.0
        lanes[LANE_GC, i] = 0.0
    for ch in range(d):
        c, b = cg[ch], LANE_ROWS + ch
        col = 0.0
        for i in range(lo, hi):
            gp, w = lanes[b, i], lanes[LANE_W, i]
            lanes[LANE_GC, i] += gp * c
            col += w * gp if w != 0.0 else 0.0
        acc[GEO + ch] += col
    s_x = s_y = s_xx = s_xy = s_yy = s_o = 0.0
    for i in range(lo, hi):
        dx, dy = lanes[LANE_X, i] - mx, lanes[LANE_Y, i] - my
        inv, gc, trans, w = lanes[LANE_INV, i], lanes[LANE_GC, i], lanes[LANE_TRANS, i], lanes[LANE_W, i]
        grad = (gc * trans - lanes[LANE_BEHIND, i]) * inv  # dL/dalpha
        alpha = lanes[LANE_ALPHA, i]
        on = alpha != 0.0
        la = grad * alpha if on else 0.0
        lx, ly = la * dx, la * dy
        s_x += lx
        s_y += ly
        s_xx += lx * dx
        s_xy += lx * dy
        s_yy += ly * dy
        s_o += grad * lanes[LANE_GAUSS, i] if on else 0.0
        take = w != 0.0
        lanes[LANE_BEHIND, i] += w * gc if take else 0.0
        lanes[LANE_TRANS, i] = trans * inv if take else trans
    acc[0] += s_x
    acc[1] += s_y
    acc[2] += s_xx
    acc[3] += s_xy
    acc[4] += s_yy
    acc[5] += s_o


@njit(parallel=True, cache=True)
def backward(offsets, ids, rects, geom, colors, background, width, height, tile_size, tiles_x, alpha_min, alpha_max,
             trans_final, last_in, grad_image, grad_alpha, num_slices):
    """Back-to-front replay over bands. Returns per-Gaussian gradients [N, 6 + D]: mean x, y, conic a, b, c,
    opacity, colour[D] (for loss gradients grad_image [D, H, W] and grad_alpha [H, W])."""
    n, d = colors.shape
    num_tiles = offsets.shape[0] - 1
    buf = np.zeros((num_slices, n, GEO + d))
    for sl in prange(num_slices):  # interleaved tiles, one gradient buffer per slice
        lanes = _band_lanes(tile_size, d)  # LANE_BEHIND: g . (colour behind the current pair) - dL/dalpha_out T_final
        acc = np.empty(GEO + d)
        for t in range(sl, num_tiles, num_slices):
            px0, py0 = (t % tiles_x) * tile_size, (t // tiles_x) * tile_size
            longest = _load_band_tile(px0, py0, width, height, tile_size, trans_final, last_in, lanes)
            for y in range(min(tile_size, height - py0)):
                for x in range(min(tile_size, width - px0)):
                    p = y * tile_size + x
                    gb = 0.0
                    for ch in range(d):
                        lanes[LANE_ROWS + ch, p] = grad_image[ch, py0 + y, px0 + x]
                        gb += grad_image[ch, py0 + y, px0 + x] * background[ch]
                    lanes[LANE_BEHIND, p] = lanes[LANE_TRANS, p] * (gb - grad_alpha[py0 + y, px0 + x])
            start = offsets[t]
            for j in range(longest - 1, -1, -1):
                g = ids[start + j]
                x_lo, x_hi, y_lo, y_hi = _pair_box(geom, rects, g, px0, py0, tile_size)
                if x_hi < x_lo or y_hi < y_lo:  # the reach box misses the tile
                    continue
                lo, hi = _band(y_lo, y_hi, tile_size)
                acc[:] = 0.0
                _backward_band(lanes, lo, hi, float(x_lo), float(x_hi + 1), colors[g], float(j), geom[g, 0] - px0,
                               geom[g, 1] - py0, geom[g, 2], geom[g, 3], geom[g, 4], geom[g, 5], geom[g, 6],
                               alpha_min, alpha_max, acc)
                ca, cb, cc = geom[g, 2], geom[g, 3], geom[g, 4]
                row = buf[sl, g]
                row[0] += ca * acc[0] + cb * acc[1]
                row[1] += cb * acc[0] + cc * acc[1]
                row[2] += -0.5 * acc[2]
                row[3] += -acc[3]
                row[4] += -0.5 * acc[4]
                row[5] += acc[5]
                for ch in range(d):
                    row[GEO + ch] += acc[GEO + ch]
    return _sum_slices(buf)
