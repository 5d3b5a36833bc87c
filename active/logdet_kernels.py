"""Compiled (numba) per-block log-det gains and commits over the Gaussians a view sees, float64 arithmetic.

A view's information enters as a factor, H_v,i = R_i R_i^T with R_i [P, r] lower trapezoidal and packed row by row
(`active.logdet.ViewFactors`, `active.trapezoid`), and the running information A_i = L_i L_i^T by its Cholesky
factor L_i [P, P]. Per visible block b (Gaussian i = idx[b]):

    Y = L_i^-1 R_i                       forward substitution, P^2 r / 2 multiply-adds
    gain term = logdet(I_r + Y^T Y)      Sylvester: = logdet(I_P + L^-1 H L^-T); Cholesky of an r x r matrix whose
                                         eigenvalues are >= 1, so it cannot fail
    commit: C C^T = I_P + Y Y^T,  L_i <- L_i C

Each term is clamped at 0 (its exact value is >= 0; roundoff can leave -1e-16) and a commit skips the blocks whose
term is 0, so logdet(A) grows by exactly the sum of the clamped terms the gain reported. The blocks are split into
one contiguous slice per thread with its scratch arrays allocated once. `active.logdet` holds the torch twin
(`factor_gain_terms_torch`, `factor_commit_torch`) that the tests compare with these kernels.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(inline="always", cache=True)
def _row_start(k, r):
    """Offset of row k in a packed lower-trapezoidal factor with r columns (`active.trapezoid.row_start`)."""
    return k * (k + 1) // 2 if k <= r else r * (r + 1) // 2 + (k - r) * r


@njit(inline="always", cache=True)
def _whiten(chol, i, packed, b, r, y):
    """y [P, r] <- L_i^-1 R_b by forward substitution, R_b lower trapezoidal and packed. y must come zero-filled
    (np.zeros, once per thread): its entries above the trapezoid are never written and stay 0, so the loops keep the
    full width r, which vectorises better than the trapezoid's shorter rows."""
    p = chol.shape[1]
    for k in range(p):
        inv = 1.0 / chol[i, k, k]
        width, start = min(k + 1, r), _row_start(k, r)
        for c in range(width):  # y[k, width:] is 0 from the caller's np.zeros and stays 0: y[j, width:] = 0, j < k
            y[k, c] = packed[b, start + c]
        for j in range(k):
            ljk = chol[i, k, j]
            for c in range(r):
                y[k, c] -= ljk * y[j, c]
        for c in range(r):
            y[k, c] *= inv


@njit(inline="always", cache=True)
def _logdet_spd(m, n):
    """In-place Cholesky of the leading n x n of the symmetric m (lower triangle used); returns log det, or -inf when
    a pivot is not positive."""
    total = 0.0
    for k in range(n):
        d = m[k, k]
        for j in range(k):
            d -= m[k, j] * m[k, j]
        if not d > 0.0:
            return -math.inf
        d = math.sqrt(d)
        m[k, k] = d
        total += math.log(d)
        inv = 1.0 / d
        for i in range(k + 1, n):
            s = m[i, k]
            for j in range(k):
                s -= m[i, j] * m[k, j]
            m[i, k] = s * inv
    return 2.0 * total


@njit(parallel=True, cache=True)
def gain_terms(chol, indices, packed, r, num_slices):
    """Per visible block logdet(I + L^-1 R R^T L^-T), clamped at 0.

    Args:
        chol: Cholesky factors L of the running information, float64. [N, P, P]
        indices: the Gaussian of each visible block, int64. [n]
        packed: R of each visible block, lower trapezoidal [P, r] packed row by row, float32 or float64. [n, m]
        r: the factors' column count.
        num_slices: contiguous slices of blocks, one per thread.
    Returns:
        terms, float64. [n]
    """
    n, p = packed.shape[0], chol.shape[1]
    terms = np.zeros(n)
    per = (n + num_slices - 1) // num_slices
    for s in prange(num_slices):
        y = np.zeros((p, r))  # entries above the trapezoid stay 0 (`_whiten`)
        g = np.empty((r, r))
        for b in range(s * per, min(n, (s + 1) * per)):
            _whiten(chol, indices[b], packed, b, r, y)
            for a in range(r):  # lower triangle of I + Y^T Y
                for c in range(a + 1):
                    acc = 0.0
                    for k in range(p):
                        acc += y[k, a] * y[k, c]
                    g[a, c] = acc
                g[a, a] += 1.0
            terms[b] = max(_logdet_spd(g, r), 0.0)
    return terms


@njit(parallel=True, cache=True)
def commit(chol, indices, packed, r, num_slices):
    """L_i <- L_i C with C C^T = I + Y Y^T, Y = L_i^-1 R, in place on `chol` [N, P, P] for the visible blocks whose
    clamped term (the logdet of C C^T) is > 0; returns the terms [n] float64 (0 where skipped). Arguments as
    `gain_terms`."""
    n, p = packed.shape[0], chol.shape[1]
    terms = np.zeros(n)
    per = (n + num_slices - 1) // num_slices
    for s in prange(num_slices):
        y = np.zeros((p, r))  # entries above the trapezoid stay 0 (`_whiten`)
        m = np.empty((p, p))
        out = np.empty((p, p))
        for b in range(s * per, min(n, (s + 1) * per)):
            i = indices[b]
            _whiten(chol, i, packed, b, r, y)
            for a in range(p):  # lower triangle of I + Y Y^T
                for c in range(a + 1):
                    acc = 0.0
                    for k in range(r):
                        acc += y[a, k] * y[c, k]
                    m[a, c] = acc
                m[a, a] += 1.0
            term = _logdet_spd(m, p)
            if not term > 0.0:
                continue
            terms[b] = term
            for a in range(p):  # L C, both lower triangular
                for c in range(a + 1):
                    acc = 0.0
                    for k in range(c, a + 1):
                        acc += chol[i, a, k] * m[k, c]
                    out[a, c] = acc
            for a in range(p):
                for c in range(a + 1):
                    chol[i, a, c] = out[a, c]
    return terms


LQ_LANES = 8  # blocks made lower trapezoidal together, one per float64 SIMD lane (AVX-512; two AVX2 vectors)


@njit(inline="always", cache=True)
def _lower_trapezoid_lanes(lanes, v, s, scale, alpha):
    """For each lane l: R_l <- R_l Q_l with Q_l orthogonal (Householder reflections from the right) so that
    R_l[k, c] = 0 for c > k: the LQ factorisation's L, with the same R_l R_l^T. Branch-free over the lanes (a zero
    row leaves its reflection the identity), so every inner loop runs over the LQ_LANES lanes.

    Args:
        lanes: R_l transposed, lanes[c, row, l] = R_l[row, c], float64, in place. [A, P, LQ_LANES]
        v: scratch, the Householder vectors. [A, LQ_LANES]
        s, scale, alpha: scratch. [LQ_LANES]
    """
    a, p = lanes.shape[0], lanes.shape[1]
    for k in range(min(p, a)):
        for l in range(LQ_LANES):
            s[l] = 0.0
        for c in range(k, a):  # |R_l[k, k:]|^2
            for l in range(LQ_LANES):
                s[l] += lanes[c, k, l] * lanes[c, k, l]
        for l in range(LQ_LANES):
            x0 = lanes[k, k, l]
            alpha[l] = math.copysign(math.sqrt(s[l]), -x0)  # the sign that avoids cancellation in v[k]
            v[k, l] = x0 - alpha[l]
            norm_v2 = 2.0 * s[l] - 2.0 * x0 * alpha[l]  # |v|^2
            scale[l] = 2.0 / norm_v2 if norm_v2 > 0.0 else 0.0
            lanes[k, k, l] = alpha[l]  # what the reflection makes of row k, exactly
        for c in range(k + 1, a):
            for l in range(LQ_LANES):
                v[c, l] = lanes[c, k, l]
                lanes[c, k, l] = 0.0
        for row in range(k + 1, p):  # R_l[row, k:] -= (2 / |v|^2) (R_l[row, k:] . v) v
            for l in range(LQ_LANES):
                s[l] = 0.0
            for c in range(k, a):
                for l in range(LQ_LANES):
                    s[l] += lanes[c, row, l] * v[c, l]
            for l in range(LQ_LANES):
                s[l] *= scale[l]
            for c in range(k, a):
                for l in range(LQ_LANES):
                    lanes[c, row, l] -= s[l] * v[c, l]


PIVOT_TOLERANCE = 2.220446049250313e-16  # float64 epsilon: a pivot <= A eps of the unit-diagonal S ends the factorisation


@njit(inline="always", cache=True)
def _attribute_root(gram, jac, b, scale, tol, w, c, perm, root_diag, inv_root, root_t):
    """Rows 0 .. rank-1 of R_b^T = scale C_G^T J_b into root_t [A, P] (pivoted Cholesky of the equilibrated Gram, as
    `gram_root_factors` describes); returns the rank. Scratch w, c [A, A], perm, root_diag, inv_root [A]."""
    a, p = jac.shape[1], jac.shape[2]
    for i in range(a):  # equilibrate: S = D^-1/2 G D^-1/2 has a unit diagonal (attributes differ in units)
        perm[i] = i
        root_diag[i] = math.sqrt(gram[b, i, i]) if gram[b, i, i] > 0.0 else 0.0
        inv_root[i] = 1.0 / root_diag[i] if root_diag[i] > 0.0 else 0.0
    for i in range(a):
        for j in range(a):
            w[i, j] = gram[b, i, j] * inv_root[i] * inv_root[j]
    rank = 0
    for k in range(a):
        q, best = k, w[k, k]
        for i in range(k + 1, a):
            if w[i, i] > best:
                q, best = i, w[i, i]
        if not best > tol:
            break
        if q != k:  # symmetric swap of rows and columns k, q; the rows of C computed so far follow
            for j in range(a):
                w[k, j], w[q, j] = w[q, j], w[k, j]
            for j in range(a):
                w[j, k], w[j, q] = w[j, q], w[j, k]
            for j in range(k):
                c[k, j], c[q, j] = c[q, j], c[k, j]
            perm[k], perm[q] = perm[q], perm[k]
        d = math.sqrt(w[k, k])
        c[k, k] = d
        for i in range(k + 1, a):
            c[i, k] = w[i, k] / d
        for i in range(k + 1, a):  # Schur complement
            for j in range(k + 1, i + 1):
                w[i, j] -= c[i, k] * c[j, k]
                w[j, i] = w[i, j]
        rank = k + 1
    for k in range(rank):  # R^T = scale C_G^T J, C_G = D^1/2 Pi C: row k of R^T over contiguous rows of J
        for row in range(p):
            root_t[k, row] = 0.0
        for i in range(k, a):  # C's row i is attribute perm[i]
            f = scale * c[i, k] * root_diag[perm[i]]
            for row in range(p):
                root_t[k, row] += f * jac[b, perm[i], row]
    return rank


@njit(parallel=True, cache=True)
def gram_root_factors(gram, jac, scale, num_slices, out):
    """R_b = scale J_b^T C_b [P, A] with C_b C_b^T the PSD part of the attribute Gram G_b, by pivoted Cholesky.

    G_b is first equilibrated, S = D^-1/2 G_b D^-1/2 with D = diag(G_b) (the nine attributes differ by orders of
    magnitude in their units; attributes with a zero diagonal drop out), then factored by Cholesky with diagonal
    pivoting (largest remaining diagonal first), stopping at rank k when every remaining pivot is <= A eps, LAPACK
    pstrf's default tolerance: what is dropped is the roundoff-level (possibly negative) part of a Gram that is PSD in
    exact arithmetic, as the eigen-clamping twin (`active.logdet.gram_root_factors_torch`, on the same S) drops its
    negative eigenvalues. C_b = D^1/2 Pi C_S. Its columns are another orthonormal mix of those of the eigen root, so
    R_b R_b^T (all a gain uses) agrees with the twin to roundoff.

    Args:
        gram: G, float64. [n, A, A]
        jac: projection Jacobian d a / d theta, float64. [n, A, P]
        scale: 1 / sigma.
        num_slices: contiguous slices of blocks, one per thread.
        out: where R goes, lower trapezoidal (Householder LQ, `_lower_trapezoid_lanes`) and packed row by row
            (`active.trapezoid`), float64 or float32 (computed in float64, rounded once when stored). [n, m]
    Returns:
        out: R (columns past the rank are 0), every entry written by the thread that owns the block.
    """
    n, a, p = jac.shape
    per = (n + num_slices - 1) // num_slices
    tol = a * PIVOT_TOLERANCE
    for s in prange(num_slices):
        w = np.empty((a, a))
        c = np.empty((a, a))  # entries (i, k), k <= i, k < rank are written before they are read
        root_t = np.empty((a, p))  # R^T of one block, rows past its rank unwritten
        lanes = np.empty((a, p, LQ_LANES))  # R^T of LQ_LANES blocks
        ranks = np.zeros(LQ_LANES, np.int64)
        v = np.empty((a, LQ_LANES))
        s_lane, scale_lane, alpha_lane = np.empty(LQ_LANES), np.empty(LQ_LANES), np.empty(LQ_LANES)
        perm = np.empty(a, np.int64)
        root_diag = np.empty(a)
        inv_root = np.empty(a)
        end = min(n, (s + 1) * per)
        for first in range(s * per, end, LQ_LANES):
            count = min(LQ_LANES, end - first)
            for l in range(LQ_LANES):  # lanes past the slice's end hold zeros (their reflections are identities)
                ranks[l] = _attribute_root(gram, jac, first + l, scale, tol, w, c, perm, root_diag, inv_root,
                                           root_t) if l < count else 0
                for k in range(a):
                    for row in range(p):
                        lanes[k, row, l] = root_t[k, row] if k < ranks[l] else 0.0
            _lower_trapezoid_lanes(lanes, v, s_lane, scale_lane, alpha_lane)
            for l in range(count):
                for row in range(p):  # packed row by row; columns past the rank are 0
                    start = _row_start(row, a)
                    for k in range(min(row + 1, a)):
                        out[first + l, start + k] = lanes[k, row, l] if k < ranks[l] else 0.0
    return out
