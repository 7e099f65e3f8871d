r"""The one Gauss–Newton / Levenberg–Marquardt engine, on residuals whose Jacobian is given
analytically.

:func:`least_squares` wraps ``optx.least_squares`` for any residual that comes with its exact
Jacobian (``jax.custom_jvp``, so optimistix never differentiates through forward kinematics;
which is faster: ``benchmarks/bench_gn_batch.py`` compares).
:func:`gauss_newton` is Gauss–Newton on the normal equations through ``optx.root_find`` (Newton's
method on the stationarity condition), for small full-rank problems whose ``J^T J`` can be
formed where the Jacobian is made. :func:`fit` is the calibration solve used by every workflow:
Gauss–Newton (and the one-step ``linear``) on :func:`gauss_newton`, Levenberg–Marquardt on
:func:`least_squares`; both optimistix:

$$\min_y \sum_k w_k |W e_k(x)|^2 + \sum_j (p_j x_j)^2,\qquad x = \text{scatter}(\text{free}, y)$$

``e_k`` the residual rows of pose ``k`` (:func:`jaxcal.model.residual_and_jacobian`), ``W`` the
row weights ``1/sigma``, ``w_k`` per-pose weights (a cross-validation training mask, or robust
weights), ``p_j`` prior weights on the free parameters:

* ``0``: free;
* ``1 / s_j``: a ridge (Tikhonov) prior of standard deviation ``s_j`` toward the reference model;
* :data:`PIN`: held at the reference. One compiled solve then serves every parameter set.

The free variables are scaled by the column norms of the weighted Jacobian at the start, so
Levenberg–Marquardt's damping and the step tolerances see parameters of comparable size
whatever their units (mm, rad, or a camera's dimensionless unknowns).

## Robust losses (outliers)
``loss="huber"`` or ``"cauchy"`` runs iteratively reweighted least squares (IRLS): ``rounds``
outer rounds (``lax.fori_loop``, one compiled solve) around the solve. Round 0 is the plain (L2)
fit; each later round weights every *pose* by ``rho'(u_k) / u_k`` of its standardised residual
norm ``u_k = |W e_k| / s`` and refits, warm-started. ``s`` is the per-row noise scale:
``loss_scale`` if given, else :func:`robust_scale`, ``median_k |W e_k| / sqrt(median chi2_dof)``
(consistent for Gaussian noise, unaffected by up to half the poses being gross outliers),
floored at :data:`SCALE_FLOOR`. With ``c = sqrt(chi2_dof(0.95))``:

* Huber: ``w = min(1, c / u)``;
* Cauchy: ``w = 1 / (1 + (u / c)^2)``.

A pose is an **outlier** when ``u_k`` exceeds :func:`outlier_threshold`: a standardised norm
as improbable under Gaussian noise as a one-sided deviation of :data:`OUTLIER_SIGMAS` standard
deviations of a normal variable (``sqrt`` of the chi-square quantile of the pose's rows at that
tail probability, 2.9e-7 for 5), so the false-alarm rate per pose is the same for positions,
poses and several points.

## Lost points
A NaN coordinate of a measured point (a marker not seen at that pose) is not observed
(:func:`jaxcal.model.observed`): its rows get weight 0 and its value is never read.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..model import Layout, Model, apply, errors, filled, observed, residual_and_jacobian_soa

METHODS = ("gn", "lm", "linear")
LOSSES = ("l2", "huber", "cauchy")
PIN = 1e8
"""Prior weight that holds a parameter at its reference value (not in the estimated set)."""
COLUMN_NORM = 1e3
"""Norm of every scaled Jacobian column at the start of a fit (see :func:`fit`)."""
SCALE_FLOOR = 1e-3
"""Smallest robust scale (weighted-residual units, i.e. 1e-3 sigma): noise-free fits do not
turn rounding noise into outliers."""


def chi2_sf(x: float, dof: int) -> float:
    """Survival function of the chi-square distribution with an integer ``dof``, in closed form
    (a finite sum, with ``erfc`` for an odd ``dof``): scipy.stats, which would give it too, takes
    longer to import than a calibration takes to run."""
    if x <= 0:
        return 1.0
    h = 0.5 * x
    if dof % 2 == 0:
        terms = (j * math.log(h) - h - math.lgamma(j + 1) for j in range(dof // 2))
        return math.fsum(math.exp(t) for t in terms)
    terms = ((j + 0.5) * math.log(h) - h - math.lgamma(j + 1.5) for j in range(dof // 2))
    return math.erfc(math.sqrt(h)) + math.fsum(math.exp(t) for t in terms)


def chi2_isf(p: float, dof: int) -> float:
    """``x`` with :func:`chi2_sf` ``(x, dof) = p`` (``0 < p < 1``), by bisection to rounding."""
    lo, hi = 0.0, float(dof) + 1.0
    while chi2_sf(hi, dof) > p:
        lo, hi = hi, 2.0 * hi
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        lo, hi = (mid, hi) if chi2_sf(mid, dof) > p else (lo, mid)
    return 0.5 * (lo + hi)


_CHI2_SQRT: dict = {}


def _chi2_sqrt(p: float, dof: int) -> float:
    """``sqrt`` of the chi-square quantile ``p`` for ``dof`` degrees of freedom."""
    if (p, dof) not in _CHI2_SQRT:
        _CHI2_SQRT[(p, dof)] = math.sqrt(chi2_isf(1.0 - p, dof))
    return _CHI2_SQRT[(p, dof)]


def _per_pose(p: float, dof):
    """``sqrt(chi2_dof(p))`` for an int ``dof``, or per pose for an array of row counts."""
    if np.ndim(dof) == 0:
        return _chi2_sqrt(p, int(dof))
    dof = np.asarray(dof, int)
    return np.array([_chi2_sqrt(p, int(d)) for d in np.unique(dof)])[np.searchsorted(np.unique(dof), dof)]


def tuning(dof) -> float:
    """Robust loss tuning constant ``sqrt(chi2_dof(0.95))`` for ``dof`` rows per pose (an array
    of row counts: per pose)."""
    return _per_pose(0.95, dof)


OUTLIER_SIGMAS = 5.0
"""Default outlier level: a pose's residual as improbable as a 5-sigma normal deviation
(one-sided tail 2.9e-7: about one false alarm in 3.5 million clean poses)."""


def outlier_threshold(dof: int, sigmas: float = OUTLIER_SIGMAS) -> float:
    """Standardised residual norm (units of the noise per row) beyond which a pose of ``dof``
    rows is an outlier: ``sqrt(chi2_dof.isf(p))`` with ``p`` the one-sided normal tail beyond
    ``sigmas`` (5: 5.77 for a position, 6.40 for a pose, 7.34 for four points)."""
    key = ("outlier", float(sigmas), int(dof))
    if key not in _CHI2_SQRT:
        _CHI2_SQRT[key] = math.sqrt(chi2_isf(0.5 * math.erfc(sigmas / math.sqrt(2.0)), int(dof)))
    return _CHI2_SQRT[key]


def _xp(a):
    """NumPy for NumPy input (no JAX dispatch outside a solve), ``jax.numpy`` otherwise."""
    return np if isinstance(a, (np.ndarray, np.generic)) else jnp


def robust_scale(norms: Float[Array, " K"], dof, weights=None) -> Float[Array, ""]:
    """Per-row noise scale from per-pose weighted residual norms (the last axis): ``median |r_k| /
    sqrt(median chi2_dof)`` over the poses with positive ``weights`` (all by default), floored at
    :data:`SCALE_FLOOR`. ``dof``: the rows per pose, or (NumPy) an array of each pose's observed
    rows (lost points), each norm then divided by its own chi median."""
    xp = _xp(norms)
    med = _per_pose(0.5, dof)
    if np.ndim(med):
        norms, med = norms / med, 1.0
    if weights is None:
        m = xp.median(norms, axis=-1)
    else:  # median over the selected poses: the others sorted to the end as +inf
        sel = weights > 0
        srt = xp.sort(xp.where(sel, norms, xp.inf), axis=-1)
        n = xp.sum(sel, axis=-1, keepdims=True)
        lo = xp.take_along_axis(srt, xp.maximum((n - 1) // 2, 0), -1)[..., 0]
        hi = xp.take_along_axis(srt, xp.maximum(n // 2, 0), -1)[..., 0]
        m = 0.5 * (lo + hi)
    return xp.maximum(m / med, SCALE_FLOOR)


def robust_weights(norms, scale, dof, loss: str):
    """Per-pose IRLS weights ``rho'(u)/u`` for ``u = norms / scale`` (see the module docstring)."""
    xp = _xp(norms)
    u = norms / scale
    c = tuning(dof)
    if loss == "huber":
        return xp.minimum(1.0, c / xp.maximum(u, 1e-300))
    if loss == "cauchy":
        return 1.0 / (1.0 + (u / c) ** 2)
    return xp.ones_like(u)


class Solution(eqx.Module):
    """What one solve returns (vmapped: a leading axis on every field)."""

    x: Float[Array, " m"]
    """The full parameter vector (non-free entries at their reference, 0)."""
    converged: Bool[Array, ""]
    """The solver met its tolerances and every value is finite."""
    steps: Int[Array, ""]
    """Solver steps taken (summed over robust rounds)."""


def _solver(method: str, rtol: float, atol: float):
    import lineax as lx  # imported while a solve is traced: a process that loads kept programs never needs them
    import optimistix as optx

    if method == "gn":  # the free set is full rank (the base set) and its columns are scaled: the
        # normal equations are well conditioned, and several times cheaper than QR on tall systems
        return optx.GaussNewton(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
    if method == "lm":  # the damped system is full rank; its default QR made a vmapped solve compile for minutes
        return optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
    raise ValueError(f"unknown least-squares method {method!r}: use one of {METHODS}")


def least_squares(
    rj,
    y0,
    args,
    *,
    method: str = "gn",
    max_steps: int = 50,
    rtol: float = 1e-8,
    atol: float = 1e-8,
    transposed: bool = False,
):
    """Minimise ``|r(y)|^2`` with optimistix, ``rj(y, args) -> (r, J)`` giving the residual and
    its exact Jacobian ``dr/dy`` (``(N, p)``, or ``(p, N)`` with ``transposed``: a Jacobian built
    parameter by parameter needs no transpose). Pure and vmappable.

    **Returns** ``(y, converged, steps)``; ``converged`` is False when optimistix did not report
    success (e.g. ``max_steps`` reached) or the result is not finite. ``method``: ``"gn"`` or
    ``"lm"`` (:func:`fit` takes its one-step ``"linear"`` on the normal equations itself).
    """

    @jax.custom_jvp
    def fn(y, args):
        return rj(y, args)[0]

    @fn.defjvp
    def fn_jvp(primals, tangents):  # data in args are not differentiated
        y, args_ = primals
        r, J = rj(y, args_)
        return r, (tangents[0] @ J if transposed else J @ tangents[0])

    import optimistix as optx  # (see _solver)

    sol = optx.least_squares(fn, _solver(method, rtol, atol), y0, args=args, max_steps=max_steps, throw=False)
    ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(sol.value))
    return sol.value, ok, sol.stats["num_steps"]


def newton_step(normal, z: Float[Array, " p"], args) -> Float[Array, " p"]:
    """The Gauss–Newton step ``dz`` (move to ``z - dz``) of the normal equations at ``z``."""
    A, g = normal(z, args)
    return jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(A), True), g)


def gauss_newton(normal, z0: Float[Array, " p"], args, *, max_steps: int = 50, rtol: float = 1e-8, atol: float = 1e-8):
    r"""Gauss–Newton on the normal equations, run by optimistix's Newton root finder:
    ``normal(z, args) -> (A, g)`` gives ``A = J^T J = L L^T`` and ``g = J^T r`` at ``z``. Pure
    and vmappable.

    Gauss–Newton is Newton's method on the stationarity condition ``J^T r = 0`` with ``A`` for
    its Jacobian. ``optx.Newton`` runs it on the whitened gradient ``f = L^{-1} g / c`` (``c =``
    :data:`COLUMN_NORM`, the scale of ``L`` after :func:`fit`'s column scaling), declared to have
    the Jacobian ``L^T / c``: each step solves ``L^T dz = L^{-1} g``, i.e. ``A dz = g``, and
    moves to ``z - dz``. ``f`` is then ``L^T dz / c``, so optimistix's Cauchy test (``|dz_j| <
    atol + rtol |z_j|`` and ``|f| < atol``) looks at that same step twice, in ``z`` and in the
    metric of ``A``, and stops after the first step within the tolerances.

    ``normal`` reduces each Jacobian to its ``p x p`` normal matrix where it is made, so no
    ``(rows, p)`` Jacobian is carried from step to step as in ``optx.GaussNewton``: made for the
    small, full-rank, column-scaled problems of :func:`fit`.

    **Returns** ``(z, converged, steps)``; ``converged`` is False when ``max_steps`` was reached
    or a value is not finite (a singular ``A``).
    """

    def whitened(z, args_):
        A, g = normal(z, args_)
        L = jnp.linalg.cholesky(A)
        return jax.scipy.linalg.solve_triangular(L, g, lower=True) / COLUMN_NORM, L

    @jax.custom_jvp
    def f(z, args_):
        return whitened(z, args_)[0]

    @f.defjvp
    def f_jvp(primals, tangents):  # L^T / c stands for f's Jacobian: the Gauss–Newton model
        f_z, L = whitened(*primals)
        return f_z, L.T @ tangents[0] / COLUMN_NORM

    import lineax as lx  # (see _solver)
    import optimistix as optx

    solver = optx.Newton(rtol=rtol, atol=atol, linear_solver=lx.Triangular())
    tags = frozenset({lx.upper_triangular_tag})
    sol = optx.root_find(f, solver, z0, args, max_steps=max_steps, throw=False, tags=tags)
    ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(sol.value))
    return sol.value, ok, sol.stats["num_steps"]


def fit(
    model: Model,
    layout: Layout,
    free: tuple[int, ...],
    q: Float[Array, "K n"],
    target,
    *,
    weights: Float[Array, " rows"],
    pose_weights: Float[Array, " K"] | None = None,
    prior: Float[Array, " p"] | None = None,
    method: str = "gn",
    max_steps: int = 50,
    rtol: float = 1e-8,
    atol: float = 1e-8,
    loss: str = "l2",
    loss_scale=None,
    rounds: int = 6,
    column_norms=None,
    x0=None,
) -> Solution:
    """Fit the free parameters of ``model`` to one data set (module docstring). Pure and vmappable.

    **Arguments**: ``free`` indices into the layout's ``x`` (static); ``q (K, n)``; ``target``
    the measurements (``(K, 4, 4)`` poses or ``(K, M, 3)`` points, NaN where a point was lost:
    its rows weigh nothing); ``weights`` ``1/sigma`` per
    residual row; ``pose_weights`` ``(K,)`` (default 1); ``prior`` ``(len(free),)`` (default 0);
    ``loss_scale`` the robust per-row noise scale (None or NaN: estimated); ``column_norms``
    ``(len(free),)`` the norms of the weighted Jacobian's columns, with prior rows, at the start
    (default: computed here; a caller that knows them saves one Jacobian in the compiled solve);
    ``x0`` ``(m,)`` a starting point (default 0, the reference; entries outside ``free`` ignored).

    **Returns** a :class:`Solution`; ``x`` is relative to ``model``.
    """
    K = q.shape[0]
    m, rows = layout.size, layout.rows
    free_idx = jnp.asarray(free, dtype=jnp.int32)
    pose_w = jnp.ones(K) if pose_weights is None else jnp.asarray(pose_weights, jnp.float64)
    prior = jnp.zeros(len(free)) if prior is None else jnp.asarray(prior, jnp.float64)

    every = tuple(free) == tuple(range(m))
    seen = observed(target).T  # (rows, K): a lost point's rows weigh nothing
    target = filled(target)

    def full(y):
        return y if every else jnp.zeros(m).at[free_idx].set(y)

    def weighted(y, sqrt_pw):
        # pose axis last (residual_and_jacobian_soa): the weights broadcast along it, and the
        # Jacobian stays parameter-major, (p, rows K), with no transpose
        e, J = residual_and_jacobian_soa(model, layout, full(y), q, target)  # (rows, K), (m, rows, K)
        wk = weights[:, None] * sqrt_pw[None, :] * seen
        Jw = (J if every else J[free_idx]) * wk[None]
        return e * wk, Jw

    # column scaling from the start, y = s * z: every column of the weighted Jacobian gets the norm
    # COLUMN_NORM, so LM's initial damping (lambda = 1 on z) is light next to J^T J, as in
    # Marquardt's scaling; with unit columns it damped every step and took five times more steps
    if column_norms is None:
        _, Jw0 = weighted(jnp.zeros(len(free)), jnp.sqrt(pose_w))
        column_norms = jnp.sqrt(jnp.sum(Jw0.reshape(len(free), -1) ** 2, 1) + prior**2)
    norm = jnp.asarray(column_norms) / COLUMN_NORM
    scale = jnp.where(norm > 0, 1.0 / norm, 1.0)

    def rj(z, sqrt_pw):
        y = scale * z
        ew, Jw = weighted(y, sqrt_pw)
        r = jnp.concatenate([ew.reshape(-1), prior * y])
        JT = jnp.concatenate([Jw.reshape(len(free), -1) * scale[:, None], jnp.diag(prior * scale)], 1)
        return r, JT

    def normal(z, sqrt_pw):  # J^T J and J^T r of rj's system, the data rows reduced where they are made
        y = scale * z
        ew, Jw = weighted(y, sqrt_pw)
        Jf = Jw.reshape(len(free), -1)
        ps = prior * scale
        A = scale[:, None] * (Jf @ Jf.T) * scale[None, :] + jnp.diag(ps**2)
        return A, scale * (Jf @ ew.reshape(-1)) + ps * (prior * y)

    def solve(z0, pw):
        if method == "gn":
            return gauss_newton(normal, z0, jnp.sqrt(pw), max_steps=max_steps, rtol=rtol, atol=atol)
        if method == "linear":  # one Gauss-Newton step from the start
            z = z0 - newton_step(normal, z0, jnp.sqrt(pw))
            return z, jnp.all(jnp.isfinite(z)), jnp.asarray(1)
        return least_squares(
            rj, z0, jnp.sqrt(pw), method=method, max_steps=max_steps, rtol=rtol, atol=atol, transposed=True
        )

    z0 = jnp.zeros(len(free)) if x0 is None else jnp.asarray(x0)[free_idx] / scale
    if loss == "l2" or method == "linear":
        z, ok, steps = solve(z0, pose_w)
    else:
        if loss not in LOSSES:
            raise ValueError(f"unknown loss {loss!r}: use one of {LOSSES}")
        given = jnp.asarray(jnp.nan if loss_scale is None else loss_scale, dtype=jnp.float64)

        def outer(i, c):  # round 0 the plain fit, then reweighted: one solve in the compiled loop
            z_, _ok, steps_ = c
            e = errors(apply(model, layout, full(scale * z_)), q, target)
            norms = jnp.linalg.norm(e * weights * seen.T, axis=-1)
            s = jnp.where(jnp.isnan(given), robust_scale(norms, rows, pose_w), given)
            rw = jnp.where(i == 0, 1.0, robust_weights(norms, s, rows, loss))
            z2, ok2, s2 = solve(z_, pose_w * rw)
            return z2, ok2, steps_ + s2

        z, ok, steps = jax.lax.fori_loop(0, rounds + 1, outer, (z0, jnp.asarray(False), jnp.asarray(0)))
    return Solution(x=full(scale * z), converged=ok, steps=steps)
