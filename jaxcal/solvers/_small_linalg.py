"""Dense linear algebra for tiny matrices (n <= ~30), in plain ``jax.numpy``, unrolled.

Used inside vmapped ``while_loop`` bodies instead of LAPACK custom calls: with batched
``cholesky``/``qr``/``solve_triangular`` inside the elimination loop, some batch sizes (e.g. 200
robots) hung on the CPU backend of jax 0.10.2, while others ran (100, 1000). Unrolled
elementwise code has no such custom calls and fuses with its neighbours.
"""

from __future__ import annotations

import jax.numpy as jnp


def cholesky(A):
    """Lower Cholesky factor of symmetric positive-definite ``A`` ``(..., n, n)``; NaN if not
    positive definite."""
    n = A.shape[-1]
    L = [[None] * n for _ in range(n)]
    for j in range(n):
        s = A[..., j, j] - sum((L[j][k] ** 2 for k in range(j)), jnp.zeros_like(A[..., j, j]))
        L[j][j] = jnp.sqrt(s)
        for i in range(j + 1, n):
            t = A[..., i, j] - sum((L[i][k] * L[j][k] for k in range(j)), jnp.zeros_like(A[..., i, j]))
            L[i][j] = t / L[j][j]
    z = jnp.zeros_like(A[..., 0, 0])
    return jnp.stack([jnp.stack([L[i][j] if j <= i else z for j in range(n)], -1) for i in range(n)], -2)


def solve_lower(L, B):
    """``L^{-1} B`` for lower-triangular ``L`` ``(..., n, n)``, ``B`` ``(..., n, k)``."""
    n = L.shape[-1]
    X = []
    for i in range(n):
        r = B[..., i, :] - sum((L[..., i, k, None] * X[k] for k in range(i)), jnp.zeros_like(B[..., i, :]))
        X.append(r / L[..., i, i, None])
    return jnp.stack(X, -2)


def solve_upper(U, B):
    """``U^{-1} B`` for upper-triangular ``U`` ``(..., n, n)``, ``B`` ``(..., n, k)``."""
    n = U.shape[-1]
    X = [None] * n
    for i in reversed(range(n)):
        r = B[..., i, :] - sum((U[..., i, k, None] * X[k] for k in range(i + 1, n)), jnp.zeros_like(B[..., i, :]))
        X[i] = r / U[..., i, i, None]
    return jnp.stack(X, -2)


def lstsq_normal(A, b):
    """Least squares ``argmin |A y - b|`` for full-column-rank ``A`` ``(r, k)`` through
    column-scaled normal equations and an unrolled Cholesky (well-conditioned blocks only:
    the scaled condition number is squared)."""
    s = jnp.linalg.norm(A, axis=0)
    s = jnp.where(s > 0, s, 1.0)
    As = A / s
    L = cholesky(As.T @ As)
    y = solve_upper(jnp.swapaxes(L, -1, -2), solve_lower(L, (As.T @ b)[:, None]))[:, 0]
    return y / s
