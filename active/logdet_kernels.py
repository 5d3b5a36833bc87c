"""Compiled (numba) per-block log-det gains and commits over the Gaussians a view sees, float64 arithmetic.

A view's information enters as a factor, H_v,i = R_i R_i^T with R_i [P, r] (`active.logdet.ViewFactors`), and the
running information A_i = L_i L_i^T by its Cholesky factor L_i [P, P]. Per visible block b (Gaussian i = idx[b]):

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
def _whiten(chol, i, factors, b, y):
    """y [P, r] <- L_i^-1 R_b by forward substitution (row by row, inner loop over the r columns)."""
    p, r = factors.shape[1], factors.shape[2]
    for k in range(p):
        inv = 1.0 / chol[i, k, k]
        for c in range(r):
            y[k, c] = factors[b, k, c]
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
def gain_terms(chol, indices, factors, num_slices):
    """Per visible block logdet(I + L^-1 R R^T L^-T), clamped at 0.

    Args:
        chol: Cholesky factors L of the running information, float64. [N, P, P]
        indices: the Gaussian of each visible block, int64. [n]
        factors: R of each visible block, float32 or float64. [n, P, r]
        num_slices: contiguous slices of blocks, one per thread.
    Returns:
        terms, float64. [n]
    """
    n, p, r = factors.shape
    terms = np.zeros(n)
    per = (n + num_slices - 1) // num_slices
    for s in prange(num_slices):
        y = np.empty((p, r))
        g = np.empty((r, r))
        for b in range(s * per, min(n, (s + 1) * per)):
            _whiten(chol, indices[b], factors, b, y)
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
def commit(chol, indices, factors, num_slices):
    """L_i <- L_i C with C C^T = I + Y Y^T, Y = L_i^-1 R, in place on `chol` [N, P, P] for the visible blocks whose
    clamped term (the logdet of C C^T) is > 0; returns the terms [n] float64 (0 where skipped)."""
    n, p, r = factors.shape
    terms = np.zeros(n)
    per = (n + num_slices - 1) // num_slices
    for s in prange(num_slices):
        y = np.empty((p, r))
        m = np.empty((p, p))
        out = np.empty((p, p))
        for b in range(s * per, min(n, (s + 1) * per)):
            i = indices[b]
            _whiten(chol, i, factors, b, y)
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


PIVOT_TOLERANCE = 2.220446049250313e-16  # float64 epsilon: a pivot <= A eps of the unit-diagonal S ends the factorisation


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
        out: where R goes, float64 or float32 (computed in float64, rounded once when stored). [n, P, A]
    Returns:
        out: R (columns past the rank are 0), every entry written by the thread that owns the block.
    """
    n, a, p = jac.shape
    per = (n + num_slices - 1) // num_slices
    tol = a * PIVOT_TOLERANCE
    for s in prange(num_slices):
        w = np.empty((a, a))
        c = np.empty((a, a))  # entries (i, k), k <= i, k < rank are written before they are read
        c_t = np.empty((a, a))
        jac_t = np.empty((p, a))
        perm = np.empty(a, np.int64)
        root_diag = np.empty(a)
        inv_root = np.empty(a)
        for b in range(s * per, min(n, (s + 1) * per)):
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
            for i in range(a):  # C_G^T = (D^1/2 Pi C)^T (C's row i is attribute perm[i]) and (Pi^T J)^T, transposed so
                for k in range(a):  # that the product below runs over contiguous rows
                    c_t[k, i] = c[i, k] * root_diag[perm[i]] if k <= i and k < rank else 0.0
                for row in range(p):
                    jac_t[row, i] = jac[b, perm[i], row]
            for row in range(p):  # R = scale J^T C_G; columns past the rank are 0
                for k in range(rank):
                    acc = 0.0
                    for i in range(a):
                        acc += jac_t[row, i] * c_t[k, i]
                    out[b, row, k] = scale * acc
                for k in range(rank, a):
                    out[b, row, k] = 0.0
    return out
