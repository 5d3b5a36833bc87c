"""Row-vectorised numba kernels: forward compositing, its backward, and the Fisher moment sums (`gram`).

Same tiles, lists, pixel boxes and compositing rules as `kernels` (its module docstring), but each pair's box is
handed to a separate, non-inlined function (`_forward_box`, `_gram_box`, `_backward_box`) whose loops LLVM turns
into SIMD code (4 float64 lanes): every test is a select instead of a branch, so padding lanes and the lanes a test
rejects are computed, then discarded. The forward loops over each box row (rounded up to a multiple of `LANES`);
the replays (Gram, backward), whose per-lane work is longer, first copy the box into one contiguous run of lanes
(`_gather_box`: a box row is ~12 pixels, too short for a vector loop to pay for its set-up and scalar remainder),
make their passes over all of it, and write the updated transmittance and colour behind back. For that:

- tile state lives in padded rows (tile_size + LANES long), so a rounded-up row never reaches the next one;
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

# Box rows (forward) and gathered boxes (replays) are rounded up to a multiple of LANES: the vector loops step by
# 2 x 4 float64 lanes, so a row of 4 or 12 would leave 4 lanes to the scalar remainder (forward 1.12x against 4)
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


@njit(inline="always", cache=True)
def _load_replay_tile(px0, py0, width, height, tile_size, stride, trans_final, last_in, trans, last):
    """Fill trans / last (padded rows) of the tile at (px0, py0) from the forward pass, last = 0 outside the image;
    returns the tile's longest replay (max last)."""
    last[:] = 0
    longest = 0
    for y in range(min(tile_size, height - py0)):
        for x in range(min(tile_size, width - px0)):
            p = y * stride + x
            trans[p] = trans_final[py0 + y, px0 + x]
            last[p] = last_in[py0 + y, px0 + x]
            longest = max(longest, last[p])
    return longest


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
            trans_min, image, trans_out, last_out):
    """Front-to-back compositing, row-vectorised. Writes image [D, H, W] (background included),
    trans_out [H, W] and last_out [H, W] (int32), as the torch path does."""
    num_tiles = offsets.shape[0] - 1
    d = colors.shape[1]
    stride = tile_size + LANES
    num_px = tile_size * stride
    for t in prange(num_tiles):
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
            remaining -= _forward_box(trans, live, last, weight, color, colors[g], a0, rows, step, n, m, x_lo + 0.5,
                                      np.int32(k - start + 1), mx, y_lo + 0.5 - my, geom[g, 2], geom[g, 3], geom[g, 4],
                                      geom[g, 5], geom[g, 6], alpha_min, alpha_max, trans_min)
        for y in range(min(tile_size, height - py0)):
            for x in range(min(tile_size, width - px0)):
                p = y * stride + x
                for ch in range(d):
                    image[ch, py0 + y, px0 + x] = color[ch, p] + trans[p] * background[ch]
                trans_out[py0 + y, px0 + x] = trans[p]
                last_out[py0 + y, px0 + x] = last[p]


# rows of the box scratch (a lane per pixel of a pair's box, row-major, `_gather_box`): the pixel's offset from the
# mean, its transmittance, valid (1 / 0), pixel weight; what the kernels compute per lane; then D rows of colour
(BOX_DX, BOX_DY, BOX_TRANS, BOX_VALID, BOX_WPIX, BOX_HIT, BOX_ON, BOX_Q, BOX_SA, BOX_INV, BOX_FRONT, BOX_W, BOX_U2,
 BOX_GAUSS, BOX_GC, BOX_BEHIND, BOX_ALPHA) = range(17)
BOX_ROWS = 17


@njit(inline="always", cache=True)
def _gather_box(trans, a0, rows, stride, n, x0, mx, dy0, box):
    """Copy a pair's box (`rows` rows of n pixels from padded index a0, the first pixel x0 - mx, dy0 from the mean)
    into contiguous lanes of box: BOX_DX, BOX_DY, BOX_TRANS; the lanes after it up to a multiple of LANES get
    zeros there and in BOX_VALID. A box row is ~12 pixels: too short for a vector loop to pay for its set-up (alias
    checks) and scalar remainder, so the replays work on the box as one run of lanes. Returns the lane count
    (padding included)."""
    size = rows * n
    m = (size + np.uint64(LANES - 1)) // np.uint64(LANES) * np.uint64(LANES)
    for r in range(rows):
        a, k = a0 + r * stride, r * n
        dy = dy0 + np.float64(r)
        for i in range(n):  # one loop per row of box: each stays a plain vectorisable copy
            box[BOX_DX, k + i] = np.float64(i) + x0 - mx
        for i in range(n):
            box[BOX_DY, k + i] = dy
        for i in range(n):
            box[BOX_TRANS, k + i] = trans[a + i]
    for i in range(size, m):
        box[BOX_DX, i] = box[BOX_DY, i] = box[BOX_TRANS, i] = box[BOX_VALID, i] = 0.0
    return m


@njit(inline="always", cache=True)
def _gather_row(src, a0, rows, stride, n, m, box, dst):
    """Copy a box of the padded tile array src [*] into box row dst, as `_gather_box` lays it out (zero padding)."""
    for r in range(rows):
        a, k = a0 + r * stride, r * n
        for i in range(n):
            box[dst, k + i] = src[a + i]
    for i in range(rows * n, m):
        box[dst, i] = 0.0


@njit(inline="always", cache=True)
def _gather_valid(last, a0, rows, stride, n, pos, box):
    """BOX_VALID of a replay: 1 where the pair (at list position pos) is before the pixel's last contributor."""
    for r in range(rows):
        a, k = a0 + r * stride, r * n
        for i in range(n):
            box[BOX_VALID, k + i] = 1.0 if pos < last[a + i] else 0.0


@njit(inline="always", cache=True)
def _gather_replay(trans, last, extra, extra_row, channels, a0, rows, stride, n, x0, pos, mx, dy0, box):
    """A replay's box: `_gather_box`, BOX_VALID, one more tile array extra [*] into box row extra_row and channels
    [D, *] into rows BOX_ROWS + channel. Returns the lane count."""
    m = _gather_box(trans, a0, rows, stride, n, x0, mx, dy0, box)
    _gather_valid(last, a0, rows, stride, n, pos, box)
    _gather_row(extra, a0, rows, stride, n, m, box, extra_row)
    for ch in range(channels.shape[0]):
        _gather_row(channels[ch], a0, rows, stride, n, m, box, BOX_ROWS + ch)
    return m


@njit(inline="always", cache=True)
def _scatter_box(trans, behind, a0, rows, stride, n, box):
    """The Gram's write-back of a box: transmittance (front where hit) and colour behind to the padded tile rows."""
    d = behind.shape[0]
    for r in range(rows):
        a, k = a0 + r * stride, r * n
        for i in range(n):
            trans[a + i] = box[BOX_FRONT, k + i] if box[BOX_HIT, k + i] > 0.0 else trans[a + i]
        for ch in range(d):
            for i in range(n):
                behind[ch, a + i] = box[BOX_ROWS + ch, k + i]


@njit(fastmath={"contract", "reassoc"}, error_model="numpy", inline="never", cache=True)
def _gram_box(trans, last, behind, wpix, cg, a0, rows, stride, n, x0, pos, mx, dy0, ca, cb, cc, o, cut, alpha_min,
              alpha_max, box, acc):
    """One pair's replay over its box (`rows` rows of n pixels from padded index a0, the first pixel x0 - mx, dy0
    from the mean), back to front (see `gram`): gathered into one run of lanes (`_gather_box` says why), replayed in
    three passes over all of them (alpha and the front transmittance; per channel u, |u|^2, the colour behind and
    the cross sums; the moments), scattered back. Adds the pair's sums to acc in `gram`'s order."""
    d = cg.shape[0]
    m = _gather_replay(trans, last, wpix, BOX_WPIX, behind, a0, rows, stride, n, x0, pos, mx, dy0, box)
    ww = 0.0
    for i in range(m):
        _, alpha, hit, unclamped = _alpha_lane(box[BOX_DX, i], box[BOX_DY, i], ca, cb, cc, o, cut, alpha_min,
                                               alpha_max)
        hit = hit & (box[BOX_VALID, i] > 0.0)
        inv = 1.0 / (1.0 - alpha)
        t_front = box[BOX_TRANS, i] * inv
        w = alpha * t_front
        wp = box[BOX_WPIX, i]
        box[BOX_HIT, i] = 1.0 if hit else 0.0
        box[BOX_ON, i] = 1.0 if hit & unclamped else 0.0
        box[BOX_Q, i] = wp * w * alpha
        box[BOX_SA, i] = wp * alpha * alpha
        box[BOX_INV, i] = inv
        box[BOX_FRONT, i] = t_front
        box[BOX_W, i] = w
        box[BOX_U2, i] = 0.0
        ww += wp * w * w if hit else 0.0
    acc[NUM_MOMENTS + GEO * d] += ww
    for ch in range(d):  # X rows: x, y, xx, xy, yy, 1
        c = cg[ch]
        c_x = c_y = c_xx = c_xy = c_yy = c_1 = 0.0
        for i in range(m):
            dx, dy = box[BOX_DX, i], box[BOX_DY, i]
            u = c * box[BOX_FRONT, i] - box[BOX_ROWS + ch, i] * box[BOX_INV, i]
            box[BOX_U2, i] += u * u
            qu = box[BOX_Q, i] * u if box[BOX_ON, i] > 0.0 else 0.0
            c_x += qu * dx
            c_y += qu * dy
            c_xx += qu * dx * dx
            c_xy += qu * dx * dy
            c_yy += qu * dy * dy
            c_1 += qu
            box[BOX_ROWS + ch, i] += box[BOX_W, i] * c if box[BOX_HIT, i] > 0.0 else 0.0
        acc[NUM_MOMENTS + ch] += c_x
        acc[NUM_MOMENTS + d + ch] += c_y
        acc[NUM_MOMENTS + 2 * d + ch] += c_xx
        acc[NUM_MOMENTS + 3 * d + ch] += c_xy
        acc[NUM_MOMENTS + 4 * d + ch] += c_yy
        acc[NUM_MOMENTS + 5 * d + ch] += c_1
    m0 = m1 = m2 = m3 = m4 = m5 = m6 = m7 = m8 = m9 = m10 = m11 = m12 = m13 = m14 = 0.0
    for i in range(m):
        dx, dy = box[BOX_DX, i], box[BOX_DY, i]
        s = box[BOX_SA, i] * box[BOX_U2, i] if box[BOX_ON, i] > 0.0 else 0.0
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
    _scatter_box(trans, behind, a0, rows, stride, n, box)


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
    row_len = NUM_MOMENTS + GEO * d + 1
    num_tiles = offsets.shape[0] - 1
    stride = tile_size + LANES
    num_px = tile_size * stride
    buf = np.zeros((num_slices, n, row_len))
    for sl in prange(num_slices):  # interleaved tiles, one buffer per slice
        trans = np.ones(num_px)
        behind = np.zeros((d, num_px))
        wpix = np.zeros(num_px)
        last = np.zeros(num_px, np.int32)
        box = np.empty((BOX_ROWS + d, tile_size * tile_size + LANES))
        acc = np.empty(row_len)
        for t in range(sl, num_tiles, num_slices):
            px0, py0 = (t % tiles_x) * tile_size, (t // tiles_x) * tile_size
            longest = _load_replay_tile(px0, py0, width, height, tile_size, stride, trans_final, last_in, trans, last)
            for y in range(min(tile_size, height - py0)):
                for x in range(min(tile_size, width - px0)):
                    p = y * stride + x
                    wpix[p] = pixel_weights[py0 + y, px0 + x]
                    for ch in range(d):
                        behind[ch, p] = trans[p] * background[ch]
            start = offsets[t]
            for j in range(longest - 1, -1, -1):
                g = ids[start + j]
                x_lo, x_hi, y_lo, y_hi = _pair_box(geom, rects, g, px0, py0, tile_size)
                if x_hi < x_lo or y_hi < y_lo:  # the reach box misses the tile
                    continue
                mx, my = geom[g, 0] - px0, geom[g, 1] - py0
                a0, rows, step, cnt, _ = _box_layout(x_lo, x_hi, y_lo, y_hi, stride)
                acc[:] = 0.0
                _gram_box(trans, last, behind, wpix, colors[g], a0, rows, step, cnt, x_lo + 0.5, np.int32(j), mx,
                          y_lo + 0.5 - my, geom[g, 2], geom[g, 3], geom[g, 4], geom[g, 5], geom[g, 6], alpha_min,
                          alpha_max, box, acc)
                row = buf[sl, g]
                for k in range(row_len):
                    row[k] += acc[k]
    return _sum_slices(buf)


@njit(fastmath={"contract", "reassoc"}, error_model="numpy", inline="never", cache=True)
def _backward_box(trans, last, behind, gpix, cg, a0, rows, stride, n, x0, pos, mx, dy0, ca, cb, cc, o, cut, alpha_min,
                  alpha_max, box, acc):
    """One pair's gradient replay over its box, back to front (see `backward`), as one run of lanes like `_gram_box`
    (the pixels' loss gradients in rows BOX_ROWS + channel): adds to acc [6 + D] the alpha-weighted dL/dalpha
    moments x, y, xx, xy, yy, the opacity sum and the colour gradient sum_p w g_p; steps trans / behind [*] to the
    front of the pair where it contributes."""
    d = cg.shape[0]
    m = _gather_replay(trans, last, behind, BOX_BEHIND, gpix, a0, rows, stride, n, x0, pos, mx, dy0, box)
    for i in range(m):
        gauss, alpha, hit, unclamped = _alpha_lane(box[BOX_DX, i], box[BOX_DY, i], ca, cb, cc, o, cut, alpha_min,
                                                   alpha_max)
        hit = hit & (box[BOX_VALID, i] > 0.0)
        inv = 1.0 / (1.0 - alpha)
        box[BOX_HIT, i] = 1.0 if hit else 0.0
        box[BOX_ON, i] = 1.0 if hit & unclamped else 0.0
        box[BOX_ALPHA, i] = alpha
        box[BOX_GAUSS, i] = gauss
        box[BOX_INV, i] = inv
        box[BOX_W, i] = alpha * box[BOX_TRANS, i] * inv
        box[BOX_GC, i] = 0.0
    for ch in range(d):
        c = cg[ch]
        col = 0.0
        for i in range(m):
            gp = box[BOX_ROWS + ch, i]
            box[BOX_GC, i] += gp * c
            col += box[BOX_W, i] * gp if box[BOX_HIT, i] > 0.0 else 0.0
        acc[GEO + ch] += col
    s_x = s_y = s_xx = s_xy = s_yy = s_o = 0.0
    for i in range(m):
        dx, dy = box[BOX_DX, i], box[BOX_DY, i]
        grad = (box[BOX_GC, i] * box[BOX_TRANS, i] - box[BOX_BEHIND, i]) * box[BOX_INV, i]  # dL/dalpha
        on = box[BOX_ON, i] > 0.0
        la = grad * box[BOX_ALPHA, i] if on else 0.0
        lx, ly = la * dx, la * dy
        s_x += lx
        s_y += ly
        s_xx += lx * dx
        s_xy += lx * dy
        s_yy += ly * dy
        s_o += grad * box[BOX_GAUSS, i] if on else 0.0
    acc[0] += s_x
    acc[1] += s_y
    acc[2] += s_xx
    acc[3] += s_xy
    acc[4] += s_yy
    acc[5] += s_o
    for r in range(rows):
        a, k = a0 + r * stride, r * n
        for i in range(n):
            take = box[BOX_HIT, k + i] > 0.0
            behind[a + i] += box[BOX_W, k + i] * box[BOX_GC, k + i] if take else 0.0
        for i in range(n):
            take = box[BOX_HIT, k + i] > 0.0
            trans[a + i] = box[BOX_TRANS, k + i] * box[BOX_INV, k + i] if take else trans[a + i]


@njit(parallel=True, cache=True)
def backward(offsets, ids, rects, geom, colors, background, width, height, tile_size, tiles_x, alpha_min, alpha_max,
             trans_final, last_in, grad_image, grad_alpha, num_slices):
    """Back-to-front replay, row-vectorised. Returns per-Gaussian gradients [N, 6 + D]: mean x, y, conic a, b, c,
    opacity, colour[D] (for loss gradients grad_image [D, H, W] and grad_alpha [H, W])."""
    n, d = colors.shape
    num_tiles = offsets.shape[0] - 1
    stride = tile_size + LANES
    num_px = tile_size * stride
    buf = np.zeros((num_slices, n, GEO + d))
    for sl in prange(num_slices):  # interleaved tiles, one gradient buffer per slice
        trans = np.ones(num_px)
        behind = np.zeros(num_px)  # g . (colour behind the current pair) - dL/dalpha_out T_final
        gpix = np.zeros((d, num_px))
        last = np.zeros(num_px, np.int32)
        box = np.empty((BOX_ROWS + d, tile_size * tile_size + LANES))
        acc = np.empty(GEO + d)
        for t in range(sl, num_tiles, num_slices):
            px0, py0 = (t % tiles_x) * tile_size, (t // tiles_x) * tile_size
            longest = _load_replay_tile(px0, py0, width, height, tile_size, stride, trans_final, last_in, trans, last)
            for y in range(min(tile_size, height - py0)):
                for x in range(min(tile_size, width - px0)):
                    p = y * stride + x
                    gb = 0.0
                    for ch in range(d):
                        gpix[ch, p] = grad_image[ch, py0 + y, px0 + x]
                        gb += gpix[ch, p] * background[ch]
                    behind[p] = trans[p] * (gb - grad_alpha[py0 + y, px0 + x])
            start = offsets[t]
            for j in range(longest - 1, -1, -1):
                g = ids[start + j]
                x_lo, x_hi, y_lo, y_hi = _pair_box(geom, rects, g, px0, py0, tile_size)
                if x_hi < x_lo or y_hi < y_lo:  # the reach box misses the tile
                    continue
                mx, my = geom[g, 0] - px0, geom[g, 1] - py0
                a0, rows, step, cnt, _ = _box_layout(x_lo, x_hi, y_lo, y_hi, stride)
                acc[:] = 0.0
                _backward_box(trans, last, behind, gpix, colors[g], a0, rows, step, cnt, x_lo + 0.5, np.int32(j), mx,
                              y_lo + 0.5 - my, geom[g, 2], geom[g, 3], geom[g, 4], geom[g, 5], geom[g, 6], alpha_min,
                              alpha_max, box, acc)
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
