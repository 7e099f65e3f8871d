r"""A compact BFGS minimiser in one ``lax.while_loop`` whose body evaluates the function and its
gradient once (Nocedal & Wright, *Numerical Optimization*, alg. 6.1, with a backtracking Armijo
line search).

Why not :func:`optimistix.minimise`: its compiled program holds the objective's gradient in
several places, and the design objective (the gradient of a function of the identification
Jacobian) is expensive to compile; with one evaluation per iteration a first design compiles
markedly faster, and compile time is most of what a user waits for (``benchmarks/bench_design.py``
times it). Each iteration either accepts a trial point (and updates the inverse Hessian) or
halves the step.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

ARMIJO = 1e-4
MIN_STEP = 1e-10


def minimise(value_and_grad, x0, args, *, max_evals: int, tol: float):
    """Minimise ``f(x, args)`` from ``x0`` (any shape) with ``value_and_grad(x, args) -> (f,
    grad)``. Stops when an accepted step changes ``f`` by less than ``tol (1 + |f|)`` and moves
    ``x`` by less than ``tol (1 + |x|)`` (max norm), when the step would shrink below
    ``MIN_STEP``, or after ``max_evals`` evaluations. Returns ``(x, f, converged,
    evaluations)``."""
    shape = x0.shape
    x0 = x0.reshape(-1)
    d = x0.shape[0]
    eye = jnp.eye(d, dtype=x0.dtype)

    def body(s):
        x, f, g, H, p, t, k, done, conv = s
        y = x + t * p
        fy, gy = value_and_grad(y.reshape(shape), args)
        gy = gy.reshape(-1)
        first = ~jnp.isfinite(f)  # the first evaluation is at x0 itself (p = 0)
        ok = jnp.isfinite(fy) & (first | (fy <= f + ARMIJO * t * jnp.dot(g, p)))
        # BFGS update of the inverse Hessian on an accepted step with positive curvature
        sv, yv = y - x, gy - g
        sy = jnp.dot(sv, yv)
        H0 = jnp.where(k == 1, eye * sy / jnp.maximum(jnp.dot(yv, yv), 1e-300), H)  # scale before the first update
        sy_ = jnp.where(sy > 0, sy, 1.0)
        Hy = H0 @ yv  # the rank-two form of (I - r s y^T) H (I - r y s^T) + r s s^T: O(d^2)
        Hn = H0 + ((sy_ + jnp.dot(yv, Hy)) / sy_**2) * jnp.outer(sv, sv) - (jnp.outer(Hy, sv) + jnp.outer(sv, Hy)) / sy_
        Hn = jnp.where(ok & ~first & (sy > 0), Hn, H)
        small = (jnp.abs(f - fy) <= tol * (1 + jnp.abs(fy))) & (jnp.max(jnp.abs(sv)) <= tol * (1 + jnp.max(jnp.abs(y))))
        conv = ok & ~first & small
        x, f, g, H = (jnp.where(ok, a, b) for a, b in ((y, x), (fy, f), (gy, g), (Hn, H)))
        p = jnp.where(ok, -H @ g, p)
        t = jnp.where(ok, 1.0, t / 2)
        done = conv | (t < MIN_STEP)
        return x, f, g, H, p, t, k + ok, done, conv

    def cond(s):
        return ~s[7]

    zero = jnp.zeros_like(x0)
    init = (x0, jnp.inf, zero, eye, zero, jnp.float64(1.0), 0, False, False)

    def bounded(s):  # a counter in the state bounds the loop
        return cond(s[0]) & (s[1] < max_evals)

    out, n = jax.lax.while_loop(bounded, lambda s: (body(s[0]), s[1] + 1), (init, 0))
    x, f, *_, conv = out
    return x.reshape(shape), f, conv, n
